"""Path geometry against closed forms and invariants."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths import InteractionType, TraceOptions, WavepathsError, trace
from wavepaths.scene import load_scene, transformed

from ..conftest import quads_scene

REFL, DIFF = InteractionType.REFLECTION, InteractionType.DIFFRACTION


def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def check_laws(scene, paths, tol=1e-9):
    """Law of reflection at every reflection, Keller's cone at every diffraction."""
    dih = scene.dihedra
    checked = 0
    for i in range(len(paths)):
        v = paths.vertices[i]
        for j in range(paths.depth[i]):
            a, p, b = v[j], v[j + 1], v[j + 2]
            din, dout = unit(p - a), unit(b - p)
            if paths.interactions[i, j] == REFL:
                n = scene.polygon_normal[paths.primitive[i, j]]
                np.testing.assert_allclose(dout, din - 2 * (din @ n) * n, atol=tol)
                assert abs(n @ p - scene.polygon_offset[paths.primitive[i, j]]) < tol * 100
            else:
                k = paths.primitive[i, j]
                w = dih.direction[k]
                assert din @ w == pytest.approx(dout @ w, abs=tol)  # Keller's cone
                t = (p - dih.origin[k]) @ w
                assert -tol <= t <= dih.length[k] + tol  # on the segment
                np.testing.assert_allclose(np.cross(p - dih.origin[k], w), 0, atol=tol * 100)
            checked += 1
    return checked


def test_half_plane_diffraction_point_and_length_in_closed_form():
    s = load_scene("half_plane")  # screen y = 0, z < 0, edge on the x axis
    tx = np.array([[1.0, -7.0, -3.0]])
    rx = np.array([[6.0, 9.0, -2.0], [-4.0, 5.0, -12.0]])
    p = trace(s, tx, rx, TraceOptions(max_reflections=0))
    for j, r in enumerate(rx):
        sel = (p.rx_index == j) & (p.depth == 1)
        top = [i for i in np.nonzero(sel)[0] if abs(p.vertices[i, 1, 2]) < 1e-12]
        assert len(top) == 1
        i = top[0]
        re, rr = np.hypot(tx[0, 1], tx[0, 2]), np.hypot(r[1], r[2])
        x = tx[0, 0] + (r[0] - tx[0, 0]) * re / (re + rr)
        np.testing.assert_allclose(p.vertices[i, 1], [x, 0, 0], atol=1e-12)
        assert p.lengths[i] == pytest.approx(np.hypot(r[0] - tx[0, 0], re + rr), rel=1e-14)
    assert not (p.depth == 0).any()  # the screen hides the line of sight


def test_wedge_paths_obey_keller_and_the_law_of_reflection():
    s = load_scene("wedge")
    tx = np.array([[0.0, 3.0, 2.0]])
    rx = np.array([[x, -3.0, y] for x in (-2, 0, 3) for y in (-4, 1, 4)], float)
    p = trace(s, tx, rx, TraceOptions(max_reflections=2, diffraction_reflections=1))
    assert check_laws(s, p) > 10
    assert ((p.interactions == DIFF).any(axis=1)).sum() >= len(rx)


def test_corner_reflector_has_the_known_image_paths():
    # two perpendicular plates meeting on the z axis: x = 0 (y > 0) and y = 0 (x > 0)
    s = quads_scene([[[0, 0, -5], [0, 10, -5], [0, 10, 5], [0, 0, 5]], [[0, 0, -5], [10, 0, -5], [10, 0, 5], [0, 0, 5]]])
    tx = np.array([[3.0, 1.0, 0.0]])
    rx = np.array([[1.0, 4.0, 1.0]])
    p = trace(s, tx, rx, TraceOptions(max_reflections=2, diffraction=False))
    kinds = sorted(tuple(k) for k in p.kind_names())
    # inside a right-angle corner only one of the two orders of the double bounce is realisable
    # (here y = 0 first: the other order's first crossing falls at x < 0, off the plate)
    assert kinds == [(), ("reflection",), ("reflection",), ("reflection", "reflection")]
    rr = p.depth == 2
    assert p.vertices[rr][0, 1, 1] == pytest.approx(0.0, abs=1e-12)
    # the double-bounce path has the length of tx to the doubly mirrored receiver
    np.testing.assert_allclose(p.lengths[rr], np.linalg.norm(rx[0] - tx[0] * [-1, -1, 1]), rtol=1e-14)
    single = np.sort(p.lengths[p.depth == 1])
    expect = np.sort([np.linalg.norm(rx[0] - tx[0] * [-1, 1, 1]), np.linalg.norm(rx[0] - tx[0] * [1, -1, 1])])
    np.testing.assert_allclose(single, expect, rtol=1e-14)
    check_laws(s, p)


