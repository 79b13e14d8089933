"""End points lying exactly on faces: which face, and which objects' surfaces.

A transmitter or receiver within the casters' plane tolerance of a polygon's plane and
inside the polygon lies on that face. It takes part in no reflection or diffraction there
(docs/search.md), and it is on the surface of the face's object, not inside it: the ray-parity
inside test, which may answer either way on a surface, is overruled there, both for the
warnings and for the one-sided culling of closed objects (an end on a block's edge had the
block's faces reflect from inside, in one direction of travel only).
"""

from __future__ import annotations

import numpy as np

from ..scene.model import Scene

BUDGET = 50_000_000  # (points x polygons) distance tests; beyond it nothing is reported on a face


def _on_face_pairs(scene: Scene, points: np.ndarray, budget: int) -> tuple[np.ndarray, np.ndarray]:
    """``(point, polygon)`` index pairs of every point lying on a polygon (see the module docstring)."""
    from ..raycast import plane_tolerance
    from ..scene.polygon_query import points_in_polygons

    n, p = len(points), scene.num_polygons
    if n == 0 or p == 0 or n * p > budget:
        z = np.zeros(0, np.int64)
        return z, z
    tol = plane_tolerance(scene)
    step = max(1, (1 << 22) // p)
    rows, polys = [], []
    for s in range(0, n, step):
        pts = points[s : s + step]
        dist = np.abs(pts @ scene.polygon_normal.T - scene.polygon_offset[None, :])
        i, q = np.nonzero(dist <= tol)
        if len(i) == 0:
            continue
        on = points_in_polygons(scene, pts[i], q)
        rows.append(s + i[on])
        polys.append(q[on])
    if not rows:
        z = np.zeros(0, np.int64)
        return z, z
    return np.concatenate(rows), np.concatenate(polys)


def points_on_faces(scene: Scene, points: np.ndarray, budget: int = BUDGET) -> np.ndarray:
    """(n,) int64: a polygon each point lies exactly on (within the casters' plane tolerance), or -1.

    Such a point takes part in no reflection or diffraction on that polygon or its edges
    (its side of the face is undefined, docs/search.md), so the field computed there is
    the limit from neither side: :func:`~wavepaths.search.trace.trace` reports it. (points x
    polygons) distance tests, chunked; skipped (all -1) beyond ``budget`` of them.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.full(len(points), -1, dtype=np.int64)
    i, q = _on_face_pairs(scene, points, budget)
    out[i] = q  # (one of them, for a point on several)
    return out


def points_on_surfaces(scene: Scene, points: np.ndarray, budget: int = BUDGET) -> np.ndarray:
    """(n, objects) bool: whether each point lies exactly on a face of each object
    (every face it lies on counts: a point on a block's edge is on two of its faces)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.zeros((len(points), len(scene.object_names)), dtype=bool)
    i, q = _on_face_pairs(scene, points, budget)
    out[i, scene.polygon_object[q]] = True
    return out
