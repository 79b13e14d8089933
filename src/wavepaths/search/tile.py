"""Per-receiver work, vectorised over (receivers in a tile x candidates).

Every function here takes the scene, a :class:`~wavepaths.search.context.TxContext`
and a tile of receivers, builds the candidate arrays, applies the tests in order of
cost (sectors, segment parameter, point-in-polygon, occlusion), compacting the
survivors after each test, and casts the surviving segments in one batch. Each test
adds to the ``stats`` counters what it rejected. The line of sight and the reflections
are here; the diffracted paths are in :mod:`wavepaths.search.diffraction`.
"""

from __future__ import annotations

from collections import Counter
from typing import TYPE_CHECKING

import numpy as np

from ..errors import ImageTreeTooLarge
from .beams import reflection_candidates
from .chains import CANDIDATE_BUDGET, occluded_chains, triangle_of
from .context import TxContext
from .diffraction import diffraction_tile
from .images import backtrace, build_image_levels
from .paths import InteractionType, PathBatch

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene


RX_VISIBILITY_GROUP = 1
"""Receivers per group of the receivers' hidden-mirror test (``visibility_group`` of
:func:`~wavepaths.search.images.build_image_levels`): one box and one ray per mirror and group."""


def los_tile(
    scene: "Scene", ctx: TxContext, rx: np.ndarray, rx_offset: int, stats: Counter, grazing: np.ndarray
) -> PathBatch:
    """Line-of-sight paths from every transmitter to every receiver of the tile.

    ``grazing`` (m, n) bool marks pairs lying on a shadow boundary: their segments are
    cast in float64.
    """
    m, n = len(ctx.tx), len(rx)
    ti = np.repeat(np.arange(m), n)
    ri = np.tile(np.arange(n), m)
    a, b = ctx.tx[ti], rx[ri]
    stats["los_candidates"] += len(ti)
    ok = np.linalg.norm(b - a, axis=1) > 0
    blocked = np.ones(len(ti), dtype=bool)
    blocked[ok] = occluded_chains(scene, np.stack([a[ok], b[ok]], axis=1), stats, grazing[ti[ok], ri[ok]])
    ok &= ~blocked
    stats["los_rejected_occluded"] += int(blocked.sum())
    k = int(ok.sum())
    return PathBatch(
        ti[ok], ri[ok] + rx_offset, np.zeros((k, 0), np.int8), np.zeros((k, 0), np.int64),
        np.zeros((k, 0), np.int64), np.full((k, 2), -1, np.int64), np.stack([a[ok], b[ok]], axis=1),
    )


def reflection_tile(
    scene: "Scene", ctx: TxContext, order: int, rx: np.ndarray, rx_offset: int, stats: Counter, grazing: np.ndarray,
    pairs=None,
) -> list[PathBatch]:
    """Specular paths of one order: image method backwards from each receiver.

    Only the (receiver, chain) pairs whose chain's last-leg beam can reach the receiver are
    back-traced (:func:`~wavepaths.search.beams.reflection_candidates`; the others are
    counted in ``reflection_order_{k}_culled_beam``), or the pairs given in ``pairs`` (an
    iterable of ``(receiver rows, chain rows)``: the launched candidates).
    """
    lv = ctx.levels[order]
    c, n = len(lv), len(rx)
    out = []
    if c == 0 or n == 0:
        return out
    tag = f"reflection_order_{order}"
    if pairs is None:
        # (receiver, chain) pairs whose chain's last-leg beam can reach the receiver (beams.py)
        pairs = reflection_candidates(scene, ctx, order, rx, stats, CANDIDATE_BUDGET)
    for ri, ci in pairs:
        stats[f"{tag}_candidates"] += len(ri)
        if ctx.options.prune_db is not None:
            # |a| <= lambda / (4 pi |rx - I_k|) for |Gamma| <= 1: drop chains below the tolerance
            direct = np.linalg.norm(rx[ri] - ctx.tx[lv.source[ci]], axis=1)
            unfolded = np.linalg.norm(rx[ri] - lv.images[ci, -1], axis=1)
            weak = unfolded > 10 ** (ctx.options.prune_db / 20) * direct
            if weak.any():
                # count only those that would have been paths, so the stated bound uses the true number
                okw, _, _ = backtrace(scene, rx[ri[weak]], lv, ci[weak], compiled=ctx.options.compiled)
                stats["pruned_paths_upper_bound"] += len(okw)
                stats[f"{tag}_pruned_candidates"] += int(weak.sum())
            ri, ci = ri[~weak], ci[~weak]
        ok, pts, rej = backtrace(scene, rx[ri], lv, ci, compiled=ctx.options.compiled)
        stats[f"{tag}_rejected_segment"] += rej["segment"]
        stats[f"{tag}_rejected_outside_polygon"] += rej["outside_polygon"]
        ri, ci = ri[ok], ci[ok]
        verts = np.concatenate([lv.images[ci, :1], pts, rx[ri][:, None, :]], axis=1)
        blocked = occluded_chains(scene, verts, stats, grazing[lv.source[ci], ri])
        stats[f"{tag}_rejected_occluded"] += int(blocked.sum())
        keep = ~blocked
        ri, ci, verts = ri[keep], ci[keep], verts[keep]
        polys = lv.polygons[ci]
        k = len(ri)
        out.append(
            PathBatch(
                lv.source[ci], ri + rx_offset, np.full((k, order), InteractionType.REFLECTION, np.int8), polys,
                triangle_of(scene, polys), np.full((k, 2), -1, np.int64), verts,
            )
        )
    return out