def test_street_canyon_reflection_orders():
    s = load_scene("street_canyon")
    tx = np.array([[-20.0, 0.0, 8.0]])
    rx = np.array([[25.0, 2.0, 1.5]])
    counts = []
    for order in range(4):
        p = trace(s, tx, rx, TraceOptions(max_reflections=order, diffraction=False))
        counts.append(len(p))
        check_laws(s, p)
        # every order-k path has exactly k reflections, and lower orders are unchanged
        assert (p.depth <= order).all()
    assert counts[0] == 1 and counts[1] > counts[0] and counts[2] > counts[1] and counts[3] > counts[2]
    # the ground reflection is the image of the transmitter in z = 0
    p = trace(s, tx, rx, TraceOptions(max_reflections=1, diffraction=False))
    ground = [i for i in range(len(p)) if p.depth[i] == 1 and abs(p.vertices[i, 1, 2]) < 1e-12]
    assert len(ground) == 1
    assert p.lengths[ground[0]] == pytest.approx(np.linalg.norm(rx[0] - tx[0] * [1, 1, -1]), rel=1e-14)


def test_box_on_ground_has_no_diffraction_at_its_foot():
    s = load_scene("box_on_ground")
    d = s.dihedra
    foot = np.nonzero(d.face_count >= 3)[0]
    assert len(foot) == 4
    g = np.linspace(-25, 25, 6)
    rx = np.array([[x, y, 0.5] for x in g for y in g if max(abs(x), abs(y)) > 6])
    p = trace(s, np.array([[-15.0, -12.0, 3.0]]), rx, TraceOptions(max_reflections=1, diffraction_reflections=1))
    diff_prims = p.primitive[p.interactions == DIFF]
    assert len(diff_prims) > 20
    assert not np.isin(diff_prims, foot).any()


def test_reciprocity_of_geometry():
    s = load_scene("street_canyon")
    a, b = np.array([[-30.0, 3.0, 6.0]]), np.array([[35.0, -4.0, 1.5]])
    opts = TraceOptions(max_reflections=2, diffraction_reflections=1)
    f, r = trace(s, a, b, opts), trace(s, b, a, opts)
    key = lambda p, i, rev: (tuple(p.interactions[i, : p.depth[i]][:: -1 if rev else 1]),
                             tuple(p.primitive[i, : p.depth[i]][:: -1 if rev else 1]))
    fwd = {key(f, i, False): i for i in range(len(f))}
    bwd = {key(r, i, True): i for i in range(len(r))}
    assert set(fwd) == set(bwd) and len(fwd) > 10
    for k, i in fwd.items():
        j = bwd[k]
        d = f.depth[i]
        np.testing.assert_allclose(f.vertices[i, : d + 2], r.vertices[j, : d + 2][::-1], atol=1e-9)


