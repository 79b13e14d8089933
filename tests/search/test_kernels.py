"""The compiled kernels (numba, optional) against the numpy reference they replace."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

import wavepaths.search.end_sides as tile
from wavepaths.scene import load_scene, transformed
from wavepaths.search import TraceOptions, kernels, trace
from wavepaths.search.context import build_tx_context
from wavepaths.search.diffraction import _source_frames
from wavepaths.search.reach import mirror_reach
from wavepaths.search.images import build_image_levels

from .helpers import path_keys

needs_numba = pytest.mark.skipif(not kernels.available(), reason="numba is not installed (the `fast` extra)")

TX = np.array([[-60.0, 0.0, 10.0]])


def _receivers(rng, n: int) -> np.ndarray:
    street = rng.uniform(size=n) < 0.5
    y = np.where(street, rng.uniform(-9, 9, n), np.sign(rng.uniform(-1, 1, n)) * rng.uniform(27, 39, n))
    return np.column_stack([rng.uniform(-95, 95, n), y, np.full(n, 1.5)])


@needs_numba
def test_compiled_end_sides_equal_the_numpy_frame_and_sector_lookup(rng):
    """``_kept_pairs_end_side`` without a window: the compiled loop (frame, sector, width
    test) keeps the same pairs with the same sector, and the same angle, t and rho to
    rounding (1e-12: numpy's einsum may sum in another order on another CPU; bit for bit
    on some), and counts the same rejections; among the points, some on an edge line and
    some in a face's plane (at the margins of the on-face test)."""
    scene = load_scene("street_canyon")
    opts = TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=2)
    ctx_np = build_tx_context(scene, TX, opts.with_(compiled=False))
    ctx_nb = build_tx_context(scene, TX, opts)
    dih = scene.dihedra
    d_all = ctx_np.diffracting
    special = []
    for j in d_all[:20]:  # on the edge line, and 3 m out along each face
        special.append(dih.origin[j] + 0.3 * dih.length[j] * dih.direction[j])
        for f in range(dih.face_ptr[j], dih.face_ptr[j + 1]):
            special.append(dih.origin[j] + 3.0 * dih.face_direction[f])
    pts = np.concatenate([_receivers(rng, 30), np.array(special)])
    levels = build_image_levels(scene, pts, 2, True)
    for b in (0, 1, 2):
        lv = levels[b]
        e = np.repeat(np.arange(len(lv)), len(d_all))
        d = np.tile(d_all, len(lv))
        s_np, s_nb = Counter(), Counter()
        ref = tile._kept_pairs_end_side(scene, ctx_np, lv, e, d, None, s_np, "t")
        got = tile._kept_pairs_end_side(scene, ctx_nb, lv, e, d, None, s_nb, "t")
        assert 0 < len(ref.row) < len(e)
        for name in ("row", "dihedron", "sector"):
            np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)
        for name in ("phi", "t", "rho"):
            np.testing.assert_allclose(getattr(got, name), getattr(ref, name), rtol=1e-14, atol=1e-12, err_msg=name)
        assert s_nb == s_np


@needs_numba
@pytest.mark.parametrize("disabled", [frozenset(), frozenset({"receiver_beam"}), frozenset({"receiver_mirror_side"}),
                                      frozenset({"keller_window"})])
