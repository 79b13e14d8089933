"""A float64 bounding-volume hierarchy over a scene's triangles, for occlusion queries decided
by the exact rule alone (:class:`~wavepaths.raycast.numpy_caster.ExactSegments`), without a
float32 step.

:class:`~wavepaths.raycast.embree.EmbreeRayCaster` asks Embree (float32) for the face each of
two half-rays of a segment meets first and decides that face in float64; a segment Embree
leaves undecided goes to the float64 test against the whole scene. On small scenes a
compiled walk of this tree answers the same question faster, in float64 from the start:
each segment is tested, by the rule of ``ExactSegments.crosses``, against every triangle
whose padded box it meets, and stops at the first that blocks it (any hit). One thread, per
segment: the legs of the street canyon's R2+D1 map (74 triangles) 76-83 ns against 170-188 ns,
``etoile_crop``'s path legs (948 triangles) 180 ns against 278 ns, munich's path legs
(38,936 triangles) 285 ns against 370 ns; on random long segments across ``etoile`` (13,098
triangles) and munich Embree's wider tree is faster (331 ns against 451 ns, 458 ns against
633 ns), but the tree decides every segment by the float64 rule where Embree's float32 rays
miss a few faces crossed next to their edges (munich's path legs: 94 of 353,245), so the
caster builds it by default up to :data:`BVH_MAX_TRIANGLES` triangles, which holds both
built-in city scenes (docs/search.md).

The tree: binary, its nodes in depth-first order (a node's left child follows it), each
with the float64 box of its triangles' boxes padded by ``ExactSegments.pad`` (so that a
segment crossing a triangle meets every box on the way to it), split where the surface-area
heuristic over the triangles' centres, sorted along each axis in turn, is least; leaves of
at most ``leaf_size`` triangles, and at :data:`MAX_DEPTH` whatever they hold (the walk's
stack is bounded by the depth). The triangles' planes, tolerances and edge planes are
copied into leaf order (:attr:`SegmentBVH.rows`), so that a leaf reads one contiguous block.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from .numpy_caster import ExactSegments

BVH_MAX_TRIANGLES = 1 << 17
"""The largest scene (in triangles, 131,072) for which
:class:`~wavepaths.raycast.embree.EmbreeRayCaster` builds the tree by default (``bvh=None``):
exact occlusion on every scene up to munich's size and beyond (38,936 triangles: the tree
builds in 1.3 s, in numpy); larger scenes keep Embree's float32 casts, whose tree builds
faster and walks long segments faster."""

MAX_DEPTH = 48
"""Depth at which a node becomes a leaf whatever it holds (the walk's stack holds at most
``MAX_DEPTH + 1`` nodes)."""

ROW = 23
"""Floats per triangle in :attr:`SegmentBVH.rows`: the unit normal (3), the plane offset,
the plane tolerance, for each of the three edges its inward unit normal (3) and offset, then
the box a crossing point must lie in (``ExactSegments.box_lo`` (3), ``box_hi`` (3))."""


@dataclass(frozen=True)
class SegmentBVH:
    """A float64 tree over the triangles of one scene (coordinates relative to its centre).

    Attributes
    ----------
    box : (m, 6) float64 [m]
        Each node's padded box: ``lo`` (3), then ``hi`` (3).
    first, count : (m,) int64
        A leaf's triangles are ``rows[first:first + count]``; ``count == 0`` for an inner node.
    right : (m,) int64
        An inner node's right child (its left child is the next node); -1 for a leaf.
    triangle : (t,) int64
        The scene triangle of each row, in leaf order.
    rows : (t, 23) float64
        Per row: normal, offset, plane tolerance, the three edges' inward normals and
        offsets, and the crossing point's box (:data:`ROW`), as in
        :class:`~wavepaths.raycast.numpy_caster.ExactSegments`.
    edge_tol : float [m]
        ``ExactSegments.edge_tol``.
    slack : float [m]
        Half of what the boxes' padding (``ExactSegments.pad``) adds beyond the box a crossing
        point must lie in (``edge_tol``): the slabs' rounding this leaves room for; the walk
        grows the boxes for segments whose coordinates make it larger.
    """

    box: np.ndarray
    first: np.ndarray
    count: np.ndarray
    right: np.ndarray
    triangle: np.ndarray
    rows: np.ndarray
    edge_tol: float
    slack: float

    @property
    def depth(self) -> int:
        """The number of levels (1 for a single leaf)."""
        level = np.zeros(len(self.box), np.int64)
        for nd in range(len(self.box)):
            if self.count[nd] == 0:
                level[nd + 1] = level[self.right[nd]] = level[nd] + 1
        return int(level.max(initial=0)) + 1


def _area(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    d = np.maximum(hi - lo, 0.0)
    return d[:, 0] * d[:, 1] + d[:, 1] * d[:, 2] + d[:, 2] * d[:, 0]


def build_segment_bvh(exact: "ExactSegments", leaf_size: int = 8) -> SegmentBVH:
    """The tree of the triangles of ``exact`` (module docstring)."""
    lo, hi = exact.lo - exact.pad, exact.hi + exact.pad
    centre = 0.5 * (lo + hi)
    box, first, count, right, order = [], [], [], [], []

    def node(idx: np.ndarray, depth: int) -> int:
        me = len(box)
        box.append(np.concatenate([lo[idx].min(axis=0), hi[idx].max(axis=0)]))
        first.append(-1)
        count.append(0)
        right.append(-1)
        if len(idx) <= leaf_size or depth >= MAX_DEPTH - 1:
            first[me], count[me] = len(order), len(idx)
            order.extend(idx.tolist())
            return me
        n = len(idx)
        best, split = np.inf, None
        for ax in range(3):
            o = idx[np.argsort(centre[idx, ax], kind="stable")]
            left_area = _area(np.minimum.accumulate(lo[o], axis=0), np.maximum.accumulate(hi[o], axis=0))
            right_area = _area(np.minimum.accumulate(lo[o][::-1], axis=0),
                               np.maximum.accumulate(hi[o][::-1], axis=0))[::-1]
            # the first h triangles left, the others right, for h = 1 .. n - 1
            cost = left_area[:-1] * np.arange(1, n) + right_area[1:] * np.arange(n - 1, 0, -1)
            h = int(np.argmin(cost))
            if cost[h] < best:
                best, split = cost[h], (o, h + 1)
        o, h = split
        node(o[:h], depth + 1)
        right[me] = node(o[h:], depth + 1)
        return me

    if len(lo):
        node(np.arange(len(lo)), 0)
    tri = np.asarray(order, dtype=np.int64)
    edges = np.concatenate([exact.inward[tri], exact.inward_offset[tri][:, :, None]], axis=2).reshape(len(tri), 12)
    rows = np.concatenate([exact.normal[tri], exact.offset[tri, None], exact.tol[tri, None], edges, exact.box_lo[tri],
                           exact.box_hi[tri]], axis=1)
    assert rows.shape[1] == ROW  # the layout the compiled walk reads (raycast._numba)
    return SegmentBVH(np.asarray(box, dtype=np.float64).reshape(-1, 6), np.asarray(first, np.int64),
                      np.asarray(count, np.int64), np.asarray(right, np.int64), tri,
                      np.ascontiguousarray(rows, dtype=np.float64), float(exact.edge_tol),
                      0.5 * float(exact.pad - exact.edge_tol))


__all__ = ["BVH_MAX_TRIANGLES", "SegmentBVH", "build_segment_bvh"]
