"""Launched candidates (``search.launch``): Keller fans from sampled edge points find the
sequences of the exhaustive search's diffracted paths."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths.coverage.inside import inside_solid_objects, solid_objects
from wavepaths.errors import WavepathsError
from wavepaths.scene import load_scene
from wavepaths.search import TraceOptions, kernels
from wavepaths.search.context import build_tx_context
from wavepaths.search.launch import LaunchOptions, candidate_sequences, edge_samples, keller_fan
from wavepaths.search.tubes import tube_pairs as _deposit
from wavepaths.search.paths import InteractionType
from wavepaths.search.tile import trace_tile

TX = np.array([[-60.0, 0.0, 10.0]])


@pytest.fixture(scope="module")
def canyon():
    scene = load_scene("street_canyon")
    ctx = build_tx_context(scene, TX, TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=2))
    rng = np.random.default_rng(11)
    lo, hi = scene.bounds
    pts = np.column_stack([rng.uniform(lo[0], hi[0], 200), rng.uniform(lo[1], hi[1], 200), np.full(200, 1.5)])
    pts = pts[~inside_solid_objects(scene, pts, solid_objects(scene))][:40]
    batches, _ = trace_tile(scene, ctx, pts)
    ref = set()
    for b in batches:
        for i in range(len(b.rx_index)):
            kinds = b.interactions[i]
            at = np.nonzero(kinds == InteractionType.DIFFRACTION)[0]
            if len(at) == 0:
                continue
            depth = int((kinds != InteractionType.NONE).sum())
            prim = b.primitive[i].tolist()
            ref.add((int(b.rx_index[i]), tuple(prim[: at[0] + 1]), tuple(prim[at[0] + 1 : depth])))
    return scene, ctx, pts, ref


def test_the_fans_find_every_diffracted_sequence_of_the_exhaustive_search(canyon):
    """Street canyon, R-D up to two reflections around the edge (D, R-D, D-R, R-R-D, R-D-R,
    D-R-R), 40 street-level receivers: every diffracted path's sequence with a reflection
    (mirrors before, the dihedron, mirrors after) is among the receiver's candidates, at a
    few per cent of the exhaustive search's candidates; the fans carry no E-D-R sequence,
    which the tiles enumerate (wavepaths.search.launched). A sparse fan (16 directions per
    turn) misses some: the comparison can fail."""
    scene, ctx, pts, ref = canyon
    assert len(ref) > 1000
    orders = {(len(bf) - 1, len(af)) for _, bf, af in ref}
    assert orders == {(a, b) for a in range(3) for b in range(3) if a + b <= 2}
    plain = {k for k in ref if len(k[1]) == 1 and not k[2]}
    assert plain
    ref = ref - plain
    found = candidate_sequences(scene, ctx, pts, LaunchOptions(fan=256))
    keys = found.keys()
    assert ref <= keys and not plain & keys
    assert len(found) < 200 * len(pts)
    sparse = candidate_sequences(scene, ctx, pts, LaunchOptions(fan=16, radius_factor=0.5))
    assert not ref <= sparse.keys()


def test_edge_samples_are_lit_points_of_the_windows(canyon):
    """Every order's samples lie on their edges; orders 0..2 all present; the incident
    direction is a unit vector; the chains hold exactly ``order`` mirrors."""
    scene, ctx, _, _ = canyon
    s = edge_samples(scene, ctx)
    D = scene.dihedra
    assert set(np.unique(s.order)) == {0, 1, 2}
    assert np.all((s.t >= -1e-9) & (s.t <= D.length[s.dihedron] + 1e-9))
    np.testing.assert_allclose(np.linalg.norm(s.incident, axis=1), 1.0, atol=1e-12)
    assert np.array_equal((s.chain >= 0).sum(axis=1), s.order)
    # order 0: the direction of arrival is from the transmitter
    o = s.order == 0
    x = D.origin[s.dihedron[o]] + s.t[o, None] * D.direction[s.dihedron[o]]
    u = (x - TX) / np.linalg.norm(x - TX, axis=1)[:, None]
    np.testing.assert_allclose(s.incident[o], u, atol=1e-12)


def test_keller_fan_directions_lie_on_the_cone_and_leave_the_solid(canyon):
    """Each fan direction v satisfies v . w = u . w (Keller's law, seed §2.1) and is a unit
    vector; the directions flagged exterior leave the wedge into the air, the others enter
    the building (checked a few centimetres along them with the point-in-solid test)."""
    scene, ctx, _, _ = canyon
    s = edge_samples(scene, ctx)
    rows = np.random.default_rng(2).choice(len(s), 50, replace=False)
    # keep samples away from the edge's ends (a corner's other wedges would confuse the check)
    D = scene.dihedra
    L = D.length[s.dihedron[rows]]
    rows = rows[(s.t[rows] > 0.2) & (s.t[rows] < L - 0.2)]
    P, V, ext, _ = keller_fan(scene, s.dihedron[rows], s.t[rows], s.incident[rows], 32)
    w = D.direction[s.dihedron[rows]]
    cos_beta = np.einsum("kj,kj->k", s.incident[rows], w)
    np.testing.assert_allclose(np.einsum("kfj,kj->kf", V, w), np.broadcast_to(cos_beta[:, None], V.shape[:2]),
                               atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(V, axis=2), 1.0, atol=1e-12)
    probe = (P[:, None, :] + 0.05 * V).reshape(-1, 3)
    inside = inside_solid_objects(scene, probe, solid_objects(scene)).reshape(ext.shape)
    # directions within a degree of a face are ambiguous at 5 cm: skip them
    f = D.face_ptr[s.dihedron[rows]]
    n0, n1 = D.face_normal[f], D.face_normal[f + 1]
    clear = (np.abs(np.einsum("kfj,kj->kf", V, n0)) > 0.02) & (np.abs(np.einsum("kfj,kj->kf", V, n1)) > 0.02)
    assert clear.sum() > 500
    assert not np.any(inside[clear] & ext[clear])
    assert np.all(inside[clear & ~ext])


@pytest.mark.skipif(not kernels.available(), reason="numba not installed (the `fast` extra)")
def test_the_compiled_tube_test_equals_the_numpy_one(monkeypatch, rng):
    """Random segments, radii and points: the same (segment, point) pairs from the compiled
    kernel and the numpy reference; a point at its closest point's radius plus 1 mm is out,
    minus 1 mm is in."""
    S = rng.normal(size=(300, 3)) * 10
    E = S + rng.normal(size=(300, 3)) * 5
    r0, r1 = rng.uniform(0, 2, 300), rng.uniform(0, 4, 300)
    pts = rng.normal(size=(200, 3)) * 10
    got = set(zip(*(x.tolist() for x in _deposit(S, E, r0, r1, pts))))
    monkeypatch.setattr(kernels, "available", lambda: False)
    ref = set(zip(*(x.tolist() for x in _deposit(S, E, r0, r1, pts))))
    assert got == ref and len(ref) > 100
    # a planar grid of receivers and long segments from far outside it (clipped to the grid's
    # box): the bucket walk finds each pair once, and the same pairs
    xy = np.stack(np.meshgrid(np.arange(-50, 50, 2.0), np.arange(-30, 30, 2.0)), axis=-1).reshape(-1, 2)
    grid_pts = np.column_stack([xy, np.full(len(xy), 1.5)])
    S2 = rng.uniform(-400, 400, (400, 3))
    S2[:, 2] = rng.uniform(0, 60, 400)
    E2 = rng.uniform(-60, 60, (400, 3))
    E2[:, 2] = rng.uniform(-5, 5, 400)
    q0, q1 = rng.uniform(0, 1, 400), rng.uniform(0, 8, 400)
    monkeypatch.undo()
    seg, pt = _deposit(S2, E2, q0, q1, grid_pts)
    pairs = list(zip(seg.tolist(), pt.tolist()))
    assert len(pairs) == len(set(pairs)) > 1000
    monkeypatch.setattr(kernels, "available", lambda: False)
    assert set(pairs) == set(zip(*(x.tolist() for x in _deposit(S2, E2, q0, q1, grid_pts))))
    monkeypatch.undo()
    # points at a known distance from a segment's middle, perpendicular to it
    d = E - S
    n = np.cross(d, rng.normal(size=(300, 3)))
    n /= np.linalg.norm(n, axis=1)[:, None]
    r = 0.5 * (r0 + r1)
    for delta, expect in ((1e-3, False), (-1e-3, True)):
        p = 0.5 * (S + E) + (r + delta)[:, None] * n
        for k in range(0, 300, 37):
            seg, _ = _deposit(S[k:k + 1], E[k:k + 1], r0[k:k + 1], r1[k:k + 1], p[k:k + 1])
            assert (len(seg) == 1) == expect


def test_launch_options_reject_nonsense():
    with pytest.raises(WavepathsError):
        LaunchOptions(fan=2)
    with pytest.raises(WavepathsError):
        LaunchOptions(spacing=0.0)


def _path_keys(paths) -> dict:
    return {(int(paths.rx_index[i]), tuple(paths.interactions[i].tolist()), tuple(paths.primitive[i].tolist())): i
            for i in range(len(paths.rx_index))}


def test_the_launched_search_finds_the_paths_of_the_exhaustive_one(canyon):
    """``diffraction_candidates="launched"`` on the street canyon at R2+D2: the same paths
    (interactions and primitives per receiver) as the exhaustive search, at the same
    vertices (1e-9 m), from fewer diffracted candidates carried by the fans than the
    exhaustive search joins (the launched tiles also enumerate E-D-R); a sparse fan loses
    some paths but finds no path the exhaustive search does not (the tests are the exact ones)."""
    from wavepaths.search import trace

    scene, _, pts, _ = canyon
    base = TraceOptions(max_reflections=2, diffraction=True, diffraction_reflections=2)
    ex = trace(scene, TX, pts, base)
    la = trace(scene, TX, pts, base.with_(diffraction_candidates="launched"))
    ke, kl = _path_keys(ex), _path_keys(la)
    assert len(ke) > 1000 and ke.keys() == kl.keys()
    for k, i in ke.items():
        np.testing.assert_allclose(la.vertices[kl[k]], ex.vertices[i], atol=1e-9)
    joined = sum(v for k, v in ex.stats.items() if k.startswith("diffraction_") and k.endswith("_candidates"))
    assert la.stats["launched_candidates"] < joined
    sparse = trace(scene, TX, pts, base.with_(diffraction_candidates="launched", launch_fan=8))
    ks = _path_keys(sparse)
    assert ks.keys() < ke.keys()
    for k, i in ks.items():
        np.testing.assert_allclose(sparse.vertices[i], ex.vertices[ke[k]], atol=1e-9)


def test_trace_options_check_the_launched_fields():
    with pytest.raises(WavepathsError, match="diffraction_candidates"):
        TraceOptions(diffraction_candidates="sampled")
    with pytest.raises(WavepathsError, match="launch_fan"):
        TraceOptions(launch_fan=2)
    with pytest.raises(WavepathsError, match="reflection_candidates"):
        TraceOptions(reflection_candidates="rays")
    with pytest.raises(WavepathsError, match="launch_rays"):
        TraceOptions(launch_rays=1)
    assert TraceOptions().diffraction_candidates == "exhaustive" and not TraceOptions().launched
    assert TraceOptions(reflection_candidates="launched").launched and TraceOptions(diffraction_candidates="launched").launched


def test_launched_reflections_find_the_exhaustive_chains(canyon):
    """``reflection_candidates="launched"`` at three reflections: the same specular paths as
    the exhaustive search, at the same vertices; with too few rays some are missed and none
    is invented."""
    from wavepaths.search import trace

    scene, _, pts, _ = canyon
    base = TraceOptions(max_reflections=3, diffraction=False)
    ex = trace(scene, TX, pts, base)
    la = trace(scene, TX, pts, base.with_(reflection_candidates="launched", launch_rays=1 << 16))
    ke, kl = _path_keys(ex), _path_keys(la)
    assert len(ke) > 150 and ke.keys() == kl.keys()
    for k, i in ke.items():
        np.testing.assert_allclose(la.vertices[kl[k]], ex.vertices[i], atol=1e-9)
    sparse = _path_keys(trace(scene, TX, pts, base.with_(reflection_candidates="launched", launch_rays=64)))
    assert sparse.keys() < ke.keys()


def test_fibonacci_directions_cover_the_sphere_evenly():
    """Unit vectors; every direction of a random sample has a lattice direction within
    twice the nominal spacing sqrt(4 pi / n)."""
    from wavepaths.search.rays import fibonacci_directions

    n = 4096
    u = fibonacci_directions(n)
    np.testing.assert_allclose(np.linalg.norm(u, axis=1), 1.0, atol=1e-12)
    probe = np.random.default_rng(5).normal(size=(2000, 3))
    probe /= np.linalg.norm(probe, axis=1)[:, None]
    nearest = np.arccos(np.clip((probe @ u.T).max(axis=1), -1, 1))
    assert nearest.max() < 2 * np.sqrt(4 * np.pi / n)


def test_chain_rows_look_up_chains():
    from wavepaths.search.txrays import chain_rows

    table = np.array([[3, 1], [0, 2], [5, 5], [1, 3]])
    got = chain_rows(table, np.array([[1, 3], [2, 0], [5, 5], [3, 1]]))
    assert got.tolist() == [3, -1, 2, 0]
    with pytest.raises(WavepathsError):
        chain_rows(np.array([[1, 2], [1, 2]]), np.array([[1, 2]]))


@pytest.mark.skipif(not kernels.available(), reason="numba not installed (the `fast` extra)")
def test_compiled_branches_equal_the_numpy_ones(canyon, rng):
    """Rays from random points to random points of random polygons: the compiled branch
    kernel gives the numpy reference's (hit, polygon, step) triples; some hits branch."""
    from wavepaths.search.rays import neighbour_branches as _neighbour_branches

    scene = canyon[0]
    k = 3000
    poly = rng.integers(0, scene.num_polygons, k)
    tri = scene.vertices[scene.triangles[scene.polygon_tris[scene.polygon_tri_ptr[poly]]]]
    w = rng.dirichlet(np.ones(3), k)
    x = np.einsum("kj,kjd->kd", w, tri)
    origin = rng.uniform(-80, 80, (k, 3))
    origin[:, 2] = rng.uniform(0, 30, k)
    u = x - origin
    u /= np.linalg.norm(u, axis=1)[:, None]
    radius = rng.uniform(0.1, 8.0, k)
    got = _neighbour_branches(scene, poly, x, u, radius, origin, compiled=True)
    ref = _neighbour_branches(scene, poly, x, u, radius, origin, compiled=False)
    key = lambda r: sorted(zip(r[0].tolist(), r[1].tolist(), np.round(r[2], 9).tolist()))
    assert key(got) == key(ref) and len(ref[0]) > 50


@pytest.mark.skipif(not kernels.available(), reason="numba not installed (the `fast` extra)")
def test_elliptic_tubes_compiled_equal_numpy_and_have_their_semi_axes(monkeypatch, rng):
    """Tubes with an elliptic cross-section (semi-axis r along ``across``, s along the other
    normal, a cap of length r past a clamped end), in float64 and float32: the compiled walk
    and the numpy reference give the same pairs; a point 1 mm inside a semi-axis (across, the
    other normal, past the end) is in, 1 mm outside is out."""
    S = rng.normal(size=(300, 3)) * 10
    E = S + rng.normal(size=(300, 3)) * 5
    d = (E - S) / np.linalg.norm(E - S, axis=1)[:, None]
    a = np.cross(d, rng.normal(size=(300, 3)))
    a /= np.linalg.norm(a, axis=1)[:, None]
    r0, r1 = rng.uniform(0.5, 2, 300), rng.uniform(2, 6, 300)
    s0, s1 = 0.2 * r0, 0.3 * r1
    pts = rng.normal(size=(400, 3)) * 10
    for dt in (np.float64, np.float32):
        args = [x.astype(dt) for x in (S, E, r0, r1)]
        kw = {"s0": s0.astype(dt), "s1": s1.astype(dt), "across": a.astype(dt)}
        got = set(zip(*(x.tolist() for x in _deposit(*args, pts, **kw))))
        monkeypatch.setattr(kernels, "available", lambda: False)
        ref = set(zip(*(x.tolist() for x in _deposit(*args, pts, **kw))))
        monkeypatch.undo()
        assert got == ref and len(ref) > 50
        round_ = set(zip(*(x.tolist() for x in _deposit(*args, pts))))
        assert ref < round_  # thinner than the round tube of radius r
    b = np.cross(d, a)
    mid, r, s = 0.5 * (S + E), 0.5 * (r0 + r1), 0.5 * (s0 + s1)
    for delta, expect in ((-1e-3, True), (1e-3, False)):
        for k in range(0, 300, 29):
            one = dict(s0=s0[k:k + 1], s1=s1[k:k + 1], across=a[k:k + 1])
            for p in (mid[k] + (r[k] + delta) * a[k], mid[k] + (s[k] + delta) * b[k], E[k] + (r1[k] + delta) * d[k]):
                seg, _ = _deposit(S[k:k + 1], E[k:k + 1], r0[k:k + 1], r1[k:k + 1], p[None], **one)
                assert (len(seg) == 1) == expect


def test_a_tube_the_box_test_drops_reaches_no_point_of_the_box(rng):
    """``_reaches_box`` is conservative: of random segments with growing radii, those it
    drops have no point of a dense cloud in the box within their tube, and it drops most
    segments that rise away from a flat box."""
    from wavepaths.search.tubes import reaches_box as _reaches_box

    lo, hi = np.array([-20.0, -10.0, 1.0]), np.array([20.0, 10.0, 2.0])
    S = rng.uniform(-40, 40, (3000, 3))
    S[:, 2] = rng.uniform(0, 20, 3000)
    E = S + rng.normal(size=(3000, 3)) * 30
    r0 = rng.uniform(0, 1, 3000)
    r1 = r0 + rng.uniform(0, 8, 3000)
    keep = _reaches_box(S, E, r0, r1, lo, hi)
    assert 0.1 < keep.mean() < 0.9
    cloud = rng.uniform(lo, hi, (20000, 3))
    seg, _ = _deposit(S[~keep], E[~keep], r0[~keep], r1[~keep], cloud)
    assert len(seg) == 0
    seg, _ = _deposit(S[keep], E[keep], r0[keep], r1[keep], cloud)
    assert len(np.unique(seg)) > 0.3 * keep.sum()
    up = np.column_stack([np.zeros(100), np.zeros(100), np.full(100, 10.0)])
    assert not _reaches_box(up, up + [0, 0, 500], np.full(100, 0.5), np.full(100, 25.0), lo, hi).any()


def test_fans_traced_once_for_a_box_give_each_subset_its_own_candidates(canyon):
    """The Keller fans traced once for the box of all receivers (:func:`fan_segments`, what
    a coverage map does) give any subset of them the candidates its own fans give; a point
    outside the box is refused."""
    from wavepaths.search.launch import fan_segments

    scene, ctx, pts, _ = canyon
    samples = edge_samples(scene, ctx)
    segs = fan_segments(scene, ctx, pts.min(axis=0), pts.max(axis=0), LaunchOptions(), samples)
    assert segs.start.dtype == np.float32 and len(segs) > 1000
    sub = pts[::3]
    own = candidate_sequences(scene, ctx, sub, LaunchOptions(), samples)
    cached = candidate_sequences(scene, ctx, sub, LaunchOptions(), samples, segs)
    assert own.keys() == cached.keys() and len(own) > 100
    with pytest.raises(WavepathsError, match="box"):
        candidate_sequences(scene, ctx, pts.max(axis=0)[None] + 1.0, LaunchOptions(), samples, segs)


def test_the_shipped_context_holds_only_the_named_sources_and_finds_the_same_paths(canyon):
    """What a launched map sends its workers (:func:`shipped_context`): the diffraction
    sources with reflections before the edge cut to those the cached fans name, the order-0
    sources whole (the tiles enumerate E-D-R over every edge the transmitter sees), the
    segments renumbered, no edge samples; its tiles find exactly the paths of the full context."""
    import dataclasses

    from wavepaths.search.launched import prepare_launched, shipped_context

    scene, ctx, pts, _ = canyon
    full = dataclasses.replace(ctx, options=ctx.options.with_(diffraction_candidates="launched"), derived={})
    prepare_launched(scene, full, pts)
    ship = shipped_context(full)
    n_full = sum(len(s.dihedron) for s in full.diffraction_sources)
    n_ship = sum(len(s.dihedron) for s in ship.diffraction_sources)
    assert 0 < n_ship < n_full
    np.testing.assert_array_equal(ship.diffraction_sources[0].dihedron, full.diffraction_sources[0].dihedron)
    np.testing.assert_array_equal(ship.diffraction_sources[0].chain, full.diffraction_sources[0].chain)
    assert not any(isinstance(k, tuple) and k[0] == "launch_samples" for k in ship.derived)
    got = {}
    for c in (full, ship):
        batches, _ = trace_tile(scene, c, pts)
        got[id(c)] = {(int(b.rx_index[i]), tuple(b.primitive[i].tolist())): b.vertices[i]
                      for b in batches for i in range(len(b.rx_index))}
    a, b = got[id(full)], got[id(ship)]
    assert len(a) > 1000 and a.keys() == b.keys()
    assert all(np.allclose(a[k], b[k], atol=1e-12) for k in a)


def _slit_scene(back_wall: bool):
    """A roof edge 30 m away that the transmitter sees only through a 6 cm slit in a wall (found
    by a review), and optionally a wall beyond the roof to reflect off."""
    from ..conftest import boxes_scene

    half = 0.03
    boxes = [((10, -20, 0), (10.2, -half, 30)), ((10, half, 0), (10.2, 20, 30)), ((30, -20, 0), (40, 20, 10))]
    return boxes_scene(boxes + ([((60, -20, 0), (61, 20, 30))] if back_wall else []))


_SLIT_TX = np.array([[0.0, 0.0, 1.5]])
_SLIT_RX = np.array([[45.0, 0.0, 12.0], [36.0, 0.05, 11.0], [34.0, -0.1, 10.5], [50.0, 0.1, 13.0]])


def _sorted_keys(p) -> list:
    return sorted((int(p.rx_index[i]), tuple(p.interactions[i, : p.depth[i]].tolist()),
                   tuple(p.primitive[i, : p.depth[i]].tolist())) for i in range(len(p)))


def test_first_order_diffraction_over_an_edge_seen_through_a_slit_is_found_by_a_launched_search():
    """The roof edge behind the slit: the samples on either side of its lit stretch are hidden
    and no fan starts there, which lost every path over that edge until the launched search
    enumerated first-order diffraction without reflections (E-D-R) as the exhaustive one does
    (wavepaths.search.launched). Those paths are now all found, on the same dihedra."""
    from wavepaths.search import trace

    scene = _slit_scene(back_wall=False)
    opts = TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=0)
    exhaustive = trace(scene, _SLIT_TX, _SLIT_RX, opts)
    launched = trace(scene, _SLIT_TX, _SLIT_RX, opts.with_(diffraction_candidates="launched"))
    assert len(exhaustive) >= 3 and _sorted_keys(launched) == _sorted_keys(exhaustive)
    assert np.allclose(launched.vertices, exhaustive.vertices, atol=1e-12, equal_nan=True)


