"""End points closer to an edge than the search's point-in-polygon margin are reported.

There a reflection on the edge's faces may be accepted at a point just beyond the edge,
where the exact geometry has none: a review moved a transmitter towards the built-in
wedge's edge and found the total field 0.3 to 30 nm from it off by up to 25 dB (against the
smooth limit it tends to from 1e-2 down to 1e-7 m), without a word.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from wavepaths import TraceOptions, trace
from wavepaths.scene import load_scene
from wavepaths.scene.polygon_query import polygon_margin_length
from wavepaths.search.on_faces import points_near_edges

NEAR = "of an edge, off its faces"
RX = np.array([[1.0, 3.0, 4.0], [-2.0, 6.0, -1.5], [3.0, -2.5, 2.0], [0.5, 0.3, 7.0], [2.0, -4.0, 0.5]])


def test_distances_to_the_edges_are_exact():
    """The wedge's edge is the x axis from -50 to 50 m: a point's distance is its distance to
    that segment (to its end beyond it), written out here."""
    scene = load_scene("wedge")
    m = polygon_margin_length(scene)
    u = np.array([0.0, 1.0, 1.0]) / np.sqrt(2)  # into the free space between the faces
    pts = np.array([[5.0, 0, 0] + 0.3 * m * u, [5.0, 0, 0] + 0.9 * m * u, [5.0, 0, 0] + 1.5 * m * u,
                    [50.0 + 0.5 * m, 0, 0] + 0.0 * u, [0.0, 3.0, 4.0]])
    edge, dist = points_near_edges(scene, pts)
    want = np.array([0.3 * m, 0.9 * m, np.inf, 0.5 * m, np.inf])
    np.testing.assert_allclose(dist[:2], want[:2], rtol=1e-6)
    assert dist[3] == pytest.approx(0.5 * m, rel=1e-6) and np.isinf(dist[[2, 4]]).all()
    # the first two on the x axis; the third beyond its end, as far from every edge meeting there
    assert edge[0] == edge[1] >= 0 and edge[3] >= 0
    assert np.abs(np.cross(scene.dihedra.direction[edge[0]], [1.0, 0, 0])).max() < 1e-12
    assert (edge[[2, 4]] == -1).all()


@pytest.mark.parametrize("d", [3e-8, 1e-8, 1e-9, 3e-10])
def test_a_transmitter_nanometres_from_an_edge_is_reported(d):
    """The review's distances, where the total field was off by up to 25 dB: a warning now."""
    scene = load_scene("wedge")
    tx = np.array([[5.0, 0.0, 0.0]]) + d * np.array([0.0, 1.0, 1.0]) / np.sqrt(2)
    with pytest.warns(UserWarning, match=NEAR):
        trace(scene, tx, RX, TraceOptions(max_reflections=2, diffraction_reflections=1))
    # and as a receiver (the search is symmetric)
    with pytest.warns(UserWarning, match=NEAR):
        trace(scene, RX[:1], tx, TraceOptions(max_reflections=1, diffraction_reflections=0))


def test_a_transmitter_beyond_the_margin_is_not_reported():
    scene = load_scene("wedge")
    tx = np.array([[5.0, 0.0, 0.0]]) + 1e-5 * np.array([0.0, 1.0, 1.0]) / np.sqrt(2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        trace(scene, tx, RX, TraceOptions(max_reflections=1, diffraction_reflections=0))


def test_coverage_reports_cell_centres_nanometres_from_an_edge():
    """A grid 0.1 um above the half-plane's edge (the x axis) with a row of centres in the
    screen's plane: those 4 are reported; 1 mm above, none."""
    from wavepaths.coverage import CoverageOptions, PlanarGrid, coverage

    scene = load_scene("half_plane")
    opts = TraceOptions(max_reflections=1, diffraction_reflections=0)
    settings = CoverageOptions(workers=1)
    tx = [[0.0, -3.0, 4.0]]
    grid = PlanarGrid(center=[0.25, 0.0], height=1e-7, size=[4.0, 3.0], cell_size=1.0)
    with pytest.warns(UserWarning, match=r"4 traced cell centres lie within \S+ m of an edge"):
        coverage(scene, tx, grid, opts, settings=settings)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        coverage(scene, tx, PlanarGrid(center=[0.25, 0.0], height=1e-3, size=[4.0, 3.0], cell_size=1.0), opts,
                 settings=settings, progress=False)


def test_the_plane_prefilter_finds_what_every_edge_tested_finds():
    """Points scattered around the street canyon's edges, within a few margins of them, and far
    from them: the plane prefilter and the exact distances to the candidates' edges give the
    edges and distances that testing every edge finds (written out here)."""
    scene = load_scene("street_canyon")
    m = polygon_margin_length(scene)
    D = scene.dihedra
    rng = np.random.default_rng(3)
    k = rng.integers(0, len(D.length), 3000)
    pts = D.origin[k] + rng.uniform(-0.1, 1.1, 3000)[:, None] * D.length[k, None] * D.direction[k] \
        + rng.normal(size=(3000, 3)) * 2 * m
    pts = np.concatenate([pts, rng.uniform(scene.bounds[0], scene.bounds[1], (500, 3))])
    edge, dist = points_near_edges(scene, pts)
    w = pts[:, None, :] - D.origin[None]
    t = np.clip(np.einsum("nkj,kj->nk", w, D.direction), 0.0, D.length)
    every = np.linalg.norm(w - t[..., None] * D.direction[None], axis=2)
    best = every.min(axis=1)
    near = best <= m
    r = 1e-13 * scene.diagonal  # the coordinates' rounding (the function works recentred)
    assert 100 < near.sum() < 3000  # both kinds of points
    clear = np.abs(best - m) > r
    np.testing.assert_array_equal((edge >= 0)[clear], near[clear])
    both = near & (edge >= 0)
    np.testing.assert_allclose(dist[both], best[both], rtol=0, atol=r)
    np.testing.assert_allclose(every[np.nonzero(both)[0], edge[both]], best[both], rtol=0, atol=r)  # a nearest edge


def test_a_reflection_only_trace_does_not_build_the_edges():
    """Without diffraction the report is not made (the geometrical-optics field jumps at an
    edge anyway), and a reflection-only trace does not build the scene's dihedra for it."""
    scene = load_scene("wedge")
    tx = np.array([[5.0, 0.0, 0.0]]) + 1e-8 * np.array([0.0, 1.0, 1.0]) / np.sqrt(2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        trace(scene, tx, RX, TraceOptions(max_reflections=1, diffraction=False))
    assert "dihedra" not in scene.__dict__
