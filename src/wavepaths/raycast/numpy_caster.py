"""The float64 segment-occlusion reference in numpy: the definition of occlusion.

:class:`ExactSegments` implements, in float64, the rule stated in :mod:`wavepaths.raycast`
(a segment is blocked where it passes through a face from one side of its plane to the
other; touching, grazing or lying in a face's plane does not block). The
:class:`NumpyRayCaster` applies it to every (segment, triangle) pair; the Embree caster
uses it to confirm or overrule its float32 hits.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from . import canonical, plane_tolerance

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene


class ExactSegments:
    """Float64 segment-versus-triangle tests of one scene (coordinates relative to its centre).

    Parameters
    ----------
    scene : Scene

    Notes
    -----
    For a segment ``a -> b`` (end points in canonical order, see
    :func:`wavepaths.raycast.canonical`) and a triangle with unit normal ``n``:

    1. ``s_a, s_b``: signed distances of the ends to the triangle's plane. The segment
       crosses the plane only if ``s_a`` and ``s_b`` are beyond the triangle's plane
       tolerance on opposite sides: an end on the plane touches it, a segment in the plane
       lies on it. The plane tolerance is :func:`~wavepaths.raycast.plane_tolerance` plus
       the distance of the triangle's corners from its polygon's plane (triangles merged
       into one polygon within ``coplanar_angle`` are not exactly in its plane, and the
       search puts reflection points on the polygon's plane).
    2. The crossing point must lie in the closed triangle: its distance inside each edge
       ``>= -edge_tol`` (``edge_tol`` = 1e-12 of the diagonal: rounding of the recentred
       coordinates, so that no segment leaks between two triangles of one wall).
    3. A crossing next to an edge (within the plane tolerance) that lies on the closure of
       a triangle whose plane contains the segment, around that edge's corners, is a graze
       along that face's boundary (a segment running over a roof, in its plane, that
       touches the top edge or a top corner of a wall below it), not a crossing.
    """

    def __init__(self, scene: "Scene") -> None:
        self.center = scene.center.copy()
        c = scene.vertices[scene.triangles] - self.center  # (f, 3, 3)
        self.corners = c
        n = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
        self.normal = n / np.linalg.norm(n, axis=1, keepdims=True)
        self.offset = np.einsum("ij,ij->i", self.normal, c[:, 0])
        e = np.roll(c, -1, axis=1) - c  # side i from corner i to corner i + 1
        inward = np.cross(self.normal[:, None, :], e)
        self.inward = inward / np.linalg.norm(inward, axis=2, keepdims=True)  # (f, 3, 3), in-plane, into the triangle
        self.inward_offset = np.einsum("fij,fij->fi", self.inward, c)  # (f, 3)
        self.lo = c.min(axis=1)
        self.hi = c.max(axis=1)
        poly = scene.triangle_polygon
        pn = scene.polygon_normal[poly]
        pd = scene.polygon_offset[poly] - pn @ self.center
        dev = np.abs(np.einsum("fij,fj->fi", c, pn) - pd[:, None]).max(axis=1)
        self.tol = plane_tolerance(scene) + dev  # (f,) per-triangle plane tolerance [m]
        self.edge_tol = 1e-12 * scene.diagonal
        # triangles around each vertex (CSR), for grazes along a coplanar face's boundary
        self.triangles = scene.triangles
        flat = scene.triangles.ravel()
        self.vertex_tris = np.argsort(flat, kind="stable") // 3
        self.vertex_ptr = np.concatenate([[0], np.cumsum(np.bincount(flat, minlength=len(scene.vertices)))])

    # ---- pairwise ------------------------------------------------------------------------
    def in_plane(self, p: np.ndarray, tri: np.ndarray) -> np.ndarray:
        """(k,) bool: the point ``p[i]`` (recentred) lies in the plane of ``tri[i]`` (within tol)."""
        return np.abs(np.einsum("ij,ij->i", p, self.normal[tri]) - self.offset[tri]) <= self.tol[tri]

    def crosses(self, a: np.ndarray, b: np.ndarray, tri: np.ndarray) -> np.ndarray:
        """(k,) bool: the segment ``a[i] -> b[i]`` (recentred, canonical) passes through triangle ``tri[i]``."""
        k = len(tri)
        out = np.zeros(k, dtype=bool)
        if k == 0:
            return out
        n, d = self.normal[tri], self.offset[tri]
        sa = np.einsum("ij,ij->i", a, n) - d
        sb = np.einsum("ij,ij->i", b, n) - d
        tol = self.tol[tri]
        strict = ((sa > tol) & (sb < -tol)) | ((sa < -tol) & (sb > tol))
        rows = np.nonzero(strict)[0]
        if len(rows) == 0:
            return out
        t = tri[rows]
        w = sa[rows] / (sa[rows] - sb[rows])
        x = a[rows] + w[:, None] * (b[rows] - a[rows])
        dist = np.einsum("kij,kj->ki", self.inward[t], x) - self.inward_offset[t]  # (m, 3) inside each edge
        inside = (dist >= -self.edge_tol).all(axis=1)
        near = inside[:, None] & (dist <= tol[rows, None])
        if near.any():
            inside &= ~self._grazes_coplanar_face(a[rows], b[rows], x, t, near)
        out[rows] = inside
        return out

    def _inside(self, x: np.ndarray, tri: np.ndarray) -> np.ndarray:
        """(k,) bool: ``x[i]`` (in or near the plane of ``tri[i]``) lies in the closed triangle, within its plane tolerance."""
        dist = np.einsum("kij,kj->ki", self.inward[tri], x) - self.inward_offset[tri]
        return (dist >= -self.tol[tri, None]).all(axis=1)

    def _grazes_coplanar_face(self, a, b, x, t, near) -> np.ndarray:
        """(m,) bool: the crossing ``x``, next to an edge of ``t``, lies on the closure of a
        triangle around that edge's corners whose plane contains the segment."""
        r, side = np.nonzero(near)
        r = np.concatenate([r, r])
        corner = self.triangles[t[r], np.concatenate([side, (side + 1) % 3])]
        start = self.vertex_ptr[corner]
        count = self.vertex_ptr[corner + 1] - start
        rr = np.repeat(r, count)
        offs = np.arange(len(rr)) - np.repeat(np.cumsum(count) - count, count)
        other = self.vertex_tris[np.repeat(start, count) + offs]
        keep = other != t[rr]
        rr, other = rr[keep], other[keep]
        graze = self.in_plane(a[rr], other) & self.in_plane(b[rr], other)
        rr, other = rr[graze], other[graze]
        graze = self._inside(x[rr], other)
        out = np.zeros(len(t), dtype=bool)
        out[rr[graze]] = True
        return out

    # ---- against the whole scene ---------------------------------------------------------
    def blocked(self, a: np.ndarray, b: np.ndarray, budget: int = 1 << 22) -> np.ndarray:
        """(k,) bool: the segments (recentred, canonical) pass through some triangle of the scene.

        Each segment is tested against the triangles whose bounding boxes meet its own.
        """
        k = len(a)
        out = np.zeros(k, dtype=bool)
        if k == 0:
            return out
        f = len(self.normal)
        pad = float(self.tol.max()) + self.edge_tol
        seg_lo = np.minimum(a, b) - pad
        seg_hi = np.maximum(a, b) + pad
        step = max(1, budget // max(f, 1))
        for s in range(0, k, step):
            sl = slice(s, min(k, s + step))
            meet = ((self.lo[None] <= seg_hi[sl, None]) & (self.hi[None] >= seg_lo[sl, None])).all(axis=2)
            seg, tri = np.nonzero(meet)
            if len(seg) == 0:
                continue
            seg = seg + s
            hit = self.crosses(a[seg], b[seg], tri)
            out[np.unique(seg[hit])] = True
        return out


class NumpyRayCaster:
    """Occlusion by testing every (segment, triangle) pair in float64.

    O(segments x triangles) (with a bounding-box filter): meant for small scenes, for the
    few segments the search asks to decide exactly, and as the reference the Embree caster
    is tested against.
    """

    def __init__(self, scene: "Scene", chunk: int = 4_000_000) -> None:
        self._exact = ExactSegments(scene)
        self._chunk = chunk
        self._rays = 0

    @property
    def rays_cast(self) -> int:
        return self._rays

    def occluded(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        a = np.asarray(a, dtype=np.float64).reshape(-1, 3)
        b = np.asarray(b, dtype=np.float64).reshape(-1, 3)
        a, b, _ = canonical(a - self._exact.center, b - self._exact.center)
        self._rays += len(a)
        return self._exact.blocked(a, b, self._chunk)
