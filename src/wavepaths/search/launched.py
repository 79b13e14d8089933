"""Diffracted paths from launched candidates: the exact engine's tests on sampled sequences.

With ``TraceOptions(diffraction_candidates="launched")`` the diffracted paths of a tile come
from the candidate sequences of :mod:`wavepaths.search.launch` instead of the enumeration of
:func:`~wavepaths.search.diffraction.diffraction_tile`. Each candidate names its
transmitter-side source (a row of ``ctx.diffraction_sources[a]``: the image chain before the
edge and the dihedron) and the mirrors after the edge; from there the steps are the
exhaustive search's own, so a launched path is exactly the path that search finds:

1. the receiver's image through the mirrors after the edge, last mirror first (its
   receiver-side image chain), projected on the edge: the sector around the edge, wider
   than pi (:func:`~wavepaths.search.end_sides._kept_pairs_end_side`'s tests);
2. the same sector as the source's (FindDihedron, seed §3.3: the join key);
3. :func:`~wavepaths.search.diffraction._diffraction_prefilter`: the closed-form point
   (seed §2.3) on the edge, not proven hidden, the lit-region option;
4. :func:`~wavepaths.search.diffraction._diffraction_candidates`: back-traces on both sides,
   then occlusion (or the coverage tolerance's pending list).

What the launched search can miss is what the sampling misses (:mod:`wavepaths.search.launch`);
what it finds, it finds exactly. First-order diffraction without reflections (E-D-R, the
seed's own case and the strongest diffracted paths) is not sampled: every tile enumerates it
as the exhaustive search does (:func:`~wavepaths.search.diffraction.diffraction_tile` with
``a = b = 0``, the receivers themselves as their images), so a launched map has every one of
those paths. It costs a per-(receiver, dihedron) test over the dihedra the transmitter sees:
on munich's map 439 M pairs and 107 M candidates, 79 M of them occluded; the fans no longer
carry those sequences (:func:`~wavepaths.search.launch.fan_segments`), which saves about as
much: the tiles took 237 s against 251 s before (535 s -> 530 s for the map, on a host where
the reference run took 312 s), with 1,042 D paths (0.3 %) the fans had missed. The sampled
chains are those with a reflection, whose pairs are what makes the exhaustive search of
munich take days.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from typing import TYPE_CHECKING

import numpy as np

from . import kernels
from .diffraction import _diffraction_candidates, _diffraction_prefilter, diffraction_tile
from .end_sides import _EndSide, _edge_frame, _sector_in_table, _transmitter_side
from .geometry import mirror_points
from .images import ImageLevel
from .launch import EdgeSamples, LaunchOptions, candidate_sequences, edge_samples, fan_segments
from .txrays import ray_segments
from .paths import PathBatch

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene
    from .context import TxContext


def launch_options(ctx: "TxContext") -> LaunchOptions:
    """The :class:`LaunchOptions` of a context's trace options (``launch_fan``)."""
    return LaunchOptions(fan=ctx.options.launch_fan)


def context_samples(scene: "Scene", ctx: "TxContext") -> EdgeSamples:
    """The context's edge samples (:func:`~wavepaths.search.launch.edge_samples`), built
    once per context (``ctx.derived``) and shared by its tiles."""
    key = ("launch_samples", ctx.options.launch_fan)
    got = ctx.derived.get(key)
    if got is None:
        with kernels.CACHE_LOCK:
            got = ctx.derived.get(key)
            if got is None:
                got = edge_samples(scene, ctx, launch_options(ctx))
                ctx.derived[key] = got
    return got