def test_compiled_receiver_side_keeps_the_same_pairs_as_numpy(disabled, rng):
    """Per (receiver image, dihedron) pair, at orders 0, 1 and 2, and at 1 and 2 also with the
    reach lists (the kernel that walks them against numpy's mask): the same survivors in the
    same order, the same sector and angle, and the same rejection counts per test (the
    kernel's extra aperture test off: numpy has none)."""
    disabled = disabled | {"receiver_aperture"}
    scene = load_scene("street_canyon")
    rx = _receivers(rng, 25)
    opts = TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=2, disable_culling=disabled)
    ctx = build_tx_context(scene, TX, opts.with_(compiled=False))  # _receiver_side: the numpy reference
    levels = build_image_levels(scene, rx, 2, opts.skip_absorbers)
    diffr = ctx.diffracting
    tside = tile._transmitter_side(scene, ctx, ctx.levels[0], ctx.diffraction_sources[0])
    window = None if "keller_window" in disabled else tile._keller_window(scene, tside)
    reach = mirror_reach(scene, _source_frames(scene, ctx, 0)[1])
    for b, lists in ((0, None), (1, None), (1, reach), (2, None), (2, reach)):
        rows = np.arange(len(levels[b]))
        s_np, s_nb = Counter(), Counter()
        ref = tile._receiver_side(scene, ctx, levels[b], rows, diffr, s_np, "t", window, lists)
        got = tile._receiver_side_compiled(scene, ctx, levels[b], rows, diffr, s_nb, "t", window, lists)
        assert len(ref.row) > 0
        if lists is not None:  # the listed kernel ran
            assert s_np["t_receiver_pairs_rejected_mirror_reach"] > 0
        np.testing.assert_array_equal(got.row, ref.row)
        np.testing.assert_array_equal(got.dihedron, ref.dihedron)
        np.testing.assert_array_equal(got.sector, ref.sector)
        np.testing.assert_allclose(got.phi, ref.phi, rtol=0, atol=1e-12)
        assert s_nb == s_np
        if b >= 1 and disabled == {"receiver_aperture"}:
            assert s_np["t_receiver_pairs_rejected_beam"] > 0 and s_np["t_receiver_pairs_rejected_mirror_side"] > 0


@needs_numba
def test_compiled_and_numpy_traces_find_the_same_paths(rng):
    scene = load_scene("street_canyon")
    rx = _receivers(rng, 40)
    opts = TraceOptions(max_reflections=2, diffraction=True, diffraction_reflections=2, rx_batch=16)
    fast = trace(scene, TX, rx, opts)
    ref = trace(scene, TX, rx, opts.with_(compiled=False))
    assert len(fast) > 100
    assert path_keys(fast) == path_keys(ref)
    # the aperture test rejects pairs the numpy reference sends on to the back-trace
    aperture = sum(v for k, v in fast.stats.items() if k.endswith("receiver_pairs_rejected_aperture"))
    assert aperture > 0
    assert sum(v for k, v in fast.stats.items() if k.endswith("_candidates") and k.startswith("diffraction")) < sum(
        v for k, v in ref.stats.items() if k.endswith("_candidates") and k.startswith("diffraction"))


@needs_numba
def test_aperture_test_keeps_every_pair_that_yields_a_path(rng):
    """Every diffracted path's (receiver image, dihedron) pair passes the aperture test: with
    the test on and off (all else equal, compiled) the same paths, and with it on the same
    counts as numpy for the tests before it."""
    scene = load_scene("street_canyon")
    rx = _receivers(rng, 60)
    opts = TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=3, rx_batch=16)
    on = trace(scene, TX, rx, opts)
    off = trace(scene, TX, rx, opts.with_(disable_culling={"receiver_aperture"}))
    assert sum(v for k, v in on.stats.items() if k.endswith("receiver_pairs_rejected_aperture")) > 0
    assert len(on) > 0 and path_keys(on) == path_keys(off)
    for k in off.stats:
        if "mirror_side" in k or "rejected_beam" in k:
            assert on.stats[k] == off.stats[k]


def test_without_numba_the_numpy_reference_runs(monkeypatch, rng):
    """No numba (or ``compiled=False``): the search falls back and finds the same paths."""
    scene = load_scene("street_canyon")
    rx = _receivers(rng, 20)
    opts = TraceOptions(max_reflections=1, diffraction=True, diffraction_reflections=1)
    called = []
    monkeypatch.setattr(tile, "_receiver_side_compiled", lambda *a, **k: called.append(1))
    monkeypatch.setattr(kernels, "available", lambda: False)
    ref = trace(scene, TX, rx, opts)
    assert not called and len(ref) > 0