@pytest.mark.parametrize("shift", [np.zeros(3), np.array([1e6, 2e6, 30.0])])
def test_invariance_under_rotation_and_translation(shift):
    s = load_scene("street_canyon")
    ang = 0.7
    rot = np.array([[np.cos(ang), -np.sin(ang), 0], [np.sin(ang), np.cos(ang), 0], [0, 0, 1]])
    moved = transformed(s, rotation=rot, translation=shift)
    tx = np.array([[-30.0, 3.0, 6.0]])
    rx = np.array([[35.0, -4.0, 1.5], [0.0, 5.0, 2.0]])
    opts = TraceOptions(max_reflections=2, diffraction_reflections=1)
    p, q = trace(s, tx, rx, opts), trace(moved, tx @ rot.T + shift, rx @ rot.T + shift, opts)
    assert len(p) == len(q)
    key = lambda x: sorted(zip(x.rx_index.tolist(), x.depth.tolist(), np.round(x.lengths, 5).tolist()))
    kp, kq = key(p), key(q)
    for a, b in zip(kp, kq):
        assert a[:2] == b[:2] and a[2] == pytest.approx(b[2], abs=2e-5)


@pytest.mark.parametrize("tx, rx, message", [
    (np.zeros((2, 2)), np.zeros((1, 3)), "shape"),
    (np.array([[0, 0, np.nan]]), np.ones((1, 3)), "NaN"),
    (np.array([[1.0, 2.0, 3.0]]), np.array([[1.0, 2.0, 3.0]]), "same position"),
])
def test_bad_positions_raise_clear_errors(tx, rx, message):
    with pytest.raises(WavepathsError, match=message):
        trace(load_scene("half_plane"), tx, rx)


def test_lit_region_option_keeps_only_shadow_diffraction():
    s = load_scene("half_plane")
    tx = np.array([[0.0, -10.0, -5.0]])
    rx = np.array([[0.0, 10.0, -5.0], [0.0, 10.0, 8.0], [0.0, -10.0, -20.0]])
    full = trace(s, tx, rx, TraceOptions(max_reflections=0))
    shadow = trace(s, tx, rx, TraceOptions(max_reflections=0, lit_region=False))
    top = lambda p: {int(p.rx_index[i]) for i in range(len(p)) if p.depth[i] == 1 and abs(p.vertices[i, 1, 2]) < 1e-12}
    assert top(full) == {0, 1, 2}
    assert top(shadow) == {0}  # receiver 0 is behind the screen; 1 sees the tx; 2 is on the tx side


def test_transmitter_inside_a_closed_room_warns_and_finds_the_inner_reflections():
    from wavepaths.scene import WavepathsWarning

    from ..conftest import boxes_scene

    s = boxes_scene([((0, 0, 0), (10, 8, 4))])  # a closed room
    tx, rx = np.array([[2.0, 3.0, 1.5]]), np.array([[7.0, 5.0, 1.2]])
    with pytest.warns(WavepathsWarning, match="inside closed object"):
        p = trace(s, tx, rx, TraceOptions(max_reflections=1, diffraction=False))
    # line of sight and one reflection on each of the six walls, lengths by the image method
    assert sorted(p.depth.tolist()) == [0, 1, 1, 1, 1, 1, 1]
    images = [tx[0] * [-1, 1, 1], tx[0] * [1, -1, 1], tx[0] * [1, 1, -1],
              tx[0] * [-1, 1, 1] + [20, 0, 0], tx[0] * [1, -1, 1] + [0, 16, 0], tx[0] * [1, 1, -1] + [0, 0, 8]]
    np.testing.assert_allclose(np.sort(p.lengths[p.depth == 1]), np.sort([np.linalg.norm(rx[0] - i) for i in images]))


