"""Transmitter-side work, done once and shared by every receiver tile.

A :class:`TxContext` holds, for a set of transmitters:

* the image tree up to the highest reflection order any path type needs;
* the beams of the reflection orders' chains, in trees (:class:`~wavepaths.search.beams.ChainBeams`,
  built on first use: :class:`~wavepaths.search.beams.LazyChainBeams`) that each receiver
  tile queries to back-trace only the chains whose last leg can reach it;
* for diffraction, every (image source, dihedron) pair whose source lies in a
  diffracting sector of the dihedron (wider than pi) and, for an image of order >= 1,
  whose edge lies beyond the image's last mirror and inside its beam (the incident leg
  leaves that mirror). Neither depends on the receiver nor on where on the edge the path
  lands, so the other pairs are dropped here, once (``*_culled_beam`` counts the second);
* for the transmitters themselves (order 0), the part of each edge a transmitter may see
  (:mod:`wavepaths.search.visibility`): pairs whose whole edge is proven hidden are dropped
  (``*_culled_hidden``), and the window of the others bounds where their diffraction
  points may fall; for images of order >= 1, the part of each edge from which a leg
  toward the image can cross its last mirror (its aperture window; ``*_culled_aperture``).

The context is all a coverage tile needs besides the scene; it is what a Dask worker
receives once (see :mod:`wavepaths.coverage`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Iterator

import numpy as np

from ..topology.sectors import SectorTable, sector_of, sector_table
from .apertures import Apertures, scene_apertures
from .beams import LazyChainBeams, chains_meeting_edges, edge_tree
from .images import ImageLevel, build_image_levels
from .options import TraceOptions, check_trace_arguments
from .aperture_windows import chain_aperture_windows
from .visibility import VisibilityWindows, visibility_windows

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene


@dataclass(frozen=True)
class DiffractionSources:
    """(image source, dihedron) pairs that can start a diffracted path, for one order.

    Sorted by ``key = dihedron * stride + sector`` so receivers can be joined to them.

    Attributes
    ----------
    chain : (c,) int64
        Row in the image level of that order.
    dihedron : (c,) int64
    key : (c,) int64
    unique_keys, key_start, key_count : (u,) int64
        Groups of equal keys in the sorted arrays.
    visible : VisibilityWindows or None
        Per pair, the part of the edge its incident leg may reach: at order 0, the part
        not proven hidden from the transmitter (:func:`~wavepaths.search.visibility.visibility_windows`);
        at order >= 1, where a leg from the edge to the image can cross the last mirror
        (:func:`~wavepaths.search.aperture_windows.aperture_windows`). Pairs whose window is
        empty are not here. ``None`` when the culling test is switched off.
    """

    chain: np.ndarray
    dihedron: np.ndarray
    key: np.ndarray
    unique_keys: np.ndarray
    key_start: np.ndarray
    key_count: np.ndarray
    visible: VisibilityWindows | None = None

    def take(self, rows: np.ndarray) -> "DiffractionSources":
        """The pairs ``rows`` (in their sorted order), regrouped."""
        key = self.key[rows]
        ascending = len(rows) < 2 or bool(np.all(rows[1:] > rows[:-1]))
        uk, start, count = _group_sorted(key) if ascending else _group(key)
        vis = None if self.visible is None else self.visible.take(rows)
        return DiffractionSources(self.chain[rows], self.dihedron[rows], key, uk, start, count, vis)


@dataclass(frozen=True)
class TxContext:
    """Receiver-independent state for a batch of transmitters (see module docstring)."""

    tx: np.ndarray
    options: TraceOptions
    levels: list[ImageLevel]
    sectors: SectorTable | None
    diffracting: np.ndarray
    diffraction_sources: list[DiffractionSources]
    key_stride: int
    stats: dict = field(default_factory=dict)
    beams: list = field(default_factory=list)  # per reflection order, LazyChainBeams or None (order 0, no chain)
    apertures: Apertures | None = None
    # per source order a, a SphereTree over the edges that order's sources can reach (the dihedra
    # of diffraction_sources[a], beams.edge_tree), or None without sources: the receiver side of
    # (a, b >= 1) queries it; empty without diffraction
    source_edges: list = field(default_factory=list)
    # arrays derived from the diffraction sources, built on first use by the tiles under
    # kernels.CACHE_LOCK (diffraction._source_frames: per order, the transmitter side and the
    # Keller-cone frame of every source); receiver-independent, so shared by every tile
    derived: dict = field(default_factory=dict)
    # the scene it was built for (Scene.fingerprint): trace() refuses it for another scene
    scene_fingerprint: str = ""


def _group(keys: np.ndarray):
    uk, start, count = np.unique(keys, return_index=True, return_counts=True)
    return uk, start.astype(np.int64), count.astype(np.int64)


def _group_sorted(keys: np.ndarray):
    """:func:`_group` of keys already sorted (no sort: the runs of equal keys)."""
    if len(keys) == 0:
        return keys.copy(), np.zeros(0, np.int64), np.zeros(0, np.int64)
    start = np.flatnonzero(np.concatenate([[True], keys[1:] != keys[:-1]])).astype(np.int64)
    return keys[start], start, np.diff(np.append(start, len(keys))).astype(np.int64)


PAIR_BLOCK = 1 << 21  # (image, dihedron) pairs given the sector test at once


def _source_pairs(
    scene: "Scene", lv: ImageLevel, diffracting: np.ndarray, edges, apertures: Apertures | None, cull: bool,
    compiled: bool = False,
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Blocks of (chain, dihedron) pairs of one order that may start a diffracted path.

    Order 0 (the transmitters), or without ``cull``: every pair. Order ``a >= 1``: only the
    pairs whose edge the chain's last leg can reach (beyond its last mirror, inside the beams
    through its mirrors: :func:`~wavepaths.search.beams.chains_meeting_edges`); the others
    cannot carry a diffracted path whose incident leg leaves the last mirror, so none is lost.
    """
    if lv.order == 0 or not cull or apertures is None:
        per = max(1, PAIR_BLOCK // max(len(diffracting), 1))
        for s in range(0, len(lv), per):
            r = np.arange(s, min(len(lv), s + per))
            yield np.repeat(r, len(diffracting)), np.tile(diffracting, len(r))
        return
    yield from chains_meeting_edges(scene, lv, apertures, edges, compiled=compiled)


def _diffracting_side(scene: "Scene", sectors: SectorTable, lv: ImageLevel, c: np.ndarray, d: np.ndarray,
                      compiled: bool) -> tuple[np.ndarray, np.ndarray]:
    """The (image chain ``c``, dihedron ``d``) pairs whose image lies in a sector of the edge
    wider than pi, off its faces (:func:`~wavepaths.topology.sectors.sector_of`): their rows
    (k,) int64 and sectors (k,) int64. With the compiled kernels, pair by pair in
    :func:`wavepaths.search._numba.end_sides` (the same expressions)."""
    from . import kernels
    from ..topology.sectors import FACE_ANGLE_TOL

    min_width = np.pi + scene.tolerances.coplanar_angle
    if compiled and kernels.available():
        from . import _numba

        k = len(c)
        keep, sec, f = np.empty(k, np.int64), np.empty(k, np.int64), np.empty(k)
        a = np.ascontiguousarray
        n = _numba.end_sides(a(lv.images), a(c, dtype=np.int64), a(d, dtype=np.int64), a(scene.dihedra.origin),
                             a(scene.dihedra.direction), a(sectors.x_hat), a(sectors.y_hat), a(sectors.angles),
                             a(sectors.count, dtype=np.int64), a(sectors.width), FACE_ANGLE_TOL, min_width,
                             keep, sec, f, f.copy(), f.copy())
        return keep[:n], sec[:n]
    sec, width = sector_of(sectors, d, lv.last[c], scene.dihedra.origin[d])
    keep = np.nonzero((sec >= 0) & (width > min_width))[0]
    return keep, sec[keep]


WINDOW_BLOCK = 1 << 19
"""(image, edge) pairs per call of the images' visibility windows: the march holds some
thirty arrays per pair, and munich's order-2 sources (tens of millions of pairs) at once
took over 24 GB."""


def _windows_in_blocks(scene: "Scene", lv: ImageLevel, c: np.ndarray, d: np.ndarray, lo: np.ndarray,
                       hi: np.ndarray, compiled: bool | None = None) -> VisibilityWindows:
    """:func:`~wavepaths.search.visibility.visibility_windows` of the image chains ``c`` of
    ``lv`` and dihedra ``d`` within their aperture windows ``[lo, hi]``, ``WINDOW_BLOCK``
    pairs at a time (each pair's march is its own: the same windows as one call)."""
    if len(c) <= WINDOW_BLOCK:
        return visibility_windows(scene, lv.last[c], d, start=(lo, hi), through=lv.polygons[c, -1], compiled=compiled)
    parts = []
    for s in range(0, len(c), WINDOW_BLOCK):
        cc, sl = c[s : s + WINDOW_BLOCK], slice(s, s + WINDOW_BLOCK)
        parts.append(visibility_windows(scene, lv.last[cc], d[sl], start=(lo[sl], hi[sl]), through=lv.polygons[cc, -1],
                                        compiled=compiled))
    cat = [np.concatenate([getattr(p, f) for p in parts]) for f in ("lo", "hi", "open0", "open1")]
    return VisibilityWindows(*cat, parts[0].tau, sum(p.rays for p in parts), max(p.rounds for p in parts))


def build_tx_context(scene: "Scene", tx: np.ndarray, options: TraceOptions | None) -> TxContext:
    """Build the :class:`TxContext` of transmitters ``tx`` (m, 3) [m] for ``options``.

    Raises a :class:`~wavepaths.errors.WavepathsError` for a ``scene`` that is not a Scene,
    ``options`` that are not a :class:`TraceOptions`, or positions that are not finite
    (k, 3) coordinates (:func:`~wavepaths.search.options.check_trace_arguments`,
    :func:`~wavepaths.search.trace.check_positions`), as :func:`~wavepaths.search.trace.trace` does.
    """
    from .trace import check_positions

    options = check_trace_arguments(scene, options)
    tx = check_positions("tx", tx)
    max_order = options.max_reflections
    if options.diffraction:
        max_order = max(max_order, options.diffraction_reflections)
    stats: dict = {}
    levels = build_image_levels(scene, tx, max_order, options.skip_absorbers, stats,
                                None if options.compiled else False,
                                visibility_group=0 if "mirror_visibility" in options.disable_culling else 1)
    stats.update({f"images_order_{k}": len(lv) for k, lv in enumerate(levels)})
    # beam trees of the reflection orders, for the per-tile culling of (receiver, chain) pairs
    apertures = scene_apertures(scene) if max_order >= 1 else None
    # (built on first use: a query of scattered receivers never needs them)
    beams: list[LazyChainBeams | None] = [None] + [
        LazyChainBeams() if len(levels[k]) else None for k in range(1, options.max_reflections + 1)
    ]
    # a scene traced without diffraction never builds its dihedra
    diffracting = np.nonzero(scene.dihedra.diffracting)[0] if options.diffraction else np.zeros(0, np.int64)
    if not options.free_edges and len(diffracting):
        free = scene.dihedra.face_count[diffracting] == 1
        stats["dihedra_skipped_free_edges"] = int(free.sum())
        diffracting = diffracting[~free]
    stats["dihedra_diffracting"] = int(len(diffracting))
    sources: list[DiffractionSources] = []
    sectors = None
    stride = 1
    edges = None
    if options.diffraction and len(diffracting):
        dihedra = scene.dihedra
        sectors = sector_table(dihedra)
        stride = int(sectors.angles.shape[1]) + 1
        edges = edge_tree(scene, diffracting)
        for a in range(options.diffraction_reflections + 1):
            lv = levels[a]
            tested = 0
            kept_c, kept_d, kept_s, kept_lo, kept_hi = [], [], [], [], []
            cull = "source_beam" not in options.disable_culling
            windows = a >= 1 and "aperture_window" not in options.disable_culling
            culled_aperture = 0
            last_mirror = lv.polygons[:, -1] if windows else None
            previous = lv.polygons[:, -2] if windows and a >= 2 else None
            # block by block, each block's survivors of every test kept before the next block:
            # the pairs that meet the beams can outnumber the survivors by far (munich, order 2:
            # 68.7 M pairs would not fit in memory at once)
            for c, d in _source_pairs(scene, lv, diffracting, edges, apertures, cull, options.compiled):
                tested += len(c)
                keep, sec = _diffracting_side(scene, sectors, lv, c, d, options.compiled)
                c, d = c[keep], d[keep]
                if windows:
                    # the incident leg leaves the last mirror: only where it can cross that mirror
                    lo, hi = chain_aperture_windows(scene, lv.last, last_mirror, c, d,
                                                    None if options.compiled else False, previous)
                    reach = lo <= hi
                    culled_aperture += int((~reach).sum())
                    c, d, sec = c[reach], d[reach], sec[reach]
                    kept_lo.append(lo[reach])
                    kept_hi.append(hi[reach])
                kept_c.append(c)
                kept_d.append(d)
                kept_s.append(sec)
            c, d, sec = (np.concatenate(x) if x else np.zeros(0, np.int64) for x in (kept_c, kept_d, kept_s))
            stats[f"diffraction_sources_order_{a}_considered"] = len(lv) * len(diffracting)
            stats[f"diffraction_sources_order_{a}_culled_beam"] = len(lv) * len(diffracting) - tested
            vis = None
            if a == 0 and "source_visibility" not in options.disable_culling:
                # the transmitters see part of each edge: pairs hidden along the whole edge go
                vis = visibility_windows(scene, lv.last[c], d, compiled=None if options.compiled else False)
                seen = ~vis.hidden
                stats["diffraction_sources_order_0_culled_hidden"] = int((~seen).sum())
                stats["visibility_rays"] = vis.rays
                c, d, sec, vis = c[seen], d[seen], sec[seen], vis.take(np.nonzero(seen)[0])
            elif windows:
                stats[f"diffraction_sources_order_{a}_culled_aperture"] = culled_aperture
                lo, hi = (np.concatenate(x) if x else np.zeros(0) for x in (kept_lo, kept_hi))
                if "source_visibility" in options.disable_culling:
                    none = np.zeros(len(c), dtype=bool)
                    vis = VisibilityWindows(lo, hi, none, none, scene.length_tolerance(1e-9), 0, 0)
                else:
                    # the leg from the last mirror to the edge: the part of each aperture window
                    # not proven hidden beyond the mirror; pairs hidden along all of it go
                    vis = _windows_in_blocks(scene, lv, c, d, lo, hi, None if options.compiled else False)
                    seen = ~vis.hidden
                    stats[f"diffraction_sources_order_{a}_culled_hidden"] = int((~seen).sum())
                    stats["visibility_rays"] = stats.get("visibility_rays", 0) + vis.rays
                    c, d, sec, vis = c[seen], d[seen], sec[seen], vis.take(np.nonzero(seen)[0])
            stats[f"diffraction_sources_order_{a}_kept"] = int(len(c))
            key = d * stride + sec
            o = np.lexsort((c, key))
            c, d, key = c[o], d[o], key[o]
            uk, start, count = _group(key)
            sources.append(DiffractionSources(c, d, key, uk, start, count, None if vis is None else vis.take(o)))
    # the receiver side of a diffracted path whose sources are of order a needs only the edges
    # those sources reach (on munich, 5,123 of 36,329 at order 0): a tree over them each
    source_edges = [edge_tree(scene, np.unique(src.dihedron)) if len(src.dihedron) else None for src in sources] \
        if edges is not None else []
    return TxContext(tx, options, levels, sectors, diffracting, sources, stride, stats, beams, apertures,
                     source_edges, scene_fingerprint=scene.fingerprint)