def test_a_first_order_diffraction_the_fans_missed_on_the_street_canyon_is_found():
    """A review's street-canyon map (twenty-fifth session, 4 m cells, R2+D1, the transmitter at
    (-60.3, 0.7, 10.1)): the launched search missed a 65 m E-D-R path off building_south_0 to a
    cell behind the north buildings, at 256 and at 1,024 fan directions. Enumerated, it is there,
    and the launched paths are the exhaustive ones."""
    from wavepaths import load_scene
    from wavepaths.search import trace

    scene = load_scene("street_canyon")
    tx, rx = np.array([[-60.3, 0.7, 10.1]]), np.array([[-42.3, 34.37, 1.5]])
    opts = TraceOptions(max_reflections=2, diffraction=True, diffraction_reflections=1)
    exhaustive = trace(scene, tx, rx, opts)
    launched = trace(scene, tx, rx, opts.with_(diffraction_candidates="launched"))
    d_only = [k for k in _sorted_keys(exhaustive) if k[1] == (2,)]
    assert d_only and set(d_only) <= set(_sorted_keys(launched))
    assert _sorted_keys(launched) == _sorted_keys(exhaustive)


def test_a_diffraction_then_reflection_over_an_edge_seen_through_a_slit_starts_a_fan():
    """The same edge with a wall beyond it: the D-R paths over the edge come from fans (7 such
    paths here). They were missed until the twenty-eighth session: the visibility march
    stopped at the wall's shadow, 2 mm beyond the slit's side face's (its float32 hint named
    the wall at their corner; it now probes once more, deeper), and the window's end samples
    stood on shadow boundaries, hidden by the occlusion rule (they now stand 1e-3 spacings
    inside). Either change alone leaves all 7 missed."""
    from wavepaths.search import trace

    scene = _slit_scene(back_wall=True)
    opts = TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=1)
    exhaustive = trace(scene, _SLIT_TX, _SLIT_RX, opts)
    launched = trace(scene, _SLIT_TX, _SLIT_RX, opts.with_(diffraction_candidates="launched"))
    dr = [k for k in _sorted_keys(exhaustive) if k[1] == (2, 1)]
    assert len(dr) >= 3 and _sorted_keys(launched) == _sorted_keys(exhaustive)