def prepare_launched(scene: "Scene", ctx: "TxContext", points: np.ndarray) -> None:
    """Trace the context's launched rays once for every query point to come (a coverage
    map's cells, a path query's receivers) and keep them in ``ctx.derived``, so that the
    tiles of ``points`` query them instead of tracing them again.

    With ``diffraction_candidates="launched"`` and ``diffraction_reflections >= 1``: the Keller fans
    (:func:`~wavepaths.search.launch.fan_segments`, key ``("launch_fans", launch_fan)``);
    with ``reflection_candidates="launched"``: the transmitter's rays
    (:func:`~wavepaths.search.txrays.ray_segments`, key ``("launch_rays", launch_rays)``).
    The segments kept are those whose tubes reach the box of ``points``; a tile outside
    that box traces its own (:func:`cached_segments`). Does nothing in the exhaustive modes.
    """
    opts = ctx.options
    if len(points) == 0:
        return
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    lo, hi = points.min(axis=0), points.max(axis=0)
    if opts.diffraction and opts.diffraction_candidates == "launched" and opts.diffraction_reflections >= 1:
        # (without reflections the diffracted paths are enumerated: no fan to trace)
        key = ("launch_fans", opts.launch_fan)
        got = ctx.derived.get(key)
        if got is None or not got.covers(points):
            ctx.derived[key] = fan_segments(scene, ctx, lo, hi, launch_options(ctx), context_samples(scene, ctx))
    if opts.reflection_candidates == "launched" and opts.max_reflections >= 1:
        key = ("launch_rays", opts.launch_rays)
        got = ctx.derived.get(key)
        if got is None or not got.covers(points):
            ctx.derived[key] = ray_segments(scene, ctx, opts.launch_rays, lo, hi, launch_options(ctx))


def shipped_context(ctx: "TxContext") -> "TxContext":
    """A copy of ``ctx`` for the tiles of a launched map, after :func:`prepare_launched`:
    each order's diffraction sources cut to those the cached fan segments name, the
    segments' source rows renumbered to match, and the edge samples left out (the tiles
    query the segments). Each worker process receives its own copy of the context: on
    munich the sources are some 480 MB of it, of which the segments name a few per cent.
    Returns ``ctx`` itself when no fans were traced."""
    key = ("launch_fans", ctx.options.launch_fan)
    segs = ctx.derived.get(key)
    if segs is None:
        return ctx
    sources = []
    renumbered = segs.source.copy()
    for a, src in enumerate(ctx.diffraction_sources):
        sel = segs.order == a
        # order 0 whole: the tiles enumerate the first-order paths without reflections from
        # every source the transmitter sees (a few thousand on munich), not only those sampled
        used = np.arange(len(src.chain)) if a == 0 else np.unique(segs.source[sel])
        sources.append(src.take(used))
        renumbered[sel] = np.searchsorted(used, segs.source[sel])
    derived = {k: v for k, v in ctx.derived.items() if not (isinstance(k, tuple) and k[0] == "launch_samples")}
    derived[key] = dataclasses.replace(segs, source=renumbered)
    return dataclasses.replace(ctx, diffraction_sources=sources, derived=derived)


def cached_segments(ctx: "TxContext", key: tuple, points: np.ndarray):
    """The segments :func:`prepare_launched` kept under ``key`` if their box holds every one
    of ``points``, else ``None`` (the caller traces the points' own)."""
    got = ctx.derived.get(key)
    return got if got is not None and got.covers(points) else None


def receiver_images(scene: "Scene", rx: np.ndarray, point: np.ndarray, after: np.ndarray) -> ImageLevel:
    """Receiver-side image chains of the candidates: ``rx[point]`` mirrored across the
    mirrors after the edge, last first.

    Parameters
    ----------
    rx : (n, 3) float64
    point : (k,) int64
        Receiver of each chain.
    after : (k, b) int64
        Mirrors after the edge, in path order.

    Returns
    -------
    ImageLevel
        Order ``b``, ``polygons`` from the receiver outward (``after`` reversed), ``source`` = ``point``.
    """
    polys = np.ascontiguousarray(after[:, ::-1])
    k, b = polys.shape
    images = np.empty((k, b + 1, 3))
    images[:, 0] = rx[point]
    for j in range(b):
        q = polys[:, j]
        images[:, j + 1] = mirror_points(images[:, j], scene.polygon_normal[q], scene.polygon_offset[q])
    return ImageLevel(np.asarray(point, np.int64), polys, images)


