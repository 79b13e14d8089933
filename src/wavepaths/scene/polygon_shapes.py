"""The shapes later stages test the scene's polygons against: bounding spheres (the beam,
reach and aperture tests of the path search) and convex hulls (the occluders and mirrors of
:mod:`wavepaths.search.mirror_visibility`'s proofs). Pure geometry of the scene, kept on it
(:attr:`Scene.polygon_spheres`, :attr:`Scene.polygon_hulls`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from .model import Scene

MAX_HULL = 12
"""Hull corners kept per polygon; a polygon with more neither occludes nor is culled."""


def polygon_spheres(scene: "Scene") -> tuple[np.ndarray, np.ndarray]:
    """Bounding spheres of the polygons: centres (p, 3) and radii (p,) [m]."""
    corners = scene.vertices[scene.triangles]
    p = scene.num_polygons
    lo = np.full((p, 3), np.inf)
    hi = np.full((p, 3), -np.inf)
    np.minimum.at(lo, scene.triangle_polygon, corners.min(axis=1))
    np.maximum.at(hi, scene.triangle_polygon, corners.max(axis=1))
    centre = 0.5 * (lo + hi)
    dist = np.linalg.norm(corners - centre[scene.triangle_polygon][:, None, :], axis=2).max(axis=1)
    radius = np.zeros(p)
    np.maximum.at(radius, scene.triangle_polygon, dist)
    return centre, radius


@dataclass(frozen=True)
class PolygonHulls:
    """The convex hull of each polygon's corners, in its plane, counter-clockwise about its normal.

    Attributes
    ----------
    corners : (p, MAX_HULL, 3) float64
        Hull corners [m]; rows past ``count`` repeat the last corner.
    count : (p,) int64
        Corners of the hull (0 when the hull has more than ``MAX_HULL`` corners).
    edge_normal : (p, MAX_HULL, 3) float64
        In-plane unit normal of side ``k`` (corners ``k`` to ``k + 1``), pointing inside; zero
        past ``count``.
    edge_offset : (p, MAX_HULL) float64
        ``edge_normal[k] @ corners[k]``; ``-inf`` past ``count`` (a test every point passes).
    centre : (p, 3) float64
        The mean of the hull's corners [m] (where the hint rays aim).
    points : (p, MAX_HULL, 3) float64
        Points whose convex hull holds the polygon [m]: the hull's corners when every corner
        lies within the plane tolerance of the polygon's plane, else all its corners (a
        polygon merged within the coplanar angle is not flat: a corner inside the hull in
        the plane can stand off it); rows past ``num_points`` repeat the last point.
    num_points : (p,) int64
        How many (0 when they would be more than ``MAX_HULL``: the polygon is never culled).
    occluder : (p,) bool
        The polygon is convex (its triangles cover its hull) and planar (every corner within
        the plane tolerance of its plane), with at most ``MAX_HULL`` corners: it can serve
        as the occluder of the proof.
    """

    corners: np.ndarray
    count: np.ndarray
    edge_normal: np.ndarray
    edge_offset: np.ndarray
    centre: np.ndarray
    points: np.ndarray
    num_points: np.ndarray
    occluder: np.ndarray


def _hulls_2d(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Convex hulls of ``b`` point sets ``xy`` (b, m, 2), counter-clockwise, by gift wrapping.

    Returns ``idx`` (b, m) int64, the hull's points in order (rows past the hull's length
    repeat its last point), and ``length`` (b,). Collinear points on a side are left out
    (the farthest one is taken). Vectorised over the sets: ``m`` steps of ``m`` comparisons.
    """
    b, m = xy.shape[:2]
    rows = np.arange(b)
    start = np.lexsort((xy[:, :, 1], xy[:, :, 0]), axis=1)[:, 0] if b else np.zeros(0, np.int64)
    idx = np.zeros((b, m), np.int64)
    length = np.zeros(b, np.int64)
    cur = start.copy()
    done = np.zeros(b, bool)
    for step in range(m):
        idx[~done, step] = cur[~done]
        length[~done] += 1
        c = xy[rows, cur]
        best = (cur + 1) % m
        for k in range(m):
            vb = xy[rows, best] - c
            vk = xy[:, k] - c
            cross = vb[:, 0] * vk[:, 1] - vb[:, 1] * vk[:, 0]
            farther = (vk * vk).sum(axis=1) > (vb * vb).sum(axis=1)
            better = (cross < 0) | ((cross == 0) & farther)
            best = np.where(better & (k != cur), k, best)
        done |= best == start
        cur = np.where(done, cur, best)
        if done.all():
            break
    idx = np.where(np.arange(m)[None, :] < length[:, None], idx, idx[rows, np.maximum(length - 1, 0)][:, None])
    return idx, length