@needs_numba
def test_compiled_chain_side_planes_equal_the_numpy_composition(rng):
    """The kernel's side planes equal apertures.chain_apertures then apertures.quad_side_planes (1e-12)."""
    from wavepaths.search.apertures import chain_apertures, quad_side_planes, scene_apertures

    scene = load_scene("street_canyon")
    rx = _receivers(rng, 6)
    levels = build_image_levels(scene, rx, 3, True)
    quads = scene_apertures(scene).quads
    for k in (1, 2, 3):
        lv = levels[k]
        rows = np.arange(len(lv))
        assert len(rows) > 10
        _, _, qd = chain_apertures(scene, lv, rows, quads=quads)
        ref = np.concatenate([quad_side_planes(lv.last[rows], qd[:, j]) for j in range(k)], axis=1)
        got = kernels.chain_side_planes(lv.last[rows], lv.polygons[rows], quads, scene.polygon_normal,
                                        scene.polygon_offset)
        assert got.shape == (len(rows), 4 * k, 3)
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)


def _reflection_pairs(scene, ctx, order: int, rx: np.ndarray):
    """beams.reflection_candidates as a set of (receiver, chain) pairs, checked to hold each
    pair once; with how many it yielded and the counters."""
    from wavepaths.search.beams import reflection_candidates

    stats = Counter()
    got = list(reflection_candidates(scene, ctx, order, rx, stats, 1 << 12))
    r = np.concatenate([g[0] for g in got])
    c = np.concatenate([g[1] for g in got])
    pairs = set(zip(r.tolist(), c.tolist()))
    assert len(pairs) == len(r)  # each pair once
    return pairs, len(r), stats


@needs_numba
@pytest.mark.parametrize("order", [1, 2, 3])
def test_compiled_reflection_candidates_equal_the_numpy_tree_query(order, rng, monkeypatch):
    """beams.reflection_candidates: the same (receiver, chain) pairs and the same culled count,
    compiled (one descent per cluster) or numpy (blocks of (cluster, node) pairs)."""
    from wavepaths.search import beams

    monkeypatch.setattr(beams, "FLAT_MAX_CLUSTER_SIZE", 0.0)  # the tree, whatever the clusters
    scene = load_scene("street_canyon")
    rx = np.concatenate([_receivers(rng, 150), rng.uniform([-90, -8, 1], [90, 8, 30], size=(50, 3))])
    opts = TraceOptions(max_reflections=3, diffraction=False)
    pairs, culled = {}, {}
    for compiled in (True, False):
        ctx = build_tx_context(scene, TX, opts.with_(compiled=compiled))
        pairs[compiled], _, stats = _reflection_pairs(scene, ctx, order, rx)
        culled[compiled] = stats[f"reflection_order_{order}_culled_beam"]
    assert len(pairs[True]) > 100 and culled[True] > 0
    assert pairs[True] == pairs[False]
    assert culled[True] == culled[False]


@needs_numba
@pytest.mark.parametrize("order", [1, 2, 3])
def test_flat_reflection_candidates_hold_the_tree_candidates_and_give_the_same_paths(order, rng, monkeypatch):
    """Scattered receivers (one per cluster): the compiled search tests every (chain, receiver)
    pair with the point test alone (kernels.reflection_pairs_flat). Its pairs hold every pair
    of the tree query (which adds bounding-sphere tests), each once, with the same culled
    count for the pairs it drops; the traced paths are the same."""
    from wavepaths.search import beams

    scene = load_scene("street_canyon")
    rx = np.concatenate([_receivers(rng, 60), rng.uniform([-90, -8, 1], [90, 8, 30], size=(20, 3))])
    opts = TraceOptions(max_reflections=3, diffraction=False)
    ctx = build_tx_context(scene, TX, opts)
    pairs = {}
    for name, size in (("tree", 0.0), ("flat", 1e9)):
        monkeypatch.setattr(beams, "FLAT_MAX_CLUSTER_SIZE", size)
        pairs[name], kept, stats = _reflection_pairs(scene, ctx, order, rx)
        assert stats[f"reflection_order_{order}_culled_beam"] == len(rx) * len(ctx.levels[order]) - kept
    assert len(pairs["tree"]) > 50 and pairs["tree"] <= pairs["flat"]
    paths = {}
    for name, size in (("tree", 0.0), ("flat", 1e9)):
        monkeypatch.setattr(beams, "FLAT_MAX_CLUSTER_SIZE", size)
        paths[name] = path_keys(trace(scene, TX, rx, opts))
    assert len(paths["tree"]) > 100 and paths["tree"] == paths["flat"]