@pytest.mark.parametrize("prune_db", [6.0, 12.0])
def test_prune_tolerance_drops_only_weak_reflections_and_respects_its_bound(prune_db):
    from wavepaths.fields import FieldConfig, compute_fields

    s = load_scene("street_canyon")
    tx = np.array([[-60.0, 0.0, 10.0]])
    rx = np.stack([np.linspace(-80, 80, 17), np.full(17, 2.0), np.full(17, 1.5)], axis=1)
    full = trace(s, tx, rx, TraceOptions(max_reflections=3, diffraction=False))
    pruned = trace(s, tx, rx, TraceOptions(max_reflections=3, diffraction=False, prune_db=prune_db))
    assert 0 < len(pruned) < len(full)
    cfg = FieldConfig(3.5e9)
    fa, pa = compute_fields(s, full, cfg), compute_fields(s, pruned, cfg)
    key = lambda p, i: (int(p.rx_index[i]), tuple(p.primitive[i, : p.depth[i]].tolist()))
    kept = {key(pruned, i) for i in range(len(pruned))}
    dropped = [i for i in range(len(full)) if key(full, i) not in kept]
    assert len(dropped) == len(full) - len(pruned) <= pruned.stats["pruned_paths_upper_bound"]
    fs = cfg.wavelength / (4 * np.pi * np.linalg.norm(rx - tx, axis=1))
    for i in dropped:  # each dropped path is at least prune_db below free space
        assert abs(fa.a[i]) <= 10 ** (-prune_db / 20) * fs[full.rx_index[i]] * (1 + 1e-12)
    # the stated bound on the power-sum change, relative to free space, per receiver
    p_full = fa.path_gain(coherent=False)[0] / fs**2
    p_kept = pa.path_gain(coherent=False)[0] / fs**2
    n_drop = np.bincount(full.rx_index[dropped], minlength=len(rx))
    assert (p_full - p_kept <= n_drop * 10 ** (-prune_db / 10) * (1 + 1e-9)).all()


@pytest.mark.parametrize("prune_db", [10.0, 25.0])
def test_prune_tolerance_drops_only_weak_diffracted_paths_and_respects_its_bound(prune_db):
    """With ``prune_frequency_hz``, diffracted paths (with reflections around them) are pruned
    too: every dropped path is at least ``prune_db`` below free space at the receiver's
    direct distance (at the pruning frequency and above), no kept path changes, and the
    power-sum change per receiver stays within the stated bound."""
    from wavepaths.fields import FieldConfig, compute_fields

    s = load_scene("street_canyon")
    tx = np.array([[-60.0, 0.0, 10.0]])
    rx = np.concatenate([np.stack([np.linspace(-80, 80, 17), np.full(17, 2.0), np.full(17, 1.5)], axis=1),
                         np.stack([np.linspace(-80, 80, 9), np.full(9, 30.0), np.full(9, 1.5)], axis=1)])
    base = TraceOptions(max_reflections=2, diffraction=True, diffraction_reflections=1)
    full = trace(s, tx, rx, base)
    pruned = trace(s, tx, rx, base.with_(prune_db=prune_db, prune_frequency_hz=3.5e9))
    refl_only = trace(s, tx, rx, base.with_(prune_db=prune_db))  # no frequency: diffraction kept
    key = lambda p, i: (int(p.rx_index[i]), tuple(p.interactions[i, : p.depth[i]].tolist()),
                        tuple(p.primitive[i, : p.depth[i]].tolist()))
    kept = {key(pruned, i) for i in range(len(pruned))}
    dropped = [i for i in range(len(full)) if key(full, i) not in kept]
    assert len(kept) == len(pruned) and kept <= {key(full, i) for i in range(len(full))}
    is_diff = (full.interactions == InteractionType.DIFFRACTION).any(axis=1)
    assert is_diff[dropped].sum() > 0.3 * is_diff.sum()  # most diffracted paths here are weak
    assert len(dropped) <= pruned.stats["pruned_paths_upper_bound"]
    kept_r = {key(refl_only, i) for i in range(len(refl_only))}
    assert all(key(full, i) in kept_r for i in np.nonzero(is_diff)[0])
    # the bound holds at the pruning frequency and above, and with Sionna's coefficient model
    for cfg in (FieldConfig(3.5e9), FieldConfig(9.5e9), FieldConfig(3.5e9, compat="sionna")):
        fa, pa = compute_fields(s, full, cfg), compute_fields(s, pruned, cfg)
        fs = cfg.wavelength / (4 * np.pi * np.linalg.norm(rx - tx, axis=1))
        amp = np.abs(fa.a).reshape(len(full), -1).max(axis=1)
        assert (amp[dropped] <= 10 ** (-prune_db / 20) * fs[full.rx_index[dropped]] * (1 + 1e-12)).all()
        p_full = fa.path_gain(coherent=False)[0] / fs**2
        p_kept = pa.path_gain(coherent=False)[0] / fs**2
        n_drop = np.bincount(full.rx_index[dropped], minlength=len(rx))
        assert (p_full - p_kept <= n_drop * 10 ** (-prune_db / 10) * (1 + 1e-9)).all()


