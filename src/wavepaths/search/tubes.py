"""Tubes around launched rays (:mod:`wavepaths.search.launch`): which query points lie
within each segment's tube, each pair once, through a bucket grid of the points."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


class PointGrid:
    """Query points bucketed on a uniform grid (cell ``h`` metres), for the compiled tube test.

    Attributes
    ----------
    points : (p, 3) float64
    lo : (3,) float64
        The grid's lowest corner [m].
    h : float
    dims : (3,) int64
    start : (nx ny nz + 1,) int64
        CSR pointer of the buckets into ``order``.
    order : (p,) int64
        Point rows sorted by bucket.
    """

    MAX_BUCKETS = 1 << 22

    def __init__(self, points: np.ndarray, h: float | None = None) -> None:
        self.points = np.ascontiguousarray(points, dtype=np.float64)
        lo = self.points.min(axis=0) if len(points) else np.zeros(3)
        hi = self.points.max(axis=0) if len(points) else np.zeros(3)
        ext = np.maximum(hi - lo, 1e-9)
        if h is None:
            # about four points per occupied bucket on a planar grid of receivers
            h = max(float(np.sqrt(ext[0] * ext[1] / max(len(points), 1) * 4)), 1e-3 * float(ext.max()))
        h = max(h, float((np.prod(ext) / self.MAX_BUCKETS) ** (1 / 3)))
        self.lo, self.h = lo, float(h)
        self.dims = (np.floor(ext / self.h).astype(np.int64) + 1)
        b = self._bucket(self.points)
        self.order = np.argsort(b, kind="stable").astype(np.int64)
        self.start = np.searchsorted(b[self.order], np.arange(int(np.prod(self.dims)) + 1)).astype(np.int64)

    def _bucket(self, x: np.ndarray) -> np.ndarray:
        i = np.clip(np.floor((x - self.lo) / self.h).astype(np.int64), 0, self.dims - 1)
        return i[:, 0] + self.dims[0] * (i[:, 1] + self.dims[1] * i[:, 2])


def _floats(x) -> np.ndarray:
    """``x`` as a C-contiguous float array: float32 kept (the cached fan segments), else float64."""
    x = np.asarray(x)
    return np.ascontiguousarray(x, dtype=np.float32 if x.dtype == np.float32 else np.float64)


def tube_pairs(start, end, r0, r1, points, grid: PointGrid | None = None, budget: int = 1 << 26,
               s0=None, s1=None, across=None) -> tuple[np.ndarray, np.ndarray]:
    """(segment, point) pairs with the point within the segment's tube, each pair once.

    The tube's radius goes from ``r0`` at ``start`` to ``r1`` at ``end``, linear in the
    parameter of the point's closest point on the segment. With ``across`` (k, 3), unit
    vectors normal to the segments, the cross-section is an ellipse instead: semi-axis ``r``
    along ``across`` and ``s`` (``s0`` to ``s1``) along the other normal direction (a Keller
    fan's rays are spaced by the fan's angle across the cone and by the samples along it;
    past a segment's end, where the ray stopped on a face, the cap is as long as ``r``: the
    neighbouring rays across the cone may go on beside the face).

    Compiled: a walk along each segment over the buckets of ``grid`` (a :class:`PointGrid`
    of ``points``, built when not given). numpy: every (segment, point) pair, in chunks
    (the reference). ``start``, ``end``, the radii and ``across`` may be float32 (the
    segments cached per context), in the frame of ``points``."""
    from . import kernels

    start, end, r0, r1 = _floats(start), _floats(end), _floats(r0), _floats(r1)
    if across is None:
        s0, s1, across = r0, r1, np.zeros((len(start), 3), r0.dtype)
    s0, s1, across = _floats(s0), _floats(s1), _floats(across)
    if kernels.available():
        from . import _numba_launch

        g = grid if grid is not None else PointGrid(points)
        args = (start, end, r0, r1, s0, s1, across, g.points, g.lo, g.h, g.dims, g.start, g.order)
        counts = np.empty(len(start), np.int64)
        _numba_launch.tube_counts(*args, counts)
        ptr = np.zeros(len(start) + 1, np.int64)
        np.cumsum(counts, out=ptr[1:])
        pt = np.empty(int(ptr[-1]), np.int64)
        _numba_launch.tube_fill(*args, ptr, pt)
        return np.repeat(np.arange(len(start)), counts), pt
    seg, pt = [], []
    step = max(1, budget // max(len(points), 1) // 8)
    for c0 in range(0, len(start), step):
        S, E = start[c0:c0 + step].astype(np.float64), end[c0:c0 + step].astype(np.float64)
        d = E - S
        L2 = np.einsum("ij,ij->i", d, d)
        p = points[None, :, :] - S[:, None, :]
        u = np.clip(np.einsum("kpj,kj->kp", p, d) / np.where(L2 > 0, L2, 1.0)[:, None], 0.0, 1.0)
        q = p - u[..., None] * d[:, None, :]
        r = r0[c0:c0 + step, None] + u * (r1 - r0)[c0:c0 + step, None]
        s = s0[c0:c0 + step, None] + u * (s1 - s0)[c0:c0 + step, None]
        qq = np.einsum("kpj,kpj->kp", q, q)
        c = np.einsum("kpj,kj->kp", q, across[c0:c0 + step].astype(np.float64)) ** 2
        c += (np.einsum("kpj,kj->kp", q, d) ** 2 / np.where(L2 > 0, L2, 1.0)[:, None])  # past a clamped end
        inside = (qq <= np.maximum(r, s) ** 2) & (c * s * s + (qq - c) * r * r <= r * r * s * s)
        i, j = np.nonzero(inside)
        seg.append(i + c0)
        pt.append(j)
    return (np.concatenate(seg), np.concatenate(pt)) if seg else (np.zeros(0, np.int64),) * 2


def unique_rows(rows: np.ndarray, return_inverse: bool = False):
    """The distinct rows of a C-contiguous int64 array (in byte order: a sort of fixed-size
    records, several times faster than ``np.unique(..., axis=0)``); with ``return_inverse``,
    also each row's index among them, (k,) int64."""
    rows = np.ascontiguousarray(rows)
    if len(rows) == 0 or rows.shape[1] == 0:
        out = rows[:1] if len(rows) else rows
        return (out, np.zeros(len(rows), np.int64)) if return_inverse else out
    rec = rows.view(np.dtype((np.void, rows.dtype.itemsize * rows.shape[1]))).ravel()
    if return_inverse:
        u, inv = np.unique(rec, return_inverse=True)
        return u.view(rows.dtype).reshape(-1, rows.shape[1]), inv.ravel().astype(np.int64)
    return np.unique(rec).view(rows.dtype).reshape(-1, rows.shape[1])