@needs_numba
@pytest.mark.parametrize("order", [1, 2])
def test_compiled_chains_meeting_edges_equal_the_numpy_tree_query(order, rng):
    """beams.chains_meeting_edges: the same (chain, dihedron) pairs compiled or in numpy, for
    the transmitter's chains and for receivers' chains."""
    from wavepaths.search.apertures import scene_apertures
    from wavepaths.search.beams import chains_meeting_edges, edge_tree

    scene = load_scene("street_canyon")
    apertures = scene_apertures(scene)
    tree = edge_tree(scene, np.nonzero(scene.dihedra.diffracting)[0])
    sources = np.concatenate([TX, _receivers(rng, 8)])
    lv = build_image_levels(scene, sources, order, True)[order]
    got = {}
    for compiled in (True, False):
        pairs = list(chains_meeting_edges(scene, lv, apertures, tree, chunk=37, compiled=compiled))
        c = np.concatenate([p[0] for p in pairs])
        e = np.concatenate([p[1] for p in pairs])
        got[compiled] = set(zip(c.tolist(), e.tolist()))
        assert len(got[compiled]) == len(c)
    assert 100 < len(got[True]) < len(lv) * len(tree)
    assert got[True] == got[False]


@needs_numba
@pytest.mark.parametrize("lit_region", [False, True])
def test_compiled_join_and_prefilter_keep_the_same_candidates_as_numpy(lit_region, rng, monkeypatch):
    """The join on (dihedron, sector) with the closed-form point, the edge segment, the
    visibility windows (order 0) or aperture windows (order 1) and the lit-region test:
    the compiled loop keeps the same (receiver row, source row) pairs at the same ``t``, bit
    for bit, and counts the same rejections, in small chunks as in one."""
    import wavepaths.search.diffraction as diffraction

    scene = load_scene("street_canyon")
    rx = _receivers(rng, 40)
    opts = TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=1, lit_region=lit_region)
    ctx_np = build_tx_context(scene, TX, opts.with_(compiled=False))
    ctx_nb = build_tx_context(scene, TX, opts)
    levels = build_image_levels(scene, rx, 1, True)
    join_ranges = diffraction._join_ranges
    for a, b in ((0, 0), (0, 1), (1, 0)):
        src = ctx_np.diffraction_sources[a]
        tside = tile._transmitter_side(scene, ctx_np, ctx_np.levels[a], src)
        rside = tile._receiver_side(scene, ctx_np, levels[b], np.arange(len(levels[b])), np.unique(src.dihedron),
                                    Counter(), "t")
        for budget in (1 << 21, 37):
            # (patched where _joined_candidates looks it up: wavepaths.search.diffraction_join)
            monkeypatch.setattr("wavepaths.search.diffraction_join._join_ranges",
                                lambda s, k, _b=budget: join_ranges(s, k, _b))
            got = []
            for ctx in (ctx_np, ctx_nb):
                st = Counter()
                parts = list(diffraction._joined_candidates(scene, ctx, a, src, rside, tside, st, "t"))
                got.append(([np.concatenate([p[i] for p in parts]) for i in range(3)], st))
            (ref, s_np), (cmp, s_nb) = got
            assert len(ref[0]) > 0 and s_np["t_rejected_off_edge"] > 0
            for x, y in zip(cmp, ref):
                np.testing.assert_array_equal(x, y)
            assert s_nb == s_np
            assert (s_np["t_rejected_lit_region"] > 0) == (not lit_region)