def test_prune_frequency_must_be_a_positive_frequency():
    with pytest.raises(WavepathsError, match="prune_frequency_hz"):
        TraceOptions(prune_db=10.0, prune_frequency_hz=0.0)
    with pytest.raises(WavepathsError, match="prune_frequency_hz"):
        TraceOptions(prune_db=10.0, prune_frequency_hz=float("nan"))


def test_path_order_does_not_depend_on_the_order_the_search_found_them():
    """Paths of equal length (a street canyon with the transmitter and receiver on its plane
    of symmetry: the left and right walls give mirror-image paths) come out in one order
    whatever the order of the batches and of the rows in them."""
    from wavepaths.search.context import build_tx_context
    from wavepaths.search.paths import PathBatch, assemble
    from wavepaths.search.tile import trace_tile

    scene = load_scene("street_canyon")
    tx, rx = np.array([[-60.0, 0.0, 10.0]]), np.array([[40.0, 0.0, 1.5], [10.0, 0.0, 1.5]])
    opts = TraceOptions(max_reflections=2, diffraction=True, diffraction_reflections=1)
    batches, stats = trace_tile(scene, build_tx_context(scene, tx, opts), rx)
    ref = assemble(tx, rx, batches, dict(stats))
    key = np.column_stack([ref.tx_index, ref.rx_index, ref.depth, ref.lengths])
    ties = (np.diff(key, axis=0) == 0).all(axis=1)
    assert ties.sum() >= 4  # the case is not vacuous: mirror-image paths of equal length
    shuffled = [PathBatch(*(np.asarray(x)[::-1] for x in (b.tx_index, b.rx_index, b.interactions, b.primitive,
                                                         b.triangle, b.wedge_faces, b.vertices)))
                for b in batches[::-1]]
    got = assemble(tx, rx, shuffled, dict(stats))
    for name in ("tx_index", "rx_index", "depth", "interactions", "primitive", "triangle", "wedge_faces", "vertices"):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)


def test_unsorted_paths_and_their_path_order_give_the_sorted_paths():
    """``assemble(..., sort=False)`` keeps the batches' order; ``path_order`` of its arrays is
    the order ``assemble`` sorts by: with ties (the symmetric canyon) and without (receivers
    off the plane of symmetry, where the one-key sort is taken), the same as sorting on the
    whole key (tx, rx, depth, length, interactions, primitives)."""
    from wavepaths.search.context import build_tx_context
    from wavepaths.search.paths import assemble, path_order
    from wavepaths.search.tile import trace_tile

    scene = load_scene("street_canyon")
    tx = np.array([[-60.0, 0.0, 10.0]])
    opts = TraceOptions(max_reflections=2, diffraction=True, diffraction_reflections=1)
    for rx in (np.array([[40.0, 0.0, 1.5], [10.0, 0.0, 1.5]]), np.array([[40.0, 2.3, 1.5], [10.0, -4.1, 1.5]])):
        batches, stats = trace_tile(scene, build_tx_context(scene, tx, opts), rx)
        raw = assemble(tx, rx, batches, dict(stats), sort=False)
        ref = assemble(tx, rx, batches, dict(stats))
        order = path_order(raw.tx_index, raw.rx_index, raw.depth, raw.lengths, raw.interactions, raw.primitive, len(rx))
        full = np.lexsort((*raw.primitive.T[::-1], *raw.interactions.T[::-1], raw.lengths, raw.depth, raw.rx_index,
                           raw.tx_index))
        np.testing.assert_array_equal(order, full)
        assert not np.array_equal(order, np.arange(len(order)))  # the batches' order is not the sorted one
        for name in ("tx_index", "rx_index", "depth", "interactions", "primitive", "triangle", "wedge_faces",
                     "vertices"):
            np.testing.assert_array_equal(getattr(raw, name)[order], getattr(ref, name), err_msg=name)


