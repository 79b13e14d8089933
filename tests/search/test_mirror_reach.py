"""The per-mirror reach lists of the receiver side (``reach.mirror_reach``): a dihedron
left out of a polygon's list has no edge point whose diffracted cone meets the polygon."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths.scene import load_scene
from wavepaths.search import TraceOptions, kernels
from wavepaths.search.context import build_tx_context
from wavepaths.search.diffraction import _source_frames
from wavepaths.search.reach import mirror_reach
from wavepaths.search.geometry import diffraction_point_parameter

needs_numba = pytest.mark.skipif(not kernels.available(), reason="numba not installed (the `fast` extra)")

TX = np.array([[-60.0, 0.0, 10.0]])


def _polygon_samples(scene, rng, per_triangle: int) -> tuple[np.ndarray, np.ndarray]:
    """Random points on every triangle, corners included: (k, 3) points and their polygons (k,)."""
    tri = scene.vertices[scene.triangles]  # (T, 3, 3)
    u = rng.uniform(size=(len(tri), per_triangle, 2))
    flip = u.sum(axis=2) > 1
    u[flip] = 1 - u[flip]
    pts = tri[:, :1] + u[..., :1] * (tri[:, 1:2] - tri[:, :1]) + u[..., 1:] * (tri[:, 2:3] - tri[:, :1])
    pts = np.concatenate([pts, tri], axis=1)
    return pts.reshape(-1, 3), np.repeat(scene.triangle_polygon, per_triangle + 3)


@pytest.mark.parametrize("a", [0, 1, 2])
def test_a_dihedron_left_out_of_a_list_reaches_no_point_of_the_polygon(a, rng):
    """For every source of order ``a`` and every sampled point X of every polygon: if the
    closed-form diffraction point from the source's image to X (seed §2.3) lies on the
    edge, X is on that point's Keller cone, so the dihedron must be in the polygon's list.
    And the lists leave pairs out (the test would otherwise show nothing)."""
    scene = load_scene("street_canyon")
    ctx = build_tx_context(scene, TX, TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=2,
                                                   compiled=False))
    _, frame = _source_frames(scene, ctx, a)
    reach = mirror_reach(scene, frame, compiled=False)
    P, u = scene.num_polygons, len(frame.dihedra)
    listed = np.zeros((P, len(scene.dihedra.length)), bool)
    listed[np.repeat(np.arange(P), reach.sizes(np.arange(P))), reach.dihedra] = True
    assert 0 < len(reach.dihedra) < P * u
    pts, poly = _polygon_samples(scene, rng, 12)
    src = ctx.diffraction_sources[a]
    S = ctx.levels[a].last[src.chain]
    dih = scene.dihedra
    reached = 0
    for i in range(len(src.chain)):
        d = src.dihedron[i]
        t = diffraction_point_parameter(S[i][None], pts, dih.origin[d][None], dih.direction[d][None])
        on = (t >= 0) & (t <= dih.length[d])
        reached += int(on.sum())
        missing = np.unique(poly[on][~listed[poly[on], d]])
        assert len(missing) == 0, f"source {i}, dihedron {d}: polygons {missing} reached but not listed"
    assert reached > 0


@needs_numba
@pytest.mark.parametrize("a", [0, 1])
def test_compiled_lists_equal_numpy(a):
    scene = load_scene("street_canyon")
    ctx = build_tx_context(scene, TX, TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=1))
    _, frame = _source_frames(scene, ctx, a)
    ref = mirror_reach(scene, frame, compiled=False)
    got = mirror_reach(scene, frame, compiled=True)
    np.testing.assert_array_equal(got.ptr, ref.ptr)
    np.testing.assert_array_equal(got.dihedra, ref.dihedra)


def test_list_chunks_cover_every_row_within_the_budget(rng):
    """The chunks of the listed receiver side: consecutive, every row once, at most
    ``max_rows`` rows, and at most ``budget`` listed pairs beyond a chunk's first row (a row
    larger than the budget starts a chunk of its own)."""
    from wavepaths.search.diffraction import _list_chunks

    sizes = rng.integers(0, 50, 1000)
    sizes[[10, 500]] = 400  # rows larger than the budget: a chunk of their own
    for budget, max_rows in ((100, 64), (10_000, 64), (100, 10_000)):
        b = _list_chunks(sizes, budget, max_rows)
        assert b[0] == 0 and b[-1] == len(sizes) and np.all(np.diff(b) > 0)
        for lo, hi in zip(b[:-1], b[1:]):
            assert hi - lo <= max_rows
            assert sizes[lo + 1:hi].sum() <= budget
        if budget < 400:
            assert {10, 500} <= set(b.tolist())  # each larger row starts a chunk
    assert list(_list_chunks(np.zeros(0, np.int64), 100, 64)) == [0]