def _diffraction_part(scene: "Scene", ctx: TxContext, rx: np.ndarray, rx_offset: int, stats: Counter,
                      grazing: np.ndarray, pending: list | None) -> list[PathBatch]:
    """The diffracted paths of :func:`trace_tile`: the receivers' image trees, then every (a, b).

    When the receivers' trees together exceed the guard of
    :func:`~wavepaths.search.images.build_image_levels` (munich at two reflections after the
    edge: up to 1.7 M order-2 chains per street-level receiver), the receivers are split in
    halves, each traced alone (their paths do not depend on each other); a single receiver
    whose own tree exceeds it raises :class:`~wavepaths.errors.ImageTreeTooLarge`.
    """
    opts = ctx.options
    try:
        rx_stats: dict = {}
        rx_levels = build_image_levels(scene, rx, opts.diffraction_reflections, opts.skip_absorbers, rx_stats,
                                       compiled=None if opts.compiled else False,
                                       visibility_group=0 if "mirror_visibility" in opts.disable_culling
                                       else RX_VISIBILITY_GROUP)
    except ImageTreeTooLarge:
        if len(rx) < 2:
            raise
        half = len(rx) // 2
        stats["rx_tile_splits"] += 1
        out = []
        for lo, hi in ((0, half), (half, len(rx))):
            first = len(pending) if pending is not None else 0
            out += _diffraction_part(scene, ctx, rx[lo:hi], rx_offset + lo, stats, grazing[:, lo:hi], pending)
            for pend in (pending or [])[first:]:  # their receivers, tile-local: from this half's start
                pend.rx = pend.rx + lo
        return out
    stats.update({f"rx_{k}": v for k, v in rx_stats.items()})
    tree = opts.diffraction_reflections >= 1 and ctx.apertures is not None and bool(ctx.source_edges)
    out = []
    for a in range(opts.diffraction_reflections + 1):
        # the receiver side queries the edges that the order-a sources reach
        edges = ctx.source_edges[a] if tree else None
        for b in range(opts.diffraction_reflections + 1 - a):
            out += diffraction_tile(scene, ctx, a, b, rx, rx_levels, rx_offset, stats, grazing, edges, pending)
    return out


def trace_tile(scene: "Scene", ctx: TxContext, rx: np.ndarray, rx_offset: int = 0,
               pending: list | None = None) -> tuple[list[PathBatch], Counter]:
    """All paths of ``ctx.options`` from the context's transmitters to the receivers ``rx``.

    With a ``pending`` list, the diffracted candidates are not cast but appended to it
    (:class:`~wavepaths.search.diffraction.PendingDiffraction`, see
    :func:`~wavepaths.search.diffraction.diffraction_tile`); the other paths are traced.
    """
    opts = ctx.options
    stats: Counter = Counter()
    batches: list[PathBatch] = []
    grazing = np.zeros((len(ctx.tx), len(rx)), dtype=bool)
    if opts.diffraction and len(ctx.diffracting):
        if opts.diffraction_candidates == "launched":
            from .launched import launched_diffraction

            batches += launched_diffraction(scene, ctx, rx, rx_offset, stats, grazing, pending)
        else:
            batches += _diffraction_part(scene, ctx, rx, rx_offset, stats, grazing, pending)
    if opts.los:
        batches.append(los_tile(scene, ctx, rx, rx_offset, stats, grazing))
    launched = None
    if opts.reflection_candidates == "launched" and opts.max_reflections >= 1:
        from .launched import cached_segments
        from .txrays import reflection_candidates_launched

        segments = cached_segments(ctx, ("launch_rays", opts.launch_rays), rx)
        launched = reflection_candidates_launched(scene, ctx, rx, opts.launch_rays, segments=segments)
        stats["launched_reflection_candidates"] += sum(len(p) for p, _ in launched)
    for k in range(1, opts.max_reflections + 1):
        pairs = None if launched is None else [launched[k - 1]]
        batches += reflection_tile(scene, ctx, k, rx, rx_offset, stats, grazing, pairs)
    return batches, stats
