"""The join of a diffraction's two end sides on (dihedron, sector), with the closed-form point.

For one chunk of receiver images, the receiver side's (image, dihedron) rows
(:func:`wavepaths.search.end_sides._receiver_side`) meet the transmitter side's sources
with the same key (dihedron, sector): that match is the seed's FindDihedron test (§3.3).
Each match gets the closed-form diffraction point in the reduced coordinates of its two
ends (§2.3), then the prefilter: on the edge segment, not proven hidden from the
transmitter side, and (without ``lit_region``) in the shadow region. Steps 2 and 3 of
:func:`wavepaths.search.diffraction.diffraction_tile`, which re-exports these functions;
with numba the join and the prefilter run as one compiled loop
(:func:`wavepaths.search._numba_diffraction.joined_candidates`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from . import kernels
from .chains import CANDIDATE_BUDGET
from .geometry import diffraction_point_reduced

if TYPE_CHECKING:  # pragma: no cover
    from collections import Counter

    from ..scene.model import Scene
    from .context import TxContext
    from .end_sides import _EndSide


def _join_ranges(src, keys: np.ndarray, budget: int = CANDIDATE_BUDGET):
    """The join of :func:`_join_chunks` as ranges: yields ``(lo, hi, first, count)``, the
    receiver-side rows ``lo .. hi - 1`` of a chunk, and for every receiver-side row the
    first transmitter-side row with its key and how many there are (0 without a match)."""
    nu = len(src.unique_keys)
    if nu == 0 or len(keys) == 0:
        return
    pos = np.minimum(np.searchsorted(src.unique_keys, keys), nu - 1)
    match = src.unique_keys[pos] == keys
    count = np.where(match, src.key_count[pos], 0)
    first = np.where(match, src.key_start[pos], 0)
    ends = np.cumsum(count)
    total = int(ends[-1])
    lo = 0
    while lo < len(keys):
        base = int(ends[lo] - count[lo])
        if base >= total:
            return
        hi = max(int(np.searchsorted(ends, base + budget, side="right")), lo + 1)
        yield lo, hi, first, count
        lo = hi


def _join_chunks(src, keys: np.ndarray, budget: int = CANDIDATE_BUDGET):
    """For each receiver-side key, all transmitter-side sources with the same key, in chunks.

    Yields ``(rows, src_rows)``: the receiver-side row and the transmitter-side row of every
    match, at most about ``budget`` matches per chunk (a single key with more matches than
    that comes in one chunk of its own), so that memory stays bounded however many image
    sources share a (dihedron, sector).
    """
    for lo, hi, first, count in _join_ranges(src, keys, budget):
        yield _join_pairs(lo, hi, first, count)


def _join_pairs(lo: int, hi: int, first: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The (receiver-side row, transmitter-side row) pairs of one range of :func:`_join_ranges`."""
    c = count[lo:hi]
    rows = np.repeat(np.arange(lo, hi), c)
    offs = np.arange(len(rows)) - np.repeat(np.cumsum(c) - c, c)
    return rows, np.repeat(first[lo:hi], c) + offs


def _diffraction_prefilter(scene: "Scene", ctx: TxContext, rside: _EndSide, rows: np.ndarray, tside: _EndSide,
                           src_rows: np.ndarray, rejected: np.ndarray):
    """Steps 2-3 of :func:`~wavepaths.search.diffraction.diffraction_tile` on joined pairs
    (receiver side ``rside[rows]``, transmitter side ``tside[src_rows]``): the closed-form
    point in the reduced coordinates (seed §2.3), on the edge segment, not proven hidden
    from the transmitter side (order 0: in a shadow proven from the transmitter, the first
    leg is blocked; order >= 1: the leg to the last image cannot cross the last mirror), and
    without ``lit_region`` in the shadow region. Returns the survivors' ``rows, src_rows,
    t``; adds the off-edge, hidden and lit-region rejections to ``rejected`` (3,)."""
    d = rside.dihedron[rows]
    t = diffraction_point_reduced(tside.t[src_rows], tside.rho[src_rows], rside.t[rows], rside.rho[rows])
    L = scene.dihedra.length[d]
    on = (t >= 0) & (t <= L)
    rejected[0] += int((~on).sum())
    if tside.visible is not None:
        seen = tside.visible.may_see(src_rows, t, L)
        rejected[1] += int((on & ~seen).sum())
        on &= seen
    if not ctx.options.lit_region:
        shadow = np.abs(rside.phi[rows] - tside.phi[src_rows]) > np.pi
        rejected[2] += int((on & ~shadow).sum())
        on &= shadow
    return rows[on], src_rows[on], t[on]


def _joined_candidates(scene: "Scene", ctx: TxContext, a: int, src, rside: _EndSide, tside: _EndSide,
                       stats: Counter, tag: str):
    """The join of the two sides on (dihedron, sector) (:func:`_join_chunks`), then
    :func:`_diffraction_prefilter`, in chunks: yields the survivors' ``rows, src_rows, t``.

    With the compiled kernels the two run as one loop over the join
    (:func:`wavepaths.search._numba_diffraction.joined_candidates`, the same expressions), which never
    materialises the pairs that fail.
    """
    keys = rside.dihedron * ctx.key_stride + rside.sector
    rejected = np.zeros(3, np.int64)
    compiled = ctx.options.compiled and kernels.available()
    if compiled:
        from . import _numba

        c = np.ascontiguousarray
        vis = tside.visible
        if vis is None:
            z, zb = np.zeros(0), np.zeros(0, np.bool_)
            vis_args = (False, z, z, zb, zb, 0.0)
        else:
            vis_args = (True, c(vis.lo), c(vis.hi), c(vis.open0), c(vis.open1), float(vis.tau))
        r_args = (c(rside.t), c(rside.rho), c(rside.phi), c(rside.dihedron, dtype=np.int64))
        s_args = (c(tside.t), c(tside.rho), c(tside.phi))
        length = c(scene.dihedra.length)
    for lo, hi, first, count in _join_ranges(src, keys):
        m = int(count[lo:hi].sum())
        stats[f"{tag}_candidates"] += m
        if compiled:
            out_r, out_s, out_t = np.empty(m, np.int64), np.empty(m, np.int64), np.empty(m)
            n = _numba.joined_candidates(lo, hi, c(first, dtype=np.int64), c(count, dtype=np.int64), *r_args, *s_args,
                                         length, *vis_args, bool(ctx.options.lit_region), out_r, out_s, out_t,
                                         rejected)
            got = out_r[:n], out_s[:n], out_t[:n]
        else:
            rows, src_rows = _join_pairs(lo, hi, first, count)
            got = _diffraction_prefilter(scene, ctx, rside, rows, tside, src_rows, rejected)
        if len(got[0]):
            yield got
    stats[f"{tag}_rejected_off_edge"] += int(rejected[0])
    if tside.visible is not None:
        stats[f"{tag}_rejected_{'hidden' if a == 0 else 'aperture'}"] += int(rejected[1])
    if not ctx.options.lit_region:
        stats[f"{tag}_rejected_lit_region"] += int(rejected[2])