def test_compiled_key_length_order_is_numpys_lexsort():
    """The counting sort behind :func:`path_order` gives ``np.lexsort((lengths, key))`` and
    reports ties of key and length exactly when that order holds one: keys with one to
    hundreds of rows (insertion sort and, above 32, numpy's stable sort), many equal
    lengths, signed zeros."""
    pytest.importorskip("numba")
    from wavepaths.search._numba import key_length_order

    rng = np.random.default_rng(11)
    for trial in range(240):
        n, n_keys = int(rng.integers(0, 3000)), int(rng.integers(1, 200))
        key = rng.integers(0, n_keys, n)
        lengths = [rng.uniform(0, 100, n), np.round(rng.uniform(0, 5, n), 1),
                   np.where(rng.random(n) < 0.5, -0.0, 0.0)][trial % 3]
        order, tie = key_length_order(key, lengths, n_keys)
        ref = np.lexsort((lengths, key))
        np.testing.assert_array_equal(order, ref)
        k, ln = key[ref], lengths[ref]
        assert tie == bool(n > 1 and ((k[1:] == k[:-1]) & (ln[1:] == ln[:-1])).any())


def test_path_lengths_are_computed_once_read_only_and_not_pickled():
    """``segment_lengths`` and ``lengths`` are kept after their first reading, read-only (a
    caller that wants to change them gets an error, not a corrupted cache), equal to the
    vertices' segment lengths, left out of a pickle and recomputed, read-only, after it."""
    import pickle

    scene = load_scene("street_canyon")
    tx, rx = np.array([[-60.0, 0.0, 10.0]]), np.array([[40.0, 3.0, 1.5], [10.0, -4.0, 1.5]])
    paths = trace(scene, tx, rx, TraceOptions(max_reflections=2, diffraction=True))
    seg = paths.segment_lengths
    assert paths.segment_lengths is seg and paths.lengths is paths.lengths
    np.testing.assert_allclose(seg, np.linalg.norm(np.diff(paths.vertices, axis=1), axis=2), rtol=1e-15, atol=0)
    np.testing.assert_array_equal(paths.lengths, seg.sum(axis=1))
    with pytest.raises(ValueError, match="read-only"):
        paths.lengths[0] = 0.0
    data = pickle.dumps(paths)
    assert len(data) < len(pickle.dumps(paths.vertices)) + len(pickle.dumps(paths.primitive)) * 4 + 20_000
    back = pickle.loads(data)
    assert "_lengths" not in back.__dict__
    np.testing.assert_array_equal(back.lengths, paths.lengths)
    assert not back.lengths.flags.writeable and not back.segment_lengths.flags.writeable
    assert len(back.select(back.depth > 0).lengths) == int((paths.depth > 0).sum())


def test_azimuths_are_in_the_documented_half_open_range():
    # a line of sight along +x arrives from -x: azimuth +pi, not -pi (the negated direction's
    # y component is -0.0); departure along +x: 0 (docs/antennas.md: azimuth in (-pi, pi])
    s = load_scene("street_canyon")
    p = trace(s, np.array([[-60.0, 0.0, 10.0]]), np.array([[20.0, 0.0, 10.0]]),
              TraceOptions(max_reflections=0, diffraction=False))
    (zd, ad), (za, aa) = p.angles_of_departure, p.angles_of_arrival
    assert len(p) == 1 and ad[0] == 0.0 and aa[0] == np.pi
    assert zd[0] == za[0] == np.pi / 2
