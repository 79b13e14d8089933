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


def solid_face_normals(scene: Scene, points: np.ndarray, budget: int = BUDGET) -> dict[int, np.ndarray]:
    """For each point lying on faces of solid objects: ``{point: (k, 3) outward unit normals}``
    of those faces (a point on a block's edge has two). Empty for points on no solid."""
    from ..scene.closed import solid_objects_mask

    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    i, q = _on_face_pairs(scene, points, budget)
    if len(i) == 0:
        return {}
    solid = solid_objects_mask(scene)[scene.polygon_object[q]] & (scene.outward_sign[q] != 0)
    i, q = i[solid], q[solid]
    normals = scene.polygon_normal[q] * scene.outward_sign[q][:, None]
    return {int(p): normals[i == p] for p in np.unique(i)}


def legs_into_solids(paths, tx_normals: dict[int, np.ndarray], rx_normals: dict[int, np.ndarray],
                     rx_offset: int = 0) -> np.ndarray:
    """(N,) bool: paths whose first leg leaves a transmitter lying on a solid's face into the
    solid, or whose last leg reaches a receiver lying on one from inside it.

    The occlusion rule lets a segment pass whose end lies on a face (docs/stress.md, "What
    blocks a segment"): from a point on a block's wall, a leg through the block crosses no face
    in its interior. A leg from such an end is inside the solid when it points against the
    outward normal of a face the end lies on by more than rounding (``d . n < -1e-12 |d|``);
    a leg along the face is the limit from outside and stays. ``rx_offset``: the receivers'
    index offset of ``paths`` (a coverage tile's).
    """
    bad = np.zeros(len(paths), dtype=bool)
    if not tx_normals and not rx_normals or len(paths) == 0:
        return bad
    rows = np.arange(len(paths))
    first = paths.vertices[:, 1] - paths.vertices[:, 0]
    back = paths.vertices[rows, paths.depth] - paths.vertices[rows, paths.depth + 1]  # from rx to the vertex before
    for index, legs, normals_of in ((paths.tx_index, first, tx_normals), (paths.rx_index + rx_offset, back, rx_normals)):
        for point, normals in normals_of.items():
            on = np.nonzero(index == point)[0]
            if len(on):
                d = legs[on]
                size = np.sqrt(np.einsum("ij,ij->i", d, d))
                bad[on] |= ((d @ normals.T) < -1e-12 * size[:, None]).any(axis=1)
    return bad