def reaches_box(origin: np.ndarray, end: np.ndarray, r0: np.ndarray, r1: np.ndarray, lo: np.ndarray,
                 hi: np.ndarray) -> np.ndarray:
    """(k,) bool: the tube of segment ``origin -> end``, radius ``r0`` to ``r1`` (linear in the
    segment's parameter ``u``), may reach the box ``[lo, hi]``: some ``u`` in [0, 1] has every
    coordinate within the radius of the box, ``lo - r(u) <= x(u) <= hi + r(u)`` (conservative:
    the box grown by a cube of the radius, not a sphere). Each of the six conditions is linear
    in ``u``, so the ``u`` that pass form one interval (a ray rising from a roof, whose tube
    widens slower than it climbs, never comes down to the receivers)."""
    d = end - origin
    dr = r1 - r0
    u0 = np.zeros(len(origin))
    u1 = np.ones(len(origin))
    for ax in range(3):
        # x + r >= lo  and  x - r <= hi, i.e. a u <= b for (a, b) below
        for a, b in ((-(d[:, ax] + dr), origin[:, ax] + r0 - lo[ax]), (d[:, ax] - dr, hi[ax] + r0 - origin[:, ax])):
            with np.errstate(divide="ignore", invalid="ignore"):
                bound = b / a
            u1 = np.where(a > 0, np.minimum(u1, bound), u1)
            u0 = np.where(a < 0, np.maximum(u0, bound), u0)
            u1 = np.where((a == 0) & (b < 0), -1.0, u1)
    return u0 <= u1


def in_box(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Whether every one of ``points`` (p, 3) lies in the box ``[lo, hi]``."""
    return bool(len(points) == 0 or (np.all(points.min(axis=0) >= lo) and np.all(points.max(axis=0) <= hi)))


@dataclass(frozen=True)
class BoxSegments:
    """Segments of launched rays kept for a box of query points, with their tubes; the
    shared part of :class:`~wavepaths.search.launch.FanSegments` and
    :class:`~wavepaths.search.txrays.RaySegments` (struct of arrays over ``n`` segments).

    The coordinates are float32 offsets from ``centre``: recentred, float32 keeps about
    0.1 mm within a few kilometres of it, and the tubes are tens of centimetres wide at least.

    Attributes
    ----------
    centre : (3,) float64
        Origin of the float32 coordinates [m].
    lo, hi : (3,) float64
        The box the segments were kept for [m].
    start, end : (n, 3) float32
        Ends of each segment [m from ``centre``].
    r0, r1 : (n,) float32
        Tube radius at each end [m] (for a Keller fan, the semi-axis across the cone).
    """

    centre: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    start: np.ndarray
    end: np.ndarray
    r0: np.ndarray
    r1: np.ndarray

    def __len__(self) -> int:
        return len(self.start)

    def covers(self, points: np.ndarray) -> bool:
        """Whether every one of ``points`` (p, 3) lies in the box the segments were kept for."""
        return in_box(points, self.lo, self.hi)
