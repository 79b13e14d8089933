"""Transmitter-side work, done once and shared by every receiver tile.

A :class:`TxContext` holds, for a set of transmitters:

* the image tree up to the highest reflection order any path type needs;
* for diffraction, every (image source, dihedron) pair whose source lies in a
  diffracting sector of the dihedron (wider than pi). Whether a source can start a
  diffracted path from an edge does not depend on the receiver nor on where on the
  edge the path lands, so the other pairs are dropped here, once.

The context is all a coverage tile needs besides the scene; it is what a Dask worker
receives once (see :mod:`wavepaths.coverage`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..topology.sectors import SectorTable, sector_of, sector_table
from .images import ImageLevel, build_image_levels
from .options import TraceOptions

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
    """

    chain: np.ndarray
    dihedron: np.ndarray
    key: np.ndarray
    unique_keys: np.ndarray
    key_start: np.ndarray
    key_count: np.ndarray


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


def _group(keys: np.ndarray):
    uk, start, count = np.unique(keys, return_index=True, return_counts=True)
    return uk, start.astype(np.int64), count.astype(np.int64)


def build_tx_context(scene: "Scene", tx: np.ndarray, options: TraceOptions) -> TxContext:
    """Build the :class:`TxContext` of transmitters ``tx`` (m, 3) for ``options``."""
    tx = np.asarray(tx, dtype=np.float64).reshape(-1, 3)
    max_order = options.max_reflections
    if options.diffraction:
        max_order = max(max_order, options.diffraction_reflections)
    levels = build_image_levels(scene, tx, max_order, options.skip_absorbers)
    stats = {f"images_order_{k}": len(lv) for k, lv in enumerate(levels)}
    # a scene traced without diffraction never builds its dihedra
    diffracting = np.nonzero(scene.dihedra.diffracting)[0] if options.diffraction else np.zeros(0, np.int64)
    stats["dihedra_diffracting"] = int(len(diffracting))
    sources: list[DiffractionSources] = []
    sectors = None
    stride = 1
    if options.diffraction and len(diffracting):
        dihedra = scene.dihedra
        sectors = sector_table(dihedra)
        stride = int(sectors.angles.shape[1]) + 1
        for a in range(options.diffraction_reflections + 1):
            lv = levels[a]
            c = np.repeat(np.arange(len(lv)), len(diffracting))
            d = np.tile(diffracting, len(lv))
            sec, width = sector_of(sectors, d, lv.last[c], dihedra.origin[d])
            keep = (sec >= 0) & (width > np.pi + scene.tolerances.coplanar_angle)
            stats[f"diffraction_sources_order_{a}_considered"] = int(len(c))
            stats[f"diffraction_sources_order_{a}_kept"] = int(keep.sum())
            c, d, sec = c[keep], d[keep], sec[keep]
            key = d * stride + sec
            o = np.argsort(key, kind="stable")
            c, d, key = c[o], d[o], key[o]
            uk, start, count = _group(key)
            sources.append(DiffractionSources(c, d, key, uk, start, count))
    return TxContext(tx, options, levels, sectors, diffracting, sources, stride, stats)
