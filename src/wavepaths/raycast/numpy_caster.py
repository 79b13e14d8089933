"""The float64 segment-occlusion reference in numpy: the definition of occlusion.

:class:`ExactSegments` implements, in float64, the rule stated in :mod:`wavepaths.raycast`
(a segment is blocked where it passes through a face from one side of its plane to the
other; touching, grazing or lying in a face's plane does not block). The
:class:`NumpyRayCaster` applies it to every (segment, triangle) pair that can meet, found
through a uniform grid of the triangles (:class:`TriangleGrid`); the Embree caster uses it
to confirm or overrule its float32 hits, and to decide the segments float32 cannot.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .._ragged import ranks
from .._vec import dot3
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
       into one polygon within ``coplanar_angle`` or ``coplanar_distance`` are not exactly in its plane, and the
       search puts reflection points on the polygon's plane).
    2. The crossing point must lie in the closed triangle: its distance inside each edge
       ``>= -edge_tol`` (``edge_tol`` = 1e-12 of the diagonal: rounding of the recentred
       coordinates, so that no segment leaks between two triangles of one wall), and in the
       triangle's bounding box grown by ``edge_tol`` (:attr:`box_lo`, :attr:`box_hi`): the
       three edge conditions alone reach ``edge_tol / sin(a / 2)`` beyond a corner of angle
       ``a``, past the padded boxes through which the indexes find a segment's triangles
       (:attr:`pad`), so a crossing there would count for one index and not for another.
    3. A crossing next to an edge (within the plane tolerance) that lies on the closure of
       a triangle whose plane contains the segment, around that edge's corners, is a graze
       along that face's boundary (a segment running over a roof, in its plane, that
       touches the top edge or a top corner of a wall below it), not a crossing; unless the
       segment runs there between two solids (:meth:`_between_solids`): in the plane of the
       shared wall of two touching buildings, it enters at a wall's edge with solid on both
       sides of that plane, and is blocked.

    The sums are written out in one order, ``(x0 y0 + x1 y1) + x2 y2``, the compiled
    kernels' (:mod:`wavepaths.raycast._numba`): for a segment nearly parallel to the plane
    the crossing point moves by far more than rounding with one ulp of ``s_a``, and the
    verdicts must be the same bit for bit.
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
        self.diagonal = float(scene.diagonal)
        self.edge_tol = 1e-12 * scene.diagonal
        self.box_lo = self.lo - self.edge_tol  # (f, 3): the crossing point's box (Notes, 2.)
        self.box_hi = self.hi + self.edge_tol
        # triangles around each vertex (CSR), for grazes along a coplanar face's boundary
        self.triangles = scene.triangles
        self._scene = scene  # the solids, for grazes between two of them (built on first use)
        self._solids = None
        self.contact_step = 4.0 * scene.length_tolerance(scene.tolerances.plane_distance)
        flat = scene.triangles.ravel()
        self.vertex_tris = np.argsort(flat, kind="stable") // 3
        self.vertex_ptr = np.concatenate([[0], np.cumsum(np.bincount(flat, minlength=len(scene.vertices)))])

    # ---- pairwise ------------------------------------------------------------------------
    def in_plane(self, p: np.ndarray, tri: np.ndarray) -> np.ndarray:
        """(k,) bool: the point ``p[i]`` (recentred) lies in the plane of ``tri[i]`` (within tol)."""
        return np.abs(dot3(p, self.normal[tri]) - self.offset[tri]) <= self.tol[tri]

    def crosses(self, a: np.ndarray, b: np.ndarray, tri: np.ndarray) -> np.ndarray:
        """(k,) bool: the segment ``a[i] -> b[i]`` (recentred, canonical) passes through triangle ``tri[i]``."""
        k = len(tri)
        out = np.zeros(k, dtype=bool)
        if k == 0:
            return out
        n, d = self.normal[tri], self.offset[tri]
        sa = dot3(a, n) - d
        sb = dot3(b, n) - d
        tol = self.tol[tri]
        strict = ((sa > tol) & (sb < -tol)) | ((sa < -tol) & (sb > tol))
        rows = np.nonzero(strict)[0]
        if len(rows) == 0:
            return out
        t = tri[rows]
        w = sa[rows] / (sa[rows] - sb[rows])
        x = a[rows] + w[:, None] * (b[rows] - a[rows])
        g = self.inward[t]  # (m, 3 edges, 3)
        dist = ((g[:, :, 0] * x[:, 0, None] + g[:, :, 1] * x[:, 1, None]) + g[:, :, 2] * x[:, 2, None]
                - self.inward_offset[t])  # (m, 3) inside each edge
        inside = (dist >= -self.edge_tol).all(axis=1)
        inside &= ((x >= self.box_lo[t]) & (x <= self.box_hi[t])).all(axis=1)
        near = inside[:, None] & (dist <= tol[rows, None])
        if near.any():
            inside &= ~self._grazes_coplanar_face(a[rows], b[rows], x, t, near)
        out[rows] = inside
        return out

    def _inside(self, x: np.ndarray, tri: np.ndarray) -> np.ndarray:
        """(k,) bool: ``x[i]`` (in or near the plane of ``tri[i]``) lies in the closed triangle, within its plane tolerance."""
        dist = np.einsum("kij,kj->ki", self.inward[tri], x) - self.inward_offset[tri]
        return (dist >= -self.tol[tri, None]).all(axis=1)

    def _grazes_coplanar_face(self, a, b, x, t, near, budget: int = 1 << 22) -> np.ndarray:
        """(m,) bool: the crossing ``x``, next to an edge of ``t``, lies on the closure of a
        triangle around that edge's corners whose plane contains the segment.

        The (crossing, triangle around a corner) pairs are taken about ``budget`` at a time
        (a vertex shared by thousands of triangles, e.g. a scene of stacked copies, would
        otherwise hold them all at once)."""
        r, side = np.nonzero(near)
        r = np.concatenate([r, r])
        corner = self.triangles[t[r], np.concatenate([side, (side + 1) % 3])]
        start = self.vertex_ptr[corner]
        count = self.vertex_ptr[corner + 1] - start
        out = np.zeros(len(t), dtype=bool)
        plane = np.zeros(len(t), dtype=np.int64)  # a triangle whose plane holds the graze
        ends = np.cumsum(count)
        lo = 0
        while lo < len(r):  # chunks of whole corners, at least one, about `budget` pairs each
            hi = max(lo + 1, int(np.searchsorted(ends, (ends[lo - 1] if lo else 0) + budget, side="right")))
            rr = np.repeat(r[lo:hi], count[lo:hi])
            c = count[lo:hi]
            offs = np.arange(len(rr)) - np.repeat(np.cumsum(c) - c, c)
            other = self.vertex_tris[np.repeat(start[lo:hi], c) + offs]
            keep = other != t[rr]
            rr, other = rr[keep], other[keep]
            graze = self.in_plane(a[rr], other) & self.in_plane(b[rr], other)
            rr, other = rr[graze], other[graze]
            on = self._inside(x[rr], other)
            out[rr[on]] = True
            plane[rr[on]] = other[on]
            lo = hi
        rows = np.nonzero(out)[0]
        if len(rows):
            out[rows] = ~self._between_solids(a[rows], b[rows], x[rows], plane[rows], t[rows])
        return out

    def _between_solids(self, a: np.ndarray, b: np.ndarray, x: np.ndarray, other: np.ndarray,
                        crossed: np.ndarray) -> np.ndarray:
        """(k,) bool: the segment ``a -> b`` (recentred), lying in the plane of triangle
        ``other`` and crossing the edge of triangle ``crossed`` at ``x``, has solid on both
        sides of that plane on one side of the crossing: it runs inside the union of two
        solids that touch there (a party wall: each building's own face in the plane), not
        along a face with air beside it.

        Tested at the points ``x + s u +- h n`` and ``x - s u +- h n`` (``u`` the segment's
        direction, ``n`` the plane's normal, ``h`` :attr:`contact_step`, four plane
        tolerances, and ``s`` as much or more, so that the points stand off the crossed
        face's plane too, at most half the segment left on that side) with wavepaths' one
        inside rule (:func:`wavepaths.scene.solids.inside_solid_objects`, float64 ray
        parity). Only the few crossings the graze rule would let pass come here.
        """
        from ..scene.solids import inside_solid_objects, solid_objects

        if self._solids is None:
            self._solids = solid_objects(self._scene)
        k = len(a)
        if len(self._solids) == 0 or k == 0:
            return np.zeros(k, dtype=bool)
        d = b - a
        length = np.sqrt(dot3(d, d))
        u = d / np.where(length > 0, length, 1.0)[:, None]
        h = self.contact_step
        n = self.normal[other]
        across = np.abs(dot3(u, self.normal[crossed]))  # off the crossed face's plane by at least h
        step = h / np.maximum(across, 1e-3)
        out = np.zeros(k, dtype=bool)
        for end, sign in ((b, 1.0), (a, -1.0)):
            left = np.sqrt(dot3(end - x, end - x))
            s = np.minimum(np.maximum(step, h), 0.5 * left)
            ok = s > 0
            p = x + (sign * s)[:, None] * u
            pts = np.concatenate([p + h * n, p - h * n]) + self.center
            inside = inside_solid_objects(self._scene, pts, self._solids)
            out |= ok & inside[:k] & inside[k:]
        return out

    # ---- against the whole scene ---------------------------------------------------------
    def blocked(self, a: np.ndarray, b: np.ndarray, budget: int = 1 << 22, index: bool = True) -> np.ndarray:
        """(k,) bool: the segments (recentred, canonical) pass through some triangle of the scene.

        Parameters
        ----------
        a, b : (k, 3) float64
            End points, recentred on the scene's centre, in canonical order.
        budget : int
            Size of the batches: (segment, triangle) box tests at once against every
            triangle; through the grid, ``budget // 16`` candidate pairs at once (each
            takes some 16 times the memory of a box test).
        index : bool
            Find each segment's triangles through :attr:`grid` (built on first use):
            sublinear in the number of triangles. ``False``: try every triangle,
            O(segments x triangles) (the reference the tests hold the grid to).

        Returns
        -------
        (k,) bool

        Notes
        -----
        Each segment is tested, by :meth:`crosses`, against the triangles whose bounding
        boxes, padded by :attr:`pad`, meet its own. The grid only leaves out triangles
        whose padded boxes the segment does not pass through, which :meth:`crosses` cannot
        find crossed: both ways give the same answers, bit for bit.
        """
        k = len(a)
        out = np.zeros(k, dtype=bool)
        if k == 0 or len(self.normal) == 0:
            return out
        pad = self.pad
        seg_lo = np.minimum(a, b) - pad
        seg_hi = np.maximum(a, b) + pad
        if not index:
            self._blocked_all(a, b, seg_lo, seg_hi, np.arange(k), budget, out)
            return out
        finite = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
        self._blocked_indexed(a, b, seg_lo, seg_hi, finite, max(1, budget // 16), out)
        self._blocked_all(a, b, seg_lo, seg_hi, np.nonzero(~finite)[0], budget, out)  # an infinite or NaN end
        return out

    @property
    def pad(self) -> float:
        """Padding [m] of the triangles' bounding boxes: a segment crossing a triangle meets the padded box."""
        return float(self.tol.max()) + self.edge_tol

    @property
    def grid(self) -> "TriangleGrid":
        """The grid of the triangles' boxes padded by :attr:`pad`, built on first use."""
        grid = self.__dict__.get("_grid")
        if grid is None:
            grid = self._grid = TriangleGrid(self.lo, self.hi, self.pad)
        return grid

    def _test_pairs(self, a: np.ndarray, b: np.ndarray, seg: np.ndarray, tri: np.ndarray, out: np.ndarray) -> None:
        """Set ``out[s]`` where segment ``s`` crosses its triangle, for the pairs ``(seg[i], tri[i])``."""
        if len(seg):
            hit = self.crosses(a[seg], b[seg], tri)
            out[seg[hit]] = True

    def _blocked_all(self, a: np.ndarray, b: np.ndarray, seg_lo: np.ndarray, seg_hi: np.ndarray,
                     which: np.ndarray, budget: int, out: np.ndarray) -> None:
        """:meth:`blocked` against every triangle for the segments ``which`` (indices), into ``out``."""
        step = max(1, budget // len(self.lo))
        for s in range(0, len(which), step):
            sel = which[s : s + step]
            meet = ((self.lo[None] <= seg_hi[sel, None]) & (self.hi[None] >= seg_lo[sel, None])).all(axis=2)
            seg, tri = np.nonzero(meet)
            self._test_pairs(a, b, sel[seg], tri, out)

    def _blocked_indexed(self, a: np.ndarray, b: np.ndarray, seg_lo: np.ndarray, seg_hi: np.ndarray,
                         which: np.ndarray, budget: int, out: np.ndarray) -> None:
        """:meth:`blocked` through the grid for the segments ``which`` (bool), ``budget`` pairs at once, into ``out``.

        The segments are walked through the grid a few slabs of cells at a time, all
        together; a segment found blocked is not walked further. A segment of zero length
        crosses no plane (its ends lie on the same side of every plane): it is not walked.
        """
        live = np.nonzero(which & (a != b).any(axis=1))[0]
        walk = self.grid.walk(a[live], b[live])
        f = len(self.normal)
        for first in range(0, int(walk.slabs.max(initial=0)), _WAVE):
            todo = np.nonzero(~out[live] & (walk.slabs > first))[0]
            for seg, tri in self.grid.pairs(walk, todo, first, _WAVE, budget):
                seg = live[seg]
                keep = ~out[seg] & ((self.lo[tri] <= seg_hi[seg]) & (self.hi[tri] >= seg_lo[seg])).all(axis=1)
                self._test_pairs(a, b, *_unique_pairs(seg[keep], tri[keep], f), out)


_WAVE = 4  # slabs of cells each segment is walked by at a time
_MAX_LISTINGS = 32  # bound on a grid's (cell, triangle) listings per triangle or cell


def _unique_pairs(seg: np.ndarray, tri: np.ndarray, f: int) -> tuple[np.ndarray, np.ndarray]:
    """The distinct pairs ``(seg[i], tri[i])`` (``tri < f``), sorted by segment, then triangle."""
    key = np.sort(seg * f + tri)
    key = key[np.diff(key, prepend=-1) != 0]
    return key // f, key % f


@dataclass(frozen=True)
class GridWalk:
    """Segments cut into the slabs of grid cells they pass through (see :meth:`TriangleGrid.walk`).

    Attributes
    ----------
    a, d : (k, 3) float64
        Start and direction ``b - a`` of each segment.
    axis : (k,) int64
        The axis along which the segment crosses the most cells: slabs are cut across it.
    first : (k,) int64
        Index along ``axis`` of the segment's first slab.
    slabs : (k,) int64
        Number of slabs (0: the segment misses the grid).
    margin : (k,) float64
        Margin [m] by which every slab and cell range is grown.
    """

    a: np.ndarray
    d: np.ndarray
    axis: np.ndarray
    first: np.ndarray
    slabs: np.ndarray
    margin: np.ndarray


class TriangleGrid:
    """A uniform grid of cells listing the triangles near them: the triangles near a segment.

    Parameters
    ----------
    lo, hi : (f, 3) float64
        The triangles' bounding boxes.
    pad : float
        Padding [m]: a triangle is listed in every cell its box grown by ``pad`` meets.
    cells_per_triangle : float
        Number of cells per triangle aimed at.

    Notes
    -----
    Cell ``(i, j, l)`` holds the points ``x`` with ``floor((x - origin) / size) = (i, j, l)``,
    computed in float64: monotone in ``x``, so every point of a triangle's padded box (the
    box is grown by a further 1e-9 of the scene's reach, far above rounding) falls in a
    cell the triangle is listed in. The cells are as near cubes as the scene allows (a
    flat scene gets a single layer), about ``cells_per_triangle`` per triangle. The cells
    of the points within a margin (again far above rounding) of a segment are found slab
    by slab (:meth:`walk`, :meth:`pairs`), so every triangle whose padded box a segment
    passes through is paired with it.
    """

    def __init__(self, lo: np.ndarray, hi: np.ndarray, pad: float, cells_per_triangle: float = 4.0) -> None:
        axes = np.arange(3)
        reach = float(np.abs(np.concatenate([lo, hi])).max(initial=0.0))
        box_lo, box_hi = lo - (pad + 1e-9 * reach), hi + (pad + 1e-9 * reach)
        self.origin = box_lo.min(axis=0)
        top = box_hi.max(axis=0)
        cells = max(1.0, cells_per_triangle * len(lo))
        while True:  # coarser while the large triangles would be listed in too many cells
            self.size = _cell_size(top - self.origin, cells)
            self.shape = self._index(top, axes) + 1
            i0, i1 = self._index(box_lo, axes), self._index(box_hi, axes)
            if cells <= 1.0 or (i1 - i0 + 1).prod(axis=1).sum() <= _MAX_LISTINGS * max(len(lo), cells):
                break
            cells = max(1.0, cells / 8.0)
        cell, tri = self._box_cells(i0, i1)
        order = np.argsort(cell, kind="stable")
        self.cell_triangles = tri[order]  # the triangles of cell c: cell_triangles[cell_ptr[c] : cell_ptr[c + 1]]
        self.cell_ptr = np.concatenate([[0], np.cumsum(np.bincount(cell, minlength=int(np.prod(self.shape))))])

    def _index(self, x: np.ndarray, axis: np.ndarray) -> np.ndarray:
        """int64 index along ``axis`` (broadcast with ``x``) of the cells of the coordinates ``x``.

        Clipped to ``[-1, 2**53]`` (monotone still): a coordinate far outside the grid
        gets an index outside it.
        """
        return np.clip(np.floor((x - self.origin[axis]) / self.size[axis]), -1.0, 2.0**53).astype(np.int64)

    def _box_cells(self, i0: np.ndarray, i1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(flat cell number, box) of every cell of the index boxes ``i0 .. i1`` ((m, 3), inclusive)."""
        w = i1 - i0 + 1
        count = w.prod(axis=1)
        box = np.repeat(np.arange(len(w)), count)
        o = ranks(count)
        wy, wz = w[box, 1], w[box, 2]
        i = i0[box, 0] + o // (wy * wz)
        j = i0[box, 1] + (o // wz) % wy
        l = i0[box, 2] + o % wz
        return (i * self.shape[1] + j) * self.shape[2] + l, box

    def walk(self, a: np.ndarray, b: np.ndarray) -> GridWalk:
        """The slabs of cells the segments ``a -> b`` (none of length zero) pass through.

        The slabs are cut across the axis along which the segment crosses the most cells,
        limited to the grid.
        """
        d = b - a
        axis = np.argmax(np.abs(d) / self.size, axis=1)
        margin = 1e-9 * (self.size.max() + np.maximum(np.abs(a), np.abs(b)).max(axis=1))
        r = np.arange(len(a))
        first = np.maximum(self._index(np.minimum(a[r, axis], b[r, axis]) - margin, axis), 0)
        last = np.minimum(self._index(np.maximum(a[r, axis], b[r, axis]) + margin, axis), self.shape[axis] - 1)
        return GridWalk(a, d, axis, first, np.maximum(last - first + 1, 0), margin)

    def pairs(self, walk: GridWalk, seg: np.ndarray, start: int, count: int,
              budget: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Batches of (segment, triangle) pairs of the segments ``seg`` in their slabs ``start .. start + count - 1``.

        Every triangle listed in a cell of the points within ``walk.margin`` of the
        segment's part in those slabs is paired with it, possibly more than once. A batch
        holds at most ``budget`` pairs, or one cell's.
        """
        step = max(1, budget // (16 * count))
        for s in range(0, len(seg), step):
            sel = seg[s : s + step]
            slabs = np.clip(walk.slabs[sel] - start, 0, count)
            cell_seg, cell = self._slab_cells(walk, np.repeat(sel, slabs), start + ranks(slabs))
            for pos, tri in self._cell_triangles(cell, budget):
                yield cell_seg[pos], tri

    def _slab_cells(self, walk: GridWalk, seg: np.ndarray, slab: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(segment, flat cell number) of the cells near the part of segment ``seg[i]`` in its slab ``slab[i]``.

        Within the slab (grown by the margin), each other coordinate runs between its
        values where the segment meets the slab's two faces; its cells are those of that
        interval grown by the margin.
        """
        ax, m = walk.axis[seg], walk.margin[seg]
        a, d = walk.a[seg], walk.d[seg]
        r = np.arange(len(seg))
        k = walk.first[seg] + slab
        face0 = self.origin[ax] + k * self.size[ax] - m
        face1 = self.origin[ax] + (k + 1) * self.size[ax] + m
        ta, tb = (face0 - a[r, ax]) / d[r, ax], (face1 - a[r, ax]) / d[r, ax]
        t0 = np.clip(np.minimum(ta, tb), 0.0, 1.0)
        t1 = np.clip(np.maximum(ta, tb), 0.0, 1.0)
        i0 = np.empty((len(seg), 3), dtype=np.int64)
        i1 = np.empty((len(seg), 3), dtype=np.int64)
        i0[r, ax] = i1[r, ax] = k
        for shift in (1, 2):
            u = (ax + shift) % 3
            p0, p1 = a[r, u] + t0 * d[r, u], a[r, u] + t1 * d[r, u]
            i0[r, u] = np.maximum(self._index(np.minimum(p0, p1) - m, u), 0)
            i1[r, u] = np.minimum(self._index(np.maximum(p0, p1) + m, u), self.shape[u] - 1)
        keep = (i1 >= i0).all(axis=1)
        cell, box = self._box_cells(i0[keep], i1[keep])
        return seg[keep][box], cell

    def _cell_triangles(self, cell: np.ndarray, budget: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Batches of (position in ``cell``, triangle) for the triangles listed in the cells ``cell``."""
        start = self.cell_ptr[cell]
        count = self.cell_ptr[cell + 1] - start
        ends = np.cumsum(count)
        lo = 0
        while lo < len(cell):
            hi = max(int(np.searchsorted(ends, ends[lo] - count[lo] + budget, side="right")), lo + 1)
            pos = np.repeat(np.arange(lo, hi), count[lo:hi])
            yield pos, self.cell_triangles[start[pos] + ranks(count[lo:hi])]
            lo = hi


def _cell_size(extent: np.ndarray, cells: float) -> np.ndarray:
    """(3,) edge lengths of about ``cells`` near-cubic cells filling a box of ``extent``.

    An axis shorter than the cubes' edge gets a single cell (a flat scene: one layer).
    """
    extent = np.maximum(extent, 1e-300)
    flat = np.zeros(3, dtype=bool)
    edge = float(extent.max())
    for _ in range(3):
        edge = float(np.prod(extent[~flat]) / cells) ** (1.0 / (~flat).sum())
        thin = ~flat & (extent < edge)
        if not thin.any():
            break
        flat |= thin
    return np.where(flat, 2.0 * extent, edge)  # a flat axis: its one cell reaches past the top


class NumpyRayCaster:
    """Occlusion by the float64 rule of :class:`ExactSegments`, on every (segment, triangle) pair that can meet.

    The pairs are found through a uniform grid of the triangles (sublinear in their
    number): meant for small scenes, for the few segments the search asks to decide
    exactly, and as the reference the Embree caster is tested against.
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

    def occluded_legs(self, V: np.ndarray, alive: np.ndarray, i: int, j: int) -> np.ndarray:
        """:meth:`occluded` of the legs ``V[alive, i] -> V[alive, j]`` of chains ``V`` (k, s, 3)."""
        return self.occluded(V[alive, i], V[alive, j])