def launched_diffraction(scene: "Scene", ctx: "TxContext", rx: np.ndarray, rx_offset: int, stats: Counter,
                         grazing: np.ndarray, pending: list | None = None) -> list[PathBatch]:
    """The diffracted paths of a tile of receivers from launched candidates (module docstring).

    Counts in ``stats``: ``launched_candidates`` (sequences carried to the tile's
    receivers), per (a, b) ``diffraction_{a}r_{b}r_candidates`` (those of the group) and
    ``..._rejected_sector`` (receiver side in no sector wider than pi, or not in the
    source's), then the exhaustive search's counters of steps 3 and 4.
    """
    opts = ctx.options
    out: list[PathBatch] = []
    if len(ctx.diffraction_sources):
        # E-D-R, enumerated (module docstring): the receivers are their own order-0 images
        rx0 = receiver_images(scene, rx, np.arange(len(rx), dtype=np.int64), np.zeros((len(rx), 0), np.int64))
        out += diffraction_tile(scene, ctx, 0, 0, rx, [rx0], rx_offset, stats, grazing, None, pending)
    Dmax = opts.diffraction_reflections
    if Dmax == 0:
        return out
    segments = cached_segments(ctx, ("launch_fans", opts.launch_fan), rx)
    samples = context_samples(scene, ctx) if segments is None else None  # the segments need no samples
    seq = candidate_sequences(scene, ctx, rx, launch_options(ctx), samples, segments)
    stats["launched_candidates"] += len(seq)
    nb = (seq.after >= 0).sum(axis=1)
    for a in range(Dmax + 1):
        if a >= len(ctx.diffraction_sources):
            break
        in_a = np.nonzero(seq.order == a)[0]
        if len(in_a) == 0:
            continue
        # the transmitter side of the sources this tile's candidates name (not of all of
        # them: munich holds 11 M order-2 sources)
        used, s_local = np.unique(seq.source[in_a], return_inverse=True)
        local = np.full(len(seq), -1, np.int64)
        local[in_a] = s_local
        tside = _transmitter_side(scene, ctx, ctx.levels[a], ctx.diffraction_sources[a].take(used))
        for b in range(1 if a == 0 else 0, Dmax + 1 - a):  # E-D-R: enumerated above, not from the fans
            tag = f"diffraction_{a}r_{b}r"
            sel = np.nonzero((seq.order == a) & (nb == b))[0]
            if len(sel) == 0:
                continue
            stats[f"{tag}_candidates"] += len(sel)
            rx_lv = receiver_images(scene, rx, seq.point[sel], seq.after[sel, :b])
            s_rows = local[sel]
            d = seq.dihedron[sel]
            x, y, t = _edge_frame(scene, ctx, rx_lv.last, d)
            sec, width, phi = _sector_in_table(ctx, d, x, y)
            good = (sec >= 0) & (width > np.pi + scene.tolerances.coplanar_angle)
            good &= sec == tside.sector[s_rows]
            stats[f"{tag}_rejected_sector"] += int((~good).sum())
            e = np.nonzero(good)[0]
            rside = _EndSide(e, d[e], sec[e], phi[e], t[e], np.sqrt(x[e] * x[e] + y[e] * y[e]))
            rejected = np.zeros(3, np.int64)
            rows, src_rows, tt = _diffraction_prefilter(scene, ctx, rside, np.arange(len(e)), tside, s_rows[e],
                                                        rejected)
            stats[f"{tag}_rejected_off_edge"] += int(rejected[0])
            stats[f"{tag}_rejected_{'hidden' if a == 0 else 'aperture'}"] += int(rejected[1])
            stats[f"{tag}_rejected_lit_region"] += int(rejected[2])
            if len(rows):
                out += _diffraction_candidates(scene, ctx, a, b, rx, rx_lv, rx_offset, stats, grazing, tag, rside,
                                               rows, tside, src_rows, tt, pending)
    return out
