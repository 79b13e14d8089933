"""Point-in-polygon and plane queries on a scene's polygons, vectorised over points."""

from __future__ import annotations

from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from .model import Scene


def triangle_dual_basis(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Per-triangle map from a point in its plane to barycentric coordinates.

    With ``e1 = b - a``, ``e2 = c - a`` and Gram matrix ``G``, the rows of
    ``M = G^-1 [e1; e2]`` give ``(v, w) = M (p - a)`` and ``u = 1 - v - w``.

    Returns
    -------
    (f, 2, 3) float64
    """
    a = vertices[triangles[:, 0]]
    e1 = vertices[triangles[:, 1]] - a
    e2 = vertices[triangles[:, 2]] - a
    g11 = np.einsum("ij,ij->i", e1, e1)
    g12 = np.einsum("ij,ij->i", e1, e2)
    g22 = np.einsum("ij,ij->i", e2, e2)
    det = g11 * g22 - g12 * g12
    det = np.where(det > 0, det, np.inf)
    r1 = (g22[:, None] * e1 - g12[:, None] * e2) / det[:, None]
    r2 = (g11[:, None] * e2 - g12[:, None] * e1) / det[:, None]
    return np.stack([r1, r2], axis=1)


@lru_cache(maxsize=1)
def _compiled():
    """The compiled twin of :func:`points_in_polygons`, or ``None`` when numba is not installed."""
    try:
        from . import _numba
    except ImportError:
        return None
    return _numba.points_in_polygons


POLYGON_MARGIN = 1e-9
"""Margin of the barycentric inside test of :func:`points_in_polygons` (closed polygons): a
point on a polygon's border, up to the rounding of its coordinates, is inside."""


def polygon_margin_length(scene: "Scene") -> float:
    """[m] ``4 POLYGON_MARGIN`` of the scene's size: beyond this distance from a polygon's
    border no point is taken for inside it by :func:`points_in_polygons` (a barycentric
    margin is at most that fraction of the triangle's size, which is at most the scene's).
    Closer to an edge, a reflection point just beyond the edge may be accepted: the UTD
    boundary side follows the search within it (:func:`wavepaths.fields.chain._on_boundary_sides`),
    and an end point this close to an edge is reported
    (:func:`wavepaths.search.on_faces.points_near_edges`)."""
    return 4 * POLYGON_MARGIN * scene.diagonal


def points_in_polygons(scene: "Scene", points: np.ndarray, polygons: np.ndarray, eps: float = POLYGON_MARGIN,
                       compiled: bool | None = None) -> np.ndarray:
    """Whether ``points[i]`` lies inside polygon ``polygons[i]`` (closed).

    Tests the triangles of each query's polygon slot by slot (most polygons have one or
    two triangles), with the precomputed barycentric maps of
    :func:`triangle_dual_basis`, and keeps testing only the queries not yet inside. With
    numba installed (``compiled`` ``None`` or ``True``) the same tests run as one compiled
    loop per query (:mod:`wavepaths.scene._numba`), with the same arithmetic in the same
    order: the same answers.

    Parameters
    ----------
    scene : Scene
    points : (k, 3) float64
        Points on (or numerically near) the polygons' planes [m].
    polygons : (k,) int64
    eps : float
        Barycentric margin (accepts points on an edge shared by two triangles of one
        polygon despite rounding).

    Returns
    -------
    (k,) bool
    """
    k = len(points)
    out = np.zeros(k, dtype=bool)
    if k == 0:
        return out
    kernel = _compiled() if compiled is not False else None
    if compiled and kernel is None:
        raise ImportError("points_in_polygons(compiled=True) needs numba (pip install 'wavepaths[fast]')")
    if kernel is not None:
        return kernel(np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(polygons, dtype=np.int64),
                      scene.polygon_tri_ptr, scene.polygon_tris, scene.triangles, scene.vertices, scene.triangle_dual,
                      float(eps))
    dual = scene.triangle_dual
    origin = scene.vertices[scene.triangles[:, 0]]
    ptr = scene.polygon_tri_ptr
    counts = ptr[polygons + 1] - ptr[polygons]
    pending = np.arange(k)
    j = 0
    while len(pending):
        pending = pending[counts[pending] > j]
        if len(pending) == 0:
            break
        tri = scene.polygon_tris[ptr[polygons[pending]] + j]
        rel = points[pending] - origin[tri]
        m = dual[tri]
        v = m[:, 0, 0] * rel[:, 0] + m[:, 0, 1] * rel[:, 1] + m[:, 0, 2] * rel[:, 2]
        w = m[:, 1, 0] * rel[:, 0] + m[:, 1, 1] * rel[:, 1] + m[:, 1, 2] * rel[:, 2]
        hit = (v >= -eps) & (w >= -eps) & (v + w <= 1 + eps)
        out[pending[hit]] = True
        pending = pending[~hit]
        j += 1
    return out