def polygon_hulls(scene: "Scene") -> PolygonHulls:
    """:class:`PolygonHulls` of every polygon of ``scene`` (cached as ``scene.polygon_hulls``).

    Polygons are taken in groups of equal corner counts, each group's hulls found at once
    (:func:`_hulls_2d`) in the polygon's plane.
    """
    from ..raycast import plane_tolerance

    p = scene.num_polygons
    corners = np.zeros((p, MAX_HULL, 3))
    count = np.zeros(p, np.int64)
    occluder = np.zeros(p, bool)
    points = np.zeros((p, MAX_HULL, 3))
    num_points = np.zeros(p, np.int64)
    n_all, d_all = scene.polygon_normal, scene.polygon_offset
    tv = scene.vertices[scene.triangles]
    tri_area = 0.5 * np.linalg.norm(np.cross(tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0]), axis=1)
    area = np.bincount(scene.triangle_polygon, tri_area, minlength=p)
    # each polygon's distinct corners, as (polygon, vertex) pairs sorted by polygon
    pv = np.unique(np.stack([np.repeat(scene.triangle_polygon, 3), scene.triangles.ravel()], 1), axis=0)
    ptr = np.searchsorted(pv[:, 0], np.arange(p + 1))
    size = np.diff(ptr)
    plane_tol = plane_tolerance(scene)
    for m in np.unique(size):
        if m < 3:
            continue
        poly = np.nonzero(size == m)[0]
        v = scene.vertices[pv[ptr[poly][:, None] + np.arange(m)[None, :], 1]]  # (b, m, 3)
        n = n_all[poly]
        helper = np.where((np.abs(n[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        u = np.cross(n, helper)
        u /= np.linalg.norm(u, axis=1)[:, None]
        w = np.cross(n, u)
        rel = v - v.mean(axis=1, keepdims=True)
        xy = np.stack([np.einsum("bmj,bj->bm", rel, u), np.einsum("bmj,bj->bm", rel, w)], axis=2)
        idx, length = _hulls_2d(xy)
        fits = (length >= 3) & (length <= MAX_HULL)
        h = idx[:, :MAX_HULL] if m >= MAX_HULL else np.concatenate(
            [idx, np.repeat(idx[:, -1:], MAX_HULL - m, axis=1)], axis=1)
        rows = np.arange(len(poly))[:, None]
        hx = xy[rows, idx]
        x, y = hx[..., 0], hx[..., 1]
        valid = np.arange(m)[None, :] < length[:, None]
        nxt = np.where(np.arange(m)[None, :] == (length - 1)[:, None], 0, np.arange(1, m + 1) % m)
        hull_area = 0.5 * np.abs(np.where(valid, x * np.take_along_axis(y, nxt, 1)
                                           - y * np.take_along_axis(x, nxt, 1), 0.0).sum(axis=1))
        planar = (np.abs(np.einsum("bmj,bj->bm", v, n) - d_all[poly][:, None]) <= plane_tol).all(axis=1)
        good = poly[fits]
        corners[good] = v[rows, h][fits]
        count[good] = length[fits]
        # the points that bound the polygon: the hull's corners if flat, else every corner
        points[good] = corners[good]
        num_points[good] = np.where(planar, length, 0)[fits]
        if m <= MAX_HULL:
            bent = poly[~planar]
            points[bent, :m] = v[~planar]
            points[bent, m:] = v[~planar][:, -1:]
            num_points[bent] = m
        occluder[good] = (planar & (hull_area > 0) & (np.abs(hull_area - area[poly]) <= 1e-9 * hull_area))[fits]
    # inward side normals: n x (c[k+1] - c[k]) for a counter-clockwise hull about n (u, w, n right-handed)
    nxt = np.roll(corners, -1, axis=1)
    k = np.arange(MAX_HULL)
    last = (k[None, :] == (count - 1)[:, None])
    nxt = np.where(last[..., None], corners[:, :1], nxt)
    side = np.cross(n_all[:, None, :], nxt - corners)
    norm = np.linalg.norm(side, axis=2)
    valid = (k[None, :] < count[:, None]) & (norm > 0)
    edge_normal = np.where(valid[..., None], side / np.where(norm > 0, norm, 1.0)[..., None], 0.0)
    edge_offset = np.where(valid, np.einsum("pkj,pkj->pk", edge_normal, corners), -np.inf)
    real = np.arange(MAX_HULL)[None, :, None] < count[:, None, None]
    centre = np.where(real, corners, 0.0).sum(axis=1) / np.maximum(count, 1)[:, None]
    return PolygonHulls(corners, count, edge_normal, edge_offset, centre, points, num_points, occluder)
