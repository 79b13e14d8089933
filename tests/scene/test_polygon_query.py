"""Point-in-polygon: the compiled loop (numba, optional) against the numpy reference, and
against the geometry (inside, outside, on vertices and edges of the triangles)."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths.scene import load_scene
from wavepaths.scene import polygon_query
from wavepaths.scene.polygon_query import points_in_polygons

needs_numba = pytest.mark.skipif(polygon_query._compiled() is None, reason="numba is not installed (the `fast` extra)")


def _queries(scene, rng, n):
    """Points in each query polygon's plane, around its first triangle (about half inside),
    plus points exactly on that triangle's vertices and edge midpoints."""
    q = rng.integers(0, len(scene.polygon_normal), n)
    V = scene.vertices[scene.triangles[scene.polygon_tris[scene.polygon_tri_ptr[q]]]]
    lo, hi = V.min(1), V.max(1)
    p = lo + rng.uniform(-0.3, 1.3, (n, 3)) * (hi - lo)
    p -= (np.einsum("ij,ij->i", p, scene.polygon_normal[q]) - scene.polygon_offset[q])[:, None] * scene.polygon_normal[q]
    m = n // 10
    p[:m] = V[:m, 0]
    p[m : 2 * m] = 0.5 * (V[m : 2 * m, 0] + V[m : 2 * m, 1])
    return p, q, m


@pytest.mark.parametrize("name", ["street_canyon", "three_face_edge", "touching_blocks"])
def test_vertices_and_edges_of_a_polygon_are_inside_and_far_points_are_not(name, rng):
    scene = load_scene(name)
    p, q, m = _queries(scene, rng, 2000)
    for compiled in (False, None):
        got = points_in_polygons(scene, p, q, compiled=compiled)
        assert got[: 2 * m].all()  # closed: its own corners and edge midpoints
        # 2 scene diagonals away within each polygon's plane: outside every polygon
        n = scene.polygon_normal[q]
        axis = np.where((np.abs(n[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        u = np.cross(n, axis)
        far = p + 2 * scene.diagonal * u / np.linalg.norm(u, axis=1, keepdims=True)
        assert not points_in_polygons(scene, far, q, compiled=compiled).any()


@needs_numba
@pytest.mark.parametrize("name", ["street_canyon", "three_face_edge", "touching_blocks"])
def test_compiled_point_in_polygon_gives_the_numpy_answers_bit_for_bit(name, rng):
    scene = load_scene(name)
    p, q, _ = _queries(scene, rng, 20_000)
    ref = points_in_polygons(scene, p, q, compiled=False)
    assert 0.2 < ref.mean() < 0.9
    np.testing.assert_array_equal(points_in_polygons(scene, p, q, compiled=True), ref)
    # points nudged by +-1e-12 of the scene diagonal across the triangles' edges and corners
    nudge = (rng.uniform(-1, 1, p.shape) * 1e-12 * scene.diagonal)
    np.testing.assert_array_equal(points_in_polygons(scene, p + nudge, q, compiled=True),
                                  points_in_polygons(scene, p + nudge, q, compiled=False))


def test_compiled_true_without_numba_is_a_clear_error(monkeypatch):
    monkeypatch.setattr(polygon_query, "_compiled", lambda: None)
    scene = load_scene("street_canyon")
    with pytest.raises(ImportError, match="numba"):
        points_in_polygons(scene, np.zeros((1, 3)), np.zeros(1, np.int64), compiled=True)
