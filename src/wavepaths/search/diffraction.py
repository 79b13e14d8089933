"""Diffracted paths of a tile: one diffraction with ``a`` reflections before and ``b`` after.

The tile's candidate search (:func:`diffraction_tile`): the transmitter side's sources come
from the context, culled per chunk of receiver images by their Keller cones
(:mod:`wavepaths.search.diffraction_bounds`); the receiver side is
:mod:`wavepaths.search.end_sides`; the two are joined on (dihedron, sector), which is the
seed's FindDihedron test (§3.3), with the closed-form diffraction point (§2.3)
(:mod:`wavepaths.search.diffraction_join`); then, here, the back-traces of the reflections
on both sides, the pruning of weak candidates (or their pending record for the tolerance
of coverage maps) and the occlusion of every leg (:func:`finish_diffraction`).

The names of the two helper modules used elsewhere are re-exported here.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from . import kernels
from .spheres import morton_order
from .chains import CANDIDATE_BUDGET, occluded_chains, triangle_of
from .context import TxContext
from .diffraction_bounds import (FRAME_BLOCK, UTD_BOUND_FLOOR, KellerFrame, _diffraction_amplitude_bound,
                                 keller_cone_keep, keller_frame)
from .diffraction_join import _diffraction_prefilter, _join_chunks, _join_pairs, _join_ranges, _joined_candidates
from .end_sides import _EndSide, _keller_window, _receiver_side, _receiver_side_by_tree, _transmitter_side
from ..scene.polygon_query import POLYGON_MARGIN
from .images import SEGMENT_EPS, ImageLevel, backtrace
from .reach import MIRROR_REACH_BUDGET, MirrorReach, mirror_reach
from .paths import InteractionType, PathBatch

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene

__all__ = [
    # the tile's candidate search
    "COMPILED_PAIR_BUDGET", "DENSE_RECEIVER_SIDE_MAX_DIHEDRA", "LISTED_CHUNK_ROWS", "PendingDiffraction",
    "by_last_mirror", "diffraction_tile", "finish_diffraction", "spatial_order",
    # re-exported from diffraction_bounds and diffraction_join
    "FRAME_BLOCK", "KellerFrame", "UTD_BOUND_FLOOR", "_diffraction_amplitude_bound", "_diffraction_prefilter",
    "_join_chunks", "_join_pairs", "_join_ranges", "_joined_candidates", "keller_cone_keep", "keller_frame",
]

# the numpy receiver side of order >= 1 is dense (matrix products over images x dihedra) up to
# this many dihedra, tree queries above: dense was 2.6x faster with 640 (etoile_crop, R3+D2) and
# 1.5x with ~100 (simple_street_canyon map, R2+D1); the tree's cost grows as log(dihedra). The
# compiled receiver side is always dense: on munich's R2+D2 strip, with 5 k to 30 k dihedra per
# chunk, R-D-R took 1.7 s dense against 2.7 s through the tree (two rounds each)
DENSE_RECEIVER_SIDE_MAX_DIHEDRA = 4096
COMPILED_PAIR_BUDGET = 1 << 23
"""(receiver image, dihedron) pairs per chunk of :func:`diffraction_tile` with the compiled
receiver side (one int32 each, 32 MB; the pairs that pass, about 50 bytes each, are
usually a few per cent): each chunk pays a fixed cost (the Keller-cone culling of every
source, the gathers of the kept ones), larger chunks cull less. On munich's R2+D2
strip, 2^21 pairs per chunk took 52 s, 2^23 39 s, 2^25 43 s (the same 120 paths)."""


def _mirror_reach(scene: "Scene", ctx: TxContext, a: int) -> MirrorReach | None:
    """The :func:`mirror_reach` lists of the order-``a`` sources, built once per context
    (``ctx.derived``); ``None`` above :data:`MIRROR_REACH_BUDGET` or with the test switched off."""
    if "mirror_reach" in ctx.options.disable_culling:
        return None
    key = ("mirror_reach", a)
    if key not in ctx.derived:
        _, cone = _source_frames(scene, ctx, a)
        with kernels.CACHE_LOCK:
            if key not in ctx.derived:
                big = scene.num_polygons * max(len(cone.inv), 1) > MIRROR_REACH_BUDGET
                ctx.derived[key] = None if big else mirror_reach(
                    scene, cone, ctx.options.compiled and kernels.available())
    return ctx.derived[key]


def _source_frames(scene: "Scene", ctx: TxContext, a: int) -> tuple[_EndSide, KellerFrame]:
    """The transmitter side (:func:`_transmitter_side`) and the
    :class:`~wavepaths.search.diffraction_bounds.KellerFrame` of all the order-``a``
    diffraction sources, built once per context (``ctx.derived``); a chunk's culled sources
    take their rows."""
    key = ("source_frames", a)
    got = ctx.derived.get(key)
    if got is None:
        with kernels.CACHE_LOCK:
            got = ctx.derived.get(key)
            if got is None:
                src, tx_lv = ctx.diffraction_sources[a], ctx.levels[a]
                got = (_transmitter_side(scene, ctx, tx_lv, src),
                       keller_frame(scene.dihedra, src, tx_lv.last[src.chain]))
                ctx.derived[key] = got
    return got


LISTED_CHUNK_ROWS = 1 << 17
"""Receiver images per chunk at most when the chunks follow the reach lists (bounds the
per-image temporaries, such as the aperture planes, 192 bytes per image at b = 2)."""


def _list_chunks(sizes: np.ndarray, budget: int, max_rows: int) -> np.ndarray:
    """Chunk boundaries (ascending, from 0 to ``len(sizes)``) over consecutive rows: a chunk
    ends where the running sum of ``sizes`` crosses a multiple of ``budget``, so it holds at
    most ``budget`` beyond its first row (a row larger than that starts a chunk), and at most
    ``max_rows`` rows."""
    n = len(sizes)
    if n == 0:
        return np.zeros(1, np.int64)
    cs = np.cumsum(sizes)
    cuts = np.searchsorted(cs, np.arange(budget, int(cs[-1]), budget), side="right")
    cuts = np.union1d(cuts, np.arange(max_rows, n, max_rows))
    return np.unique(np.concatenate([[0], cuts[(cuts > 0) & (cuts < n)], [n]])).astype(np.int64)


def spatial_order(level: ImageLevel) -> ImageLevel:
    """The chains of ``level`` reordered along a Morton curve of their last images.

    The rows of a level are self-contained (source, mirrors, images), so any order gives
    the same paths; in this one, consecutive receiver images are close in space, which is
    what the chunks of :func:`diffraction_tile` need, and their gathers read memory in order.
    """
    if level.order == 0 or len(level) < 2:
        return level
    o = morton_order(level.last)
    return ImageLevel(level.source[o], level.polygons[o], level.images[o])


def by_last_mirror(level: ImageLevel) -> ImageLevel:
    """The chains of ``level`` (order >= 1) grouped by their last mirror, in their order within a group."""
    o = np.argsort(level.polygons[:, -1], kind="stable")
    return ImageLevel(level.source[o], level.polygons[o], level.images[o])


def diffraction_tile(
    scene: "Scene",
    ctx: TxContext,
    a: int,
    b: int,
    rx: np.ndarray,
    rx_levels: list[ImageLevel],
    rx_offset: int,
    stats: Counter,
    grazing: np.ndarray,
    edges=None,
    pending: list | None = None,
) -> list[PathBatch]:
    """Diffracted paths with ``a`` reflections before and ``b`` after the diffraction.

    With a ``pending`` list, the candidates that passed every test but occlusion are
    appended to it as :class:`PendingDiffraction` (with their amplitude bounds) instead of
    being cast: :func:`finish_diffraction` casts them later.

    ``edges``: the context's :func:`~wavepaths.search.beams.edge_tree` over the dihedra of the
    order-``a`` sources (``ctx.source_edges[a]``); with it
    (and the context's apertures) the numpy receiver side of order ``b >= 1`` is found by tree
    queries instead of the dense product when there are more than
    ``DENSE_RECEIVER_SIDE_MAX_DIHEDRA`` candidate dihedra and no reach lists.

    Also marks in ``grazing`` (m, n) the (tx, rx) pairs for which a candidate lies within
    the float32 uncertainty of a shadow or reflection boundary of its edge: the geometrical
    optics paths of those pairs are then cast in float64, so that the UTD field, whose
    boundary terms switch by the float64 angles, stays continuous.

    Order of the tests, cheapest and most selective first:

    1. per (receiver image, dihedron): for ``b >= 1``, the dihedron in the reach list of the
       image's last mirror (:class:`MirrorReach`; with the compiled kernels only the listed
       pairs are visited, in chunks of about ``COMPILED_PAIR_BUDGET`` of them), the mirror
       side and beam of that mirror; the sector around the edge (:func:`_receiver_side`);
    2. the join with the transmitter side on (dihedron, sector): FindDihedron (seed
       §3.3) accepts E-P-R exactly when E and R lie in the same sector of the edge (a
       sector is a prism around the edge line), whose bounding faces are the true
       dihedron, so the join *is* the seed's test, evaluated once per end, not per path
       (:func:`~wavepaths.topology.sectors.sector_angle`; tests/search check it against
       :func:`~wavepaths.topology.find_dihedron.find_dihedron`);
    3. the closed-form diffraction point (seed §2.3) in the reduced coordinates of the
       two ends, ``t = (t_e d_r + t_r d_e) / (d_e + d_r)``, on the edge segment, not
       proven hidden from the transmitter side, in the shadow region without
       ``lit_region`` (steps 2 and 3 run as one compiled loop with numba:
       :func:`~wavepaths.search.diffraction_join._joined_candidates`);
    4. the reflection points on both sides by the image method (back-traces);
    5. occlusion of every leg, cast in one batch.
    """
    rx_lv = rx_levels[b]
    tag = f"diffraction_{a}r_{b}r"
    out: list[PathBatch] = []
    if len(rx_lv) == 0 or len(ctx.diffraction_sources[a].chain) == 0:
        return out
    src_all = ctx.diffraction_sources[a]
    tside_all, cone = _source_frames(scene, ctx, a)
    compiled = ctx.options.compiled and kernels.available()
    m = int(ctx.sectors.angles.shape[1])
    # receiver images per chunk: the numpy receiver side holds about m + 4 (images x dihedra)
    # temporaries, the compiled one a single int32 array of the survivors' columns
    per_pair, budget = (1, COMPILED_PAIR_BUDGET) if compiled else (m + 4, CANDIDATE_BUDGET)
    step = max(1, budget // (max(len(cone.dihedra), 1) * per_pair))
    # with b >= 1, each image meets only the dihedra in its last mirror's reach list
    reach = _mirror_reach(scene, ctx, a) if b >= 1 else None
    if reach is not None and compiled and a == 0:
        # one source per (transmitter, dihedron): the Keller-cone culling per chunk of nearby
        # images gains little here, while images that share their last mirror, side by side,
        # let the kernel gather that mirror's list once for all of them
        rx_lv = by_last_mirror(rx_lv)
    else:
        rx_lv = spatial_order(rx_lv)
    if reach is not None and compiled:
        # the compiled kernel walks the lists: chunks of about `budget` listed pairs
        bounds = _list_chunks(reach.sizes(rx_lv.polygons[:, -1]), budget, LISTED_CHUNK_ROWS)
    else:
        bounds = np.append(np.arange(0, len(rx_lv), step), len(rx_lv))
    # receiver images in chunks of consecutive rows: in Morton order (:func:`spatial_order`),
    # each chunk is compact in space, and the Keller-cone culling below keeps fewer dihedra
    # for it (etoile_crop at depth 3: 608 M -> 327 M pairs at b = 2); by last mirror, the
    # lists do that culling
    for s, s_end in zip(bounds[:-1], bounds[1:]):
        e_rows = np.arange(s, s_end)
        # Keller-cone culling for this chunk of receivers (or receiver images): keep the
        # (source, dihedron) pairs whose diffracted cones can reach the chunk's bounding sphere
        src, tside = src_all, tside_all
        diffr = cone.dihedra  # the distinct dihedra of the sources, ascending
        if "keller_cone" not in ctx.options.disable_culling:
            keep = keller_cone_keep(cone, rx_lv.last[e_rows], compiled)
            if keep is not None:
                rows = np.nonzero(keep)[0]
                src, tside = src_all.take(rows), tside_all.take(rows)
                kept = np.zeros(len(cone.dihedra), dtype=bool)  # (a mask: np.unique sorts millions of rows)
                kept[cone.inv[rows]] = True
                diffr = cone.dihedra[kept]
        stats[f"{tag}_source_pairs_culled_keller_cone"] += len(src_all.chain) - len(src.chain)
        if len(diffr) == 0:
            continue
        stats[f"{tag}_receiver_pairs"] += len(e_rows) * len(diffr)
        window = None if "keller_window" in ctx.options.disable_culling else _keller_window(scene, tside)
        if (b >= 1 and edges is not None and not compiled and len(diffr) > DENSE_RECEIVER_SIDE_MAX_DIHEDRA
                and reach is None and not {"receiver_mirror_side", "receiver_beam"} & ctx.options.disable_culling):
            rside = _receiver_side_by_tree(scene, ctx, rx_lv, e_rows, diffr, edges, stats, tag, window)
        else:
            rside = _receiver_side(scene, ctx, rx_lv, e_rows, diffr, stats, tag, window, reach)
        for rows, src_rows, t in _joined_candidates(scene, ctx, a, src, rside, tside, stats, tag):
            out += _diffraction_candidates(scene, ctx, a, b, rx, rx_lv, rx_offset, stats, grazing, tag,
                                           rside, rows, tside, src_rows, t, pending)
    return out


@dataclass
class PendingDiffraction:
    """Diffracted candidates that passed every test but occlusion, held back for the
    tolerance of a coverage map (:func:`wavepaths.coverage.solver.solve_tile`).

    Attributes
    ----------
    a, b : int
        Reflections before and after the diffraction.
    tx, rx : (k,) int64
        Transmitter index and receiver index (tile-local, without the offset).
    amp : (k,) float64 [1/m]
        Upper bound on ``|a| / (lambda / 4 pi)`` with unit antenna patterns
        (:func:`~wavepaths.search.diffraction_bounds._diffraction_amplitude_bound`).
    rest : tuple
        What :func:`finish_diffraction` needs to cast and assemble them.
    """

    a: int
    b: int
    tx: np.ndarray
    rx: np.ndarray
    amp: np.ndarray
    rest: tuple

    def __len__(self) -> int:
        return len(self.tx)


def _diffraction_candidates(scene, ctx, a, b, rx, rx_lv, rx_offset, stats, grazing, tag, rside: _EndSide,
                            rows: np.ndarray, tside: _EndSide, src_rows: np.ndarray, t: np.ndarray,
                            pending: list | None = None) -> list[PathBatch]:
    """Steps 4 and 5 of :func:`diffraction_tile` on the candidates that passed
    :func:`~wavepaths.search.diffraction_join._joined_candidates` (receiver side
    ``rside[rows]``, transmitter side ``tside[src_rows]``, diffraction points at ``t`` [m
    along the edge])."""
    compiled = ctx.options.compiled and kernels.available()
    fn = _diffraction_candidates_compiled if compiled else _diffraction_candidates_numpy
    return fn(scene, ctx, a, b, rx, rx_lv, rx_offset, stats, grazing, tag, rside, rows, tside, src_rows, t, pending)


def _diffraction_candidates_numpy(scene, ctx, a, b, rx, rx_lv, rx_offset, stats, grazing, tag, rside: _EndSide,
                                  rows: np.ndarray, tside: _EndSide, src_rows: np.ndarray, t: np.ndarray,
                                  pending: list | None = None) -> list[PathBatch]:
    """:func:`_diffraction_candidates` in numpy (the reference of the compiled one)."""
    tx_lv = ctx.levels[a]
    dihedra = scene.dihedra
    d = rside.dihedron[rows]
    te, de = tside.t[src_rows], tside.rho[src_rows]
    tr, dr = rside.t[rows], rside.rho[rows]
    phi, phi_prime = rside.phi[rows], tside.phi[src_rows]
    sec = rside.sector[rows]
    # GO rays within the float32 uncertainty of the edge: the angular distance to the shadow
    # or reflection boundary times the shorter leg
    wedge = ctx.sectors.width[d, sec]
    leg = np.sqrt(np.minimum((te - t) ** 2 + de * de, (tr - t) ** 2 + dr * dr))
    offs = np.minimum(np.abs(np.abs(phi - phi_prime) - np.pi), np.abs(phi + phi_prime - np.pi))
    offs = np.minimum(offs, np.abs(phi + phi_prime - (2 * wedge - np.pi)))
    near = offs * leg < 4 * scene.length_tolerance(scene.tolerances.ray_offset)
    e, c = rside.row[rows], tside.row[src_rows]
    if near.any():
        grazing[tx_lv.source[c[near]], rx_lv.source[e[near]]] = True
        stats["pairs_on_boundaries"] += int(near.sum())
    amp = None
    if ctx.options.prune_frequency_hz is not None and (ctx.options.prune_db is not None or pending is not None):
        amp = _diffraction_amplitude_bound(ctx, phi, phi_prime, wedge / np.pi, te, de, tr, dr, t)
    P = dihedra.origin[d] + t[:, None] * dihedra.direction[d]
    # reflections after (receiver images) and before (transmitter images)
    ok2, post, rej2 = backtrace(scene, P, rx_lv, e, compiled=ctx.options.compiled)
    e, d, sec, c, P = e[ok2], d[ok2], sec[ok2], c[ok2], P[ok2]
    ok1, pre, rej1 = backtrace(scene, P, tx_lv, c, compiled=ctx.options.compiled)
    e, d, sec, c, P, post = e[ok1], d[ok1], sec[ok1], c[ok1], P[ok1], post[ok1]
    stats[f"{tag}_rejected_segment"] += rej1["segment"] + rej2["segment"]
    stats[f"{tag}_rejected_outside_polygon"] += rej1["outside_polygon"] + rej2["outside_polygon"]
    if amp is not None:
        amp = amp[ok2][ok1]
    # post in path order after the diffraction
    verts = np.concatenate([tx_lv.images[c, :1], pre, P[:, None, :], post[:, ::-1], rx[rx_lv.source[e]][:, None, :]],
                           axis=1)
    return _pending_or_batch(scene, ctx, a, b, rx, rx_lv, rx_offset, stats, tag, e, d, sec, c, verts, amp, pending)


def _pending_or_batch(scene, ctx, a, b, rx, rx_lv, rx_offset, stats, tag, e, d, sec, c, verts, amp,
                      pending: list | None) -> list[PathBatch]:
    """The end of :func:`_diffraction_candidates` (both forms) on the back-traced candidates
    (receiver-side rows ``e``, dihedra ``d``, sectors ``sec``, transmitter-side rows ``c``,
    path vertices ``verts``, amplitude bounds ``amp`` or ``None``): the pruning of weak ones,
    then their pending record, or their occlusion and path batch.

    First, by structure, a reflection next to the diffraction on a mirror whose plane holds
    the diffraction point (within the casters' plane tolerance): the reflection point is then
    the diffraction point itself (a reflection on a face of the edge, or on a face coplanar
    with one), a degenerate chain that the segment-length test of
    :func:`~wavepaths.search.chains.occluded_chains` catches only where rounding leaves the
    two points closer than the weld tolerance (at 1e6 m and grazing, they came out 5e-5 m
    apart, and the path counted the edge's diffraction twice).
    """
    tx_lv = ctx.levels[a]
    holds = np.zeros(len(e), dtype=bool)
    if len(e) and (a or b):
        from ..raycast import plane_tolerance

        tol = plane_tolerance(scene)
        P = verts[:, a + 1]
        for mirrors in ([tx_lv.polygons[c, a - 1]] if a else []) + ([rx_lv.polygons[e, b - 1]] if b else []):
            n = scene.polygon_normal[mirrors]
            dist = (n[:, 0] * P[:, 0] + n[:, 1] * P[:, 1]) + n[:, 2] * P[:, 2] - scene.polygon_offset[mirrors]
            holds |= np.abs(dist) <= tol
    if holds.any():
        stats[f"{tag}_rejected_mirror_holds_edge_point"] += int(holds.sum())
        keep = ~holds
        e, d, sec, c, verts = e[keep], d[keep], sec[keep], c[keep], verts[keep]
        amp = None if amp is None else amp[keep]
    if amp is not None and ctx.options.prune_db is not None:
        # pruned after the back-traces, so that the count bounds the paths dropped (not the
        # candidates): before the casts and the fields, which cost the most per path
        direct = np.linalg.norm(rx[rx_lv.source[e]] - ctx.tx[tx_lv.source[c]], axis=1)
        weak = amp * direct < 10 ** (-ctx.options.prune_db / 20)
        stats["pruned_paths_upper_bound"] += int(weak.sum())
        stats[f"{tag}_pruned_candidates"] += int(weak.sum())
        keep = ~weak
        e, d, sec, c, verts, amp = e[keep], d[keep], sec[keep], c[keep], verts[keep], amp[keep]
    # the true dihedron: the faces bounding the sector (seed §3.3)
    f0 = ctx.sectors.face[d, sec]
    fn = ctx.sectors.face[d, np.mod(sec + 1, ctx.sectors.count[d])]
    post_polys = rx_lv.polygons[e][:, ::-1]
    pend = PendingDiffraction(a, b, tx_lv.source[c], rx_lv.source[e], amp, (d, c, f0, fn, verts, post_polys))
    if pending is not None:
        pending.append(pend)
        return []
    return [finish_diffraction(scene, ctx, pend, rx_offset, stats)]


def _diffraction_candidates_compiled(scene, ctx, a, b, rx, rx_lv, rx_offset, stats, grazing, tag, rside: _EndSide,
                                     rows: np.ndarray, tside: _EndSide, src_rows: np.ndarray, t: np.ndarray,
                                     pending: list | None = None) -> list[PathBatch]:
    """:func:`_diffraction_candidates` with the boundary flags, the points on the edges, both
    back-traces and the vertices in :func:`wavepaths.search._numba_diffraction.diffraction_vertices`
    (the same expressions, candidate by candidate)."""
    from . import _numba

    tx_lv = ctx.levels[a]
    k = len(rows)
    c_ = np.ascontiguousarray
    near = np.empty(k, np.bool_)
    keep = np.empty(k, np.int64)
    verts = np.empty((k, a + b + 3, 3))
    rej = np.zeros(2, np.int64)
    n = _numba.diffraction_vertices(
        c_(rows, dtype=np.int64), c_(src_rows, dtype=np.int64), c_(t, dtype=np.float64), rside.row, rside.dihedron,
        rside.sector, rside.phi, rside.t, rside.rho, tside.row, tside.phi, tside.t, tside.rho, ctx.sectors.width,
        scene.dihedra.origin, scene.dihedra.direction, 4 * scene.length_tolerance(scene.tolerances.ray_offset),
        rx_lv.images, rx_lv.polygons, rx_lv.source, c_(rx, dtype=np.float64), tx_lv.images, tx_lv.polygons,
        scene.polygon_normal, scene.polygon_offset, scene.polygon_tri_ptr, scene.polygon_tris, scene.triangles,
        scene.vertices, scene.triangle_dual, SEGMENT_EPS, POLYGON_MARGIN, near, keep, verts, rej)
    if near.any():
        grazing[tx_lv.source[tside.row[src_rows[near]]], rx_lv.source[rside.row[rows[near]]]] = True
        stats["pairs_on_boundaries"] += int(near.sum())
    stats[f"{tag}_rejected_segment"] += int(rej[0])
    stats[f"{tag}_rejected_outside_polygon"] += int(rej[1])
    keep, verts = keep[:n], verts[:n]
    rr, ss = rows[keep], src_rows[keep]
    e, d, sec, c = rside.row[rr], rside.dihedron[rr], rside.sector[rr], tside.row[ss]
    amp = None
    if ctx.options.prune_frequency_hz is not None and (ctx.options.prune_db is not None or pending is not None):
        from ..em.utd_terms import SIN_BETA_0_FLOOR
        from . import _numba_tolerance
        from .paths import SPEED_OF_LIGHT

        # _diffraction_amplitude_bound (the numpy reference), candidate by candidate
        amp = _numba_tolerance.amplitude_bounds(rside.phi[rr], tside.phi[ss], ctx.sectors.width[d, sec] / np.pi, tside.t[ss],
                                      tside.rho[ss], rside.t[rr], rside.rho[rr], t[keep],
                                      2.0 * np.pi * ctx.options.prune_frequency_hz / SPEED_OF_LIGHT, SIN_BETA_0_FLOOR,
                                      UTD_BOUND_FLOOR)
    return _pending_or_batch(scene, ctx, a, b, rx, rx_lv, rx_offset, stats, tag, e, d, sec, c, verts, amp, pending)


def finish_diffraction(scene: "Scene", ctx: TxContext, pend: PendingDiffraction, rx_offset: int, stats: Counter,
                       keep: np.ndarray | None = None) -> PathBatch:
    """Step 5 of :func:`diffraction_tile` (occlusion of every leg) on the candidates ``pend``
    (those of ``keep``, a bool mask, if given), and their path batch."""
    dihedra = scene.dihedra
    a, b = pend.a, pend.b
    tx_lv = ctx.levels[a]
    tag = f"diffraction_{a}r_{b}r"
    rx_i = pend.rx
    d, c, f0, fn, verts, post_polys = pend.rest
    rows = None if keep is None else np.nonzero(keep)[0]
    if rows is not None:
        verts = verts[rows]
    blocked = occluded_chains(scene, verts, stats)
    stats[f"{tag}_rejected_occluded"] += int(blocked.sum())
    clear = np.nonzero(~blocked)[0]
    rows = clear if rows is None else rows[clear]  # the candidates kept and clear: one gather each
    verts = verts[clear]
    rx_i, d, c, f0, fn, post_polys = (x[rows] for x in (rx_i, d, c, f0, fn, post_polys))
    k = len(d)
    kinds = np.full((k, a + 1 + b), InteractionType.REFLECTION, np.int8)
    kinds[:, a] = InteractionType.DIFFRACTION
    prims = np.concatenate([tx_lv.polygons[c], d[:, None], post_polys], axis=1)
    tris = np.concatenate(
        [triangle_of(scene, tx_lv.polygons[c]), dihedra.face_triangle[f0][:, None], triangle_of(scene, post_polys)],
        axis=1,
    )
    return PathBatch(tx_lv.source[c], rx_i + rx_offset, kinds, prims, tris, np.stack([f0, fn], axis=1), verts)
