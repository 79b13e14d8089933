"""OBJ faces of four or more vertices: finding those a fan triangulates wrongly, and ear clipping.

trimesh (and Mitsuba 3, ``src/shapes/obj.cpp``) split every OBJ face into a fan from its
first vertex, which covers area outside a concave face (an L-shaped roof gains the square
that closes the L). The geometry of faces in their planes (:func:`polygon_planes`, the fan's
triangles) and :func:`triangulate_polygon`, ear clipping in the plane, which
:mod:`wavepaths.scene.obj_reader` uses where the fan would leave the face (docs/scenes.md).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np


def _extent(points: np.ndarray, axis: int | None = None) -> np.ndarray | float:
    """Length of the bounding-box diagonal [m] of finite points (the rows of ``points``,
    or along ``axis`` of a stack of point sets)."""
    if axis is not None:
        return np.linalg.norm(np.ptp(points, axis=axis), axis=-1)
    finite = points[np.isfinite(points).all(axis=1)]
    return float(np.linalg.norm(np.ptp(finite, axis=0))) if len(finite) else 0.0


# ----------------------------------------------------------------------------- polygon geometry


@dataclass(frozen=True)
class PolygonPlanes:
    """The planes of ``m`` polygons of ``k`` vertices, and their vertices in plane coordinates.

    Attributes
    ----------
    normal : (m, 3) float64
        Unit normals (Newell's method: the right-hand rule on the vertex order).
    area : (m,) float64
        Areas of the polygons projected on their planes [m^2].
    deviation : (m,) float64
        Largest distance of a vertex from the plane through the vertices' centroid [m].
    uv : (m, k, 2) float64
        Vertices in an orthonormal frame of each plane, turning counter-clockwise.
    valid : (m,) bool
        False for a polygon of no area (below ``eps`` times its size): the other
        attributes of that row mean nothing.
    """

    normal: np.ndarray
    area: np.ndarray
    deviation: np.ndarray
    uv: np.ndarray
    valid: np.ndarray


def polygon_planes(points: np.ndarray, eps: float) -> PolygonPlanes:
    """The planes of a stack of 3-D polygons of the same vertex count.

    Parameters
    ----------
    points : (m, k, 3) float64
        Vertices [m], in order, finite.
    eps : float
        Length below which detail is unresolved [m].
    """
    p = points - points.mean(axis=1, keepdims=True)
    vector_area = 0.5 * np.cross(p, np.roll(p, -1, axis=1)).sum(axis=1)
    area = np.linalg.norm(vector_area, axis=1)
    valid = area > eps * np.maximum(_extent(points, axis=1), eps)
    normal = np.where(valid[:, None], vector_area, [0.0, 0.0, 1.0]) / np.where(valid, area, 1.0)[:, None]
    helper = np.eye(3)[np.argmin(np.abs(normal), axis=1)]
    u = np.cross(helper, normal)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.cross(normal, u)  # u x w = normal: each polygon turns counter-clockwise in (u, w)
    uv = np.stack([np.einsum("mkd,md->mk", p, u), np.einsum("mkd,md->mk", p, w)], axis=-1)
    deviation = np.abs(np.einsum("mkd,md->mk", p, normal)).max(axis=1)
    return PolygonPlanes(normal, area, deviation, uv, valid)


def _cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """z component of the cross product of 2-D vectors (last axis)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def fan_doubled_areas(uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed doubled areas ``(..., k - 2)`` of the fan triangles ``(0, i, i + 1)`` of
    polygons ``(..., k, 2)`` in plane coordinates (positive: turning like the polygon), and
    the triangles' longest sides [m]. A doubled area over the longest side is the smallest
    height of the triangle."""
    a, b, c = uv[..., :1, :], uv[..., 1:-1, :], uv[..., 2:, :]
    longest = np.maximum.reduce([np.linalg.norm(b - a, axis=-1), np.linalg.norm(c - b, axis=-1),
                                 np.linalg.norm(c - a, axis=-1)])
    return _cross2(b - a, c - a), longest


def fan_is_valid(uv: np.ndarray, eps: float) -> np.ndarray:
    """``(...)`` bool: the fan from the first vertex triangulates the polygon ``(..., k, 2)``:
    every fan triangle turns counter-clockwise with every height above ``eps`` (none leaves
    the polygon, none is degenerate, no fan diagonal passes through a vertex)."""
    doubled, longest = fan_doubled_areas(uv)
    return np.all(doubled > eps * longest, axis=-1)


def _drop_repeated(uv: np.ndarray, eps: float) -> np.ndarray:
    """Indices of the vertices kept once consecutive repeats (within ``eps``) are dropped."""
    keep = [0]
    for i in range(1, len(uv)):
        if np.hypot(*(uv[i] - uv[keep[-1]])) > eps:
            keep.append(i)
    while len(keep) > 1 and np.hypot(*(uv[keep[-1]] - uv[keep[0]])) <= eps:
        keep.pop()
    return np.array(keep)


class _EarClipper:
    """Ear clipping of a counter-clockwise polygon in the plane, robust to collinear vertices.

    A vertex is an ear tip when it is strictly convex (farther than ``eps`` from the line
    through its neighbours) and no reflex or flat vertex lies in (or within ``eps`` of) the
    triangle it makes with its neighbours, a vertex on the new diagonal included. Only
    reflex and flat vertices can lie in an ear, and clipping a tip changes the status of
    its two neighbours only, so each test costs O(k) and there are O(k) tests: O(k^2).
    """

    def __init__(self, uv: np.ndarray, eps: float) -> None:
        self.uv = uv
        self.eps = eps
        k = len(uv)
        self.prv = np.roll(np.arange(k), 1)
        self.nxt = np.roll(np.arange(k), -1)
        self.alive = np.ones(k, bool)
        self.convex = self._convexity(np.arange(k)) > 0
        self.clean = True  # every clip was an ear (False for a self-intersecting polygon)

    def _convexity(self, idx: np.ndarray) -> np.ndarray:
        """Doubled area of (prev, i, next) minus ``eps`` times |next - prev|: positive at
        strictly convex vertices."""
        a, b, c = self.uv[self.prv[idx]], self.uv[idx], self.uv[self.nxt[idx]]
        return _cross2(b - a, c - b) - self.eps * np.linalg.norm(c - a, axis=-1)

    def _is_ear(self, i: int) -> bool:
        if not self.convex[i]:
            return False
        a, c = self.prv[i], self.nxt[i]
        cand = np.flatnonzero(self.alive & ~self.convex)
        cand = cand[(cand != a) & (cand != c)]
        if cand.size == 0:
            return True
        q = self.uv[cand]
        corners = self.uv[[a, i, c]]
        inside = np.ones(len(q), bool)
        for p0, p1 in zip(corners, np.roll(corners, -1, axis=0)):
            edge = p1 - p0
            inside &= _cross2(edge, q - p0) >= -self.eps * np.hypot(*edge)
        on_corner = (np.linalg.norm(q[:, None, :] - corners[None], axis=2) <= self.eps).any(axis=1)
        return not np.any(inside & ~on_corner)

    def _fallback(self) -> int:
        """The most convex remaining vertex, clipped when no ear exists (self-intersection)."""
        self.clean = False
        idx = np.flatnonzero(self.alive)
        return int(idx[np.argmax(self._convexity(idx))])

    def _clip(self, i: int) -> tuple[int, int, int]:
        a, c = int(self.prv[i]), int(self.nxt[i])
        self.nxt[a], self.prv[c] = c, a
        self.alive[i] = False
        self.convex[[a, c]] = self._convexity(np.array([a, c])) > 0
        return a, i, c

    def run(self) -> np.ndarray:
        """Triangles ``(k - 2, 3)`` of indices into ``uv``."""
        k = len(self.uv)
        tris = []
        pending = deque(range(k))
        rescans = 2  # exact arithmetic never needs one; bounded, so the cost stays O(k^2)
        while k - len(tris) > 3:
            ear = None
            while pending and ear is None:
                i = pending.popleft()
                if self.alive[i] and self._is_ear(i):
                    ear = i
            if ear is None and rescans:
                rescans -= 1
                pending.extend(np.flatnonzero(self.alive).tolist())
                continue
            tri = self._clip(self._fallback() if ear is None else ear)
            tris.append(tri)
            pending.extendleft((tri[2], tri[0]))
        last = int(np.flatnonzero(self.alive)[0])
        tris.append((int(self.prv[last]), last, int(self.nxt[last])))
        return np.array(tris, dtype=np.int64).reshape(-1, 3)


def triangulate_polygon(uv: np.ndarray, eps: float) -> tuple[np.ndarray, bool]:
    """Triangulate a simple polygon given counter-clockwise in plane coordinates.

    Parameters
    ----------
    uv : (k, 2) float64
        Vertices, counter-clockwise (a row of :attr:`PolygonPlanes.uv`).
    eps : float
        Length below which detail is unresolved [m]: vertices closer than ``eps`` to a line
        count as on it, repeated vertices closer than ``eps`` are used once.

    Returns
    -------
    triangles : (m, 3) int64
        Indices into ``uv``, counter-clockwise; ``m = k - 2`` when no vertex repeats. The
        triangles cover the polygon exactly, without new vertices.
    clean : bool
        False for a polygon that is not simple (edges crossing): some step found no ear, or
        the triangles' total area differs from the polygon's signed area by more than
        ``eps`` times its perimeter. The triangles then cover some other region.
    """
    keep = _drop_repeated(uv, eps)
    if len(keep) < 3:
        return np.zeros((0, 3), np.int64), False
    clipper = _EarClipper(uv[keep], eps)
    tris = keep[clipper.run()]
    a, b, c = uv[tris[:, 0]], uv[tris[:, 1]], uv[tris[:, 2]]
    covered = np.abs(_cross2(b - a, c - a)).sum() / 2
    signed = _cross2(uv, np.roll(uv, -1, axis=0)).sum() / 2
    perimeter = np.linalg.norm(uv - np.roll(uv, -1, axis=0), axis=1).sum()
    return tris, clipper.clean and abs(covered - signed) <= eps * perimeter