def test_group_sorted_equals_the_sorting_group(rng):
    from wavepaths.search.context import _group, _group_sorted

    for n in (0, 1, 7, 500):
        keys = np.sort(rng.integers(0, max(n // 3, 1), n))
        for got, ref in zip(_group_sorted(keys), _group(keys)):
            np.testing.assert_array_equal(got, ref)
            assert got.dtype == ref.dtype


def _keller_reference(scene, ctx, order, targets):
    """(c,) bool: the Keller-cone test source by source, from the formula (no factoring by
    dihedron): R reaches the edge iff w.(R - A)/|R - A| >= cos beta_A and
    w.(R - B)/|R - B| <= cos beta_B, each side widened by the sphere's angular radius."""
    dh = scene.dihedra
    src = ctx.diffraction_sources[order]
    S = ctx.levels[order].last[src.chain]
    w = dh.direction[src.dihedron]
    A = dh.origin[src.dihedron]
    B = A + dh.length[src.dihedron][:, None] * w
    c = targets.mean(axis=0)
    r = float(np.linalg.norm(targets - c, axis=1).max()) * (1 + 1e-9) + 1e-9

    def unit_cos(v):
        return np.einsum("ij,ij->i", v, w) / np.linalg.norm(v, axis=1)

    def spread(X):
        dist = np.linalg.norm(c - X, axis=1)
        return np.where(dist > r, np.arcsin(np.clip(r / dist, 0, 1)), np.pi)

    th_a, th_b = np.arccos(np.clip(unit_cos(c - A), -1, 1)), np.arccos(np.clip(unit_cos(c - B), -1, 1))
    ok_a = np.cos(np.maximum(th_a - spread(A), 0.0)) >= unit_cos(A - S) - 1e-9
    ok_b = np.cos(np.minimum(th_b + spread(B), np.pi)) <= unit_cos(B - S) + 1e-9
    return ok_a & ok_b


@pytest.mark.parametrize("compiled", [False, pytest.param(True, marks=needs_numba)])
@pytest.mark.parametrize("order", [0, 1])
def test_keller_cone_culling_keeps_the_sources_of_the_formula(order, compiled, rng):
    """Per (source, dihedron), for receiver spheres from a point to the whole street: the
    kept pairs of the formula evaluated source by source (the engine factors the sphere's
    side by dihedron), some culled, and the transmitter side of the kept rows equal to the one computed on them alone."""
    from wavepaths.search.diffraction import _source_frames, keller_cone_keep

    scene = load_scene("street_canyon")
    ctx = build_tx_context(scene, TX, TraceOptions(max_reflections=1, diffraction=True, diffraction_reflections=1))
    tside_all, frame = _source_frames(scene, ctx, order)
    assert len(frame.inv) > 10
    assert order == 0 or len(frame.dihedra) < len(frame.inv)  # images share dihedra: the factoring is exercised
    culled = 0
    for spread in (0.0, 0.5, 5.0, 40.0):
        for _ in range(20):
            targets = _receivers(rng, 1)[0] + rng.normal(scale=spread + 1e-12, size=(16, 3))
            ref = _keller_reference(scene, ctx, order, targets)
            got = keller_cone_keep(frame, targets, compiled=compiled)
            np.testing.assert_array_equal(np.ones(len(ref), bool) if got is None else got, ref)
            culled += int((~ref).sum())
            if got is not None:
                rows = np.nonzero(got)[0]
                alone = tile._transmitter_side(scene, ctx, ctx.levels[order], ctx.diffraction_sources[order].take(rows))
                part = tside_all.take(rows)
                for name in ("row", "dihedron", "sector", "phi", "t", "rho"):
                    np.testing.assert_array_equal(getattr(part, name), getattr(alone, name), err_msg=name)
    assert culled > 0


@needs_numba
@pytest.mark.parametrize("order", [1, 2, 3])
def test_compiled_backtrace_equals_numpy(order, rng):
    """Receivers and random edge points back-traced through every chain of the transmitter's
    tree: the same survivors, rejection counts and (to rounding) reflection points."""
    from wavepaths.search.images import backtrace

    scene = load_scene("street_canyon")
    lv = build_image_levels(scene, TX, 3)[order]
    targets = np.concatenate([_receivers(rng, 40), scene.vertices[rng.integers(0, len(scene.vertices), 20)]])
    ti, ci = np.repeat(np.arange(len(targets)), len(lv)), np.tile(np.arange(len(lv)), len(targets))
    ref = backtrace(scene, targets[ti], lv, ci, compiled=False)
    got = backtrace(scene, targets[ti], lv, ci, compiled=True)
    assert 0 < len(ref[0]) < len(ci) and ref[2]["segment"] > 0 and ref[2]["outside_polygon"] > 0
    np.testing.assert_array_equal(got[0], ref[0])
    np.testing.assert_allclose(got[1], ref[1], rtol=0, atol=1e-9)
    assert got[2] == ref[2]


@needs_numba
@pytest.mark.parametrize("prune", [False, True])
def test_compiled_diffraction_candidates_equal_numpy(prune, rng, monkeypatch):
    """The compiled candidate stage (boundary flags, points on the edges, both back-traces,
    vertices) against its numpy reference in an otherwise identical (compiled) search: the
    same paths with the same vertices, and the same counts of every rejection, with and
    without the pruning of weak candidates."""
    import wavepaths.search.diffraction as diffraction

    scene = load_scene("street_canyon")
    rx = _receivers(rng, 30)
    opts = TraceOptions(max_reflections=1, diffraction=True, diffraction_reflections=2)
    if prune:
        opts = opts.with_(prune_db=30.0, prune_frequency_hz=3.5e9)
    fast = trace(scene, TX, rx, opts)
    monkeypatch.setattr(diffraction, "_diffraction_candidates_compiled", diffraction._diffraction_candidates_numpy)
    ref = trace(scene, TX, rx, opts)
    assert path_keys(fast) == path_keys(ref)
    np.testing.assert_allclose(fast.vertices, ref.vertices, rtol=0, atol=1e-9)
    for k in ref.stats:
        if k.startswith("diffraction_") and ("rejected_segment" in k or "outside_polygon" in k or "pruned" in k):
            assert fast.stats[k] == ref.stats[k], k
    assert fast.stats.get("pairs_on_boundaries", 0) == ref.stats.get("pairs_on_boundaries", 0)
    assert sum(v for k, v in ref.stats.items() if k.endswith("rejected_outside_polygon")) > 0
    if prune:
        assert ref.stats["pruned_paths_upper_bound"] > 0


@pytest.mark.skipif(not kernels.available(), reason="numba is not installed (the `fast` extra)")
def test_a_reflection_point_at_a_polygons_border_far_from_the_origin_is_decided_alike():
    """A reflection point within about 1e-9 of a polygon's border, the scene at 1e6 m and
    rotated: the numpy back-trace summed the plane distances with ``np.einsum``, in another
    order than the kernel, and kept the reflection the kernel rejected
    (``wavepaths._vec.dot3`` now gives both one order)."""
    from scipy.spatial.transform import Rotation

    from ..conftest import boxes_scene

    rng = np.random.default_rng(132)
    rng.random()
    boxes = []
    for _ in range(rng.integers(1, 4)):
        c, h = rng.uniform(-6, 6, 2), rng.uniform(0.5, 2.5, 3)
        boxes.append(((c[0] - h[0], c[1] - h[1], 0.0), (c[0] + h[0], c[1] + h[1], 2 * h[2])))
    scene = boxes_scene(boxes, ground=12)
    tx = np.array([15.79794501367834, -7.0275448989774, 3.7250117643823892])
    rx = np.array([-2.1154401060504933, 6.332519035780019, 3.262625883233236])
    R, T = Rotation.random(random_state=132).as_matrix(), np.array([1e6, -2e6, 3e5])
    moved = transformed(scene, R, T)
    found = []
    for compiled in (True, False):
        p = trace(moved, (tx @ R.T + T)[None], (rx @ R.T + T)[None],
                  TraceOptions(max_reflections=1, diffraction=False, compiled=compiled))
        found.append(sorted(tuple(p.primitive[i, : p.depth[i]].tolist()) for i in range(len(p))))
    assert found[0] == found[1]
