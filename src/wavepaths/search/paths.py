"""Paths: the geometry of every propagation path found, as a struct of arrays.

Inside the engine paths stay flat (one row per path, padded only to the deepest
path). :meth:`Paths.padded` turns them into the (tx, rx, path) form; :meth:`Paths.records`
into plain dictionaries for tables and JSON.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from ..em.constants import SPEED_OF_LIGHT  # noqa: F401 (re-exported)

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene


class InteractionType(enum.IntEnum):
    """What happens at a path vertex. Line-of-sight paths have no interaction."""

    NONE = 0
    REFLECTION = 1
    DIFFRACTION = 2


INTERACTION_NAMES = {InteractionType.REFLECTION: "reflection", InteractionType.DIFFRACTION: "diffraction"}


_ARRAY_FIELDS = ("tx_positions", "rx_positions", "tx_index", "rx_index", "depth", "interactions", "primitive",
                 "triangle", "wedge_faces", "vertices")


@dataclass(frozen=True, eq=False)
class Paths:
    """Every path found between ``m`` transmitters and ``n`` receivers (flat, ``N`` paths).

    Attributes
    ----------
    tx_positions : (m, 3) float64 [m]
    rx_positions : (n, 3) float64 [m]
    tx_index, rx_index : (N,) int64
        Transmitter and receiver of each path.
    depth : (N,) int64
        Number of interactions (0 for line of sight).
    interactions : (N, D) int8
        :class:`InteractionType` of each interaction in path order, ``NONE`` past ``depth``.
    primitive : (N, D) int64
        Polygon index for a reflection, dihedron index for a diffraction, -1 past ``depth``.
    triangle : (N, D) int64
        For a reflection, a triangle of its polygon (object and material); for a
        diffraction, the triangle of the 0-face; -1 past ``depth``.
    wedge_faces : (N, 2) int64
        For the (single) diffraction of a path: indices into the dihedra's face arrays
        of the 0-face and the n-face found by FindDihedron; -1 for paths without one.
    vertices : (N, D + 2, 3) float64
        Transmitter, interaction points, receiver [m]. Past ``depth + 1`` the receiver
        position repeats, so segments there have zero length.
    stats : dict
        Per-stage counters: candidates considered, rejected by each test, rays cast.
    scene_fingerprint : str
        :attr:`wavepaths.scene.Scene.geometry_fingerprint` of the scene they were traced in
        (set by :func:`wavepaths.trace`; empty for paths built otherwise): the fields refuse
        them with another scene, and take them with other materials on the same geometry.

    The arrays are results, held read-only: the derived ``segment_lengths``, ``lengths`` and
    the departure and arrival directions are computed once from ``vertices`` and kept.
    """

    tx_positions: np.ndarray
    rx_positions: np.ndarray
    tx_index: np.ndarray
    rx_index: np.ndarray
    depth: np.ndarray
    interactions: np.ndarray
    primitive: np.ndarray
    triangle: np.ndarray
    wedge_faces: np.ndarray
    vertices: np.ndarray
    stats: dict = field(default_factory=dict)
    scene_fingerprint: str = ""

    def __post_init__(self) -> None:
        # results are read-only (a changed vertex would leave the cached lengths stale): each
        # array is held as a read-only view, so the caller's own arrays keep their flags
        for name in _ARRAY_FIELDS:
            a = getattr(self, name)
            if isinstance(a, np.ndarray) and a.flags.writeable:
                v = a.view()
                v.flags.writeable = False
                object.__setattr__(self, name, v)

    def __len__(self) -> int:
        return len(self.tx_index)

    # ---- derived geometry ----------------------------------------------------------
    @property
    def max_depth(self) -> int:
        return self.interactions.shape[1]

    @property
    def segment_lengths(self) -> np.ndarray:
        """(N, D + 1) float64: length of each segment [m] (0 past the path's end).

        Computed once per :class:`Paths` (the search, the sort and the field chain all read
        it) and returned read-only: copy it to change it."""
        out = self.__dict__.get("_segment_lengths")
        if out is None:
            d = np.diff(self.vertices, axis=1)
            out = np.sqrt(np.einsum("nsj,nsj->ns", d, d))
            out.flags.writeable = False
            # kept beside the fields (frozen: not through setattr); two threads that both miss
            # compute the same array, without a lock
            self.__dict__["_segment_lengths"] = out
        return out

    @property
    def lengths(self) -> np.ndarray:
        """(N,) float64: total path length [m] (computed once, read-only)."""
        out = self.__dict__.get("_lengths")
        if out is None:
            out = self.segment_lengths.sum(axis=1)
            out.flags.writeable = False
            self.__dict__["_lengths"] = out
        return out

    def __getstate__(self) -> dict:
        # the derived lengths are not pickled: recomputed, read-only, after unpickling
        return {k: v for k, v in self.__dict__.items()
                if k not in ("_segment_lengths", "_lengths", "_departure", "_arrival")}

    @property
    def delays(self) -> np.ndarray:
        """(N,) float64: propagation delay [s]."""
        return self.lengths / SPEED_OF_LIGHT

    @property
    def departure_directions(self) -> np.ndarray:
        """(N, 3) float64: unit vector leaving the transmitter (computed once, read-only)."""
        out = self.__dict__.get("_departure")
        if out is None:
            d = self.vertices[:, 1] - self.vertices[:, 0]
            out = d / self.segment_lengths[:, :1]  # the first segment's length, as kept
            out.flags.writeable = False
            self.__dict__["_departure"] = out
        return out

    @property
    def arrival_directions(self) -> np.ndarray:
        """(N, 3) float64: unit propagation direction arriving at the receiver (computed once,
        read-only)."""
        out = self.__dict__.get("_arrival")
        if out is None:
            rows = np.arange(len(self))
            last = self.vertices[rows, self.depth + 1] - self.vertices[rows, self.depth]
            out = last / self.segment_lengths[rows, self.depth][:, None]
            out.flags.writeable = False
            self.__dict__["_arrival"] = out
        return out

    @staticmethod
    def _zenith_azimuth(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        # azimuth in (-pi, pi]: a -0.0 y component (a wave along -x negated) gives +pi, not -pi
        return np.arccos(np.clip(d[:, 2], -1, 1)), np.arctan2(d[:, 1] + 0.0, d[:, 0])

    @property
    def angles_of_departure(self) -> tuple[np.ndarray, np.ndarray]:
        """Zenith and azimuth [rad] of the departure direction, each (N,)."""
        return self._zenith_azimuth(self.departure_directions)

    @property
    def angles_of_arrival(self) -> tuple[np.ndarray, np.ndarray]:
        """Zenith and azimuth [rad] of the direction the wave comes from, seen at the receiver, each (N,)."""
        return self._zenith_azimuth(-self.arrival_directions)

    def objects(self, scene: "Scene") -> np.ndarray:
        """(N, D) int64: object id of each interaction (-1 past the end)."""
        out = np.full(self.triangle.shape, -1, dtype=np.int64)
        m = self.triangle >= 0
        out[m] = scene.triangle_object[self.triangle[m]]
        return out

    def kind_names(self) -> list[list[str]]:
        """Interaction names of each path, e.g. ``["reflection", "diffraction"]``."""
        return [[INTERACTION_NAMES[InteractionType(t)] for t in row[:d]] for row, d in zip(self.interactions, self.depth)]

    def select(self, mask: np.ndarray) -> "Paths":
        """The paths where ``mask`` (N,) is true."""
        return Paths(
            self.tx_positions,
            self.rx_positions,
            self.tx_index[mask],
            self.rx_index[mask],
            self.depth[mask],
            self.interactions[mask],
            self.primitive[mask],
            self.triangle[mask],
            self.wedge_faces[mask],
            self.vertices[mask],
            dict(self.stats),
            self.scene_fingerprint,
        )

    # ---- public forms ---------------------------------------------------------------
    def padded(self) -> dict[str, np.ndarray]:
        """The (tx, rx, path) form, like Sionna RT's ``Paths``.

        Returns
        -------
        dict with
            ``valid`` (m, n, P) bool; ``vertices`` (m, n, P, D + 2, 3); ``interactions``,
            ``primitive`` (m, n, P, D); ``lengths``, ``delays`` (m, n, P); ``depth``
            (m, n, P). ``P`` is the largest number of paths of any (tx, rx) pair.
        """
        m, n = len(self.tx_positions), len(self.rx_positions)
        pair = self.tx_index * n + self.rx_index
        order = np.argsort(pair, kind="stable")
        counts = np.bincount(pair, minlength=m * n)
        p = int(counts.max()) if len(counts) and len(self) else 0
        slot = np.empty(len(self), dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        slot[order] = np.arange(len(self)) - np.repeat(starts, counts)
        d = self.max_depth
        out = {
            "valid": np.zeros((m, n, p), bool),
            "vertices": np.zeros((m, n, p, d + 2, 3)),
            "interactions": np.zeros((m, n, p, d), np.int8),
            "primitive": np.full((m, n, p, d), -1, np.int64),
            "lengths": np.zeros((m, n, p)),
            "delays": np.zeros((m, n, p)),
            "depth": np.zeros((m, n, p), np.int64),
        }
        ti, ri = self.tx_index, self.rx_index
        out["valid"][ti, ri, slot] = True
        out["vertices"][ti, ri, slot] = self.vertices
        out["interactions"][ti, ri, slot] = self.interactions
        out["primitive"][ti, ri, slot] = self.primitive
        out["lengths"][ti, ri, slot] = self.lengths
        out["delays"][ti, ri, slot] = self.delays
        out["depth"][ti, ri, slot] = self.depth
        return out

    def records(self) -> list[dict]:
        """One plain dictionary per path: ``tx``, ``rx``, ``interactions``, ``vertices``,
        ``length_m``, ``delay_s``, ``primitives``."""
        names = self.kind_names()
        lengths, delays = self.lengths, self.delays
        out = []
        for i in range(len(self)):
            d = int(self.depth[i])
            out.append(
                {
                    "tx": int(self.tx_index[i]),
                    "rx": int(self.rx_index[i]),
                    "interactions": names[i],
                    "primitives": self.primitive[i, :d].tolist(),
                    "vertices": self.vertices[i, : d + 2].tolist(),
                    "length_m": float(lengths[i]),
                    "delay_s": float(delays[i]),
                }
            )
        return out


@dataclass
class PathBatch:
    """Paths of one family (same depth), before padding. Internal."""

    tx_index: np.ndarray
    rx_index: np.ndarray
    interactions: np.ndarray  # (k, d)
    primitive: np.ndarray  # (k, d)
    triangle: np.ndarray  # (k, d)
    wedge_faces: np.ndarray  # (k, 2)
    vertices: np.ndarray  # (k, d + 2, 3)


def path_order(tx_index: np.ndarray, rx_index: np.ndarray, depth: np.ndarray, lengths: np.ndarray,
               interactions: np.ndarray, primitive: np.ndarray, n_rx: int) -> np.ndarray:
    """(N,) int64: the canonical order of paths, by (tx, rx, depth, length), then by their
    interactions and primitives (equal lengths occur in symmetric scenes), so that it does
    not depend on the order in which the search found them.

    ``np.lexsort`` on one int64 key for (tx, rx, depth) and the lengths (compiled, when the
    keys are few against the paths: a counting sort on the key, then each key's paths by
    length, the same permutation); only where two paths tie on both is the whole key
    (interactions, primitives) sorted, which gives the same order as sorting it everywhere
    (a stable sort of a total order).
    """
    key = (tx_index.astype(np.int64) * max(n_rx, 1) + rx_index) * (interactions.shape[1] + 1) + depth
    n_keys = int(key.max()) + 1 if len(key) else 0
    # the counting sort indexes by key: only for keys in [0, n_keys) that are few against the paths
    few = len(key) == 0 or (n_keys <= 4 * len(key) + 4096 and int(key.min()) >= 0)
    compiled = _key_length_order() if few else None
    if compiled is not None and not np.isnan(lengths).any():
        # the same order, by a counting sort on the key (a coverage tile's keys are few)
        # a writable copy: Paths.lengths is read-only, which numba would compile apart
        order, tie = compiled(np.ascontiguousarray(key), np.array(lengths, dtype=np.float64), n_keys)
    else:
        order = np.lexsort((lengths, key))
        k, ln = key[order], lengths[order]
        tie = len(order) > 1 and bool(((k[1:] == k[:-1]) & (ln[1:] == ln[:-1])).any())
    if tie:
        order = np.lexsort((*primitive.T[::-1], *interactions.T[::-1], lengths, depth, rx_index, tx_index))
    return order


@lru_cache(maxsize=1)
def _key_length_order():
    """The compiled ``np.lexsort((lengths, key))`` (:func:`wavepaths.search._numba.key_length_order`),
    or ``None`` without numba."""
    try:
        from ._numba import key_length_order
    except ImportError:
        return None
    return key_length_order


def coincident_paths(tx_index: np.ndarray, rx_index: np.ndarray, depth: np.ndarray, interactions: np.ndarray,
                     lengths: np.ndarray, vertices: np.ndarray, order: np.ndarray, tol: float) -> np.ndarray:
    """(N,) bool: the paths that repeat another one, to drop.

    A reflection point on the common border of two coplanar polygons (a wall of two
    materials, two touching or stacked boxes) lies in both, and a diffraction point where
    two collinear dihedra meet (an edge whose faces change there) lies on both: the search
    finds the one geometrical path once per primitive. Two paths are the same when they
    join the same transmitter and receiver with the same interaction kinds and every vertex
    within ``tol`` [m] of the other's; the first in ``order`` (:func:`path_order`, where such
    paths are neighbours: same key, lengths within rounding) is kept.

    Parameters
    ----------
    tx_index, rx_index, depth : (N,) int64
    interactions : (N, D) int8
    lengths : (N,) float64 [m]
    vertices : (N, D + 2, 3) float64 [m]
        Padded with the receiver past each path's end.
    order : (N,) int64
        :func:`path_order` of these arrays.
    tol : float
        [m], the scene's weld tolerance.
    """
    drop = np.zeros(len(order), dtype=bool)
    if len(order) < 2:
        return drop
    a, b = order[:-1], order[1:]
    near = ((tx_index[a] == tx_index[b]) & (rx_index[a] == rx_index[b]) & (depth[a] == depth[b])
            & (np.abs(lengths[a] - lengths[b]) <= 2.0 * (depth[a] + 1) * tol))
    a, b = a[near], b[near]
    if len(a):
        same = np.all(interactions[a] == interactions[b], axis=1)
        same &= np.abs(vertices[a] - vertices[b]).max(axis=(1, 2)) <= tol
        drop[b[same]] = True
    return drop


def _pad_columns(a: np.ndarray, width: int, fill) -> np.ndarray:
    """``a`` (N, w, ...) widened to ``width`` columns with ``fill``."""
    extra = width - a.shape[1]
    if extra == 0:
        return a
    return np.concatenate([a, np.full((a.shape[0], extra) + a.shape[2:], fill, dtype=a.dtype)], axis=1)


def _pad_vertices(v: np.ndarray, width: int) -> np.ndarray:
    """Vertices ``v`` (N, w, 3) widened to ``width`` points by repeating the last (the receiver)."""
    extra = width - v.shape[1]
    return v if extra == 0 else np.concatenate([v, np.repeat(v[:, -1:], extra, axis=1)], axis=1)


def concatenate(first: Paths, second: Paths) -> Paths:
    """The paths of ``first`` then those of ``second`` (found for the same transmitters and
    receivers), padded to the deeper of the two as :func:`assemble` pads: ``NONE`` interactions,
    primitives and triangles -1, the receiver repeated in ``vertices``. Unsorted; the stats
    are ``first``'s."""
    d = max(first.interactions.shape[1], second.interactions.shape[1])
    return Paths(first.tx_positions, first.rx_positions,
                 np.concatenate([first.tx_index, second.tx_index]), np.concatenate([first.rx_index, second.rx_index]),
                 np.concatenate([first.depth, second.depth]),
                 np.concatenate([_pad_columns(p.interactions, d, 0) for p in (first, second)]).astype(np.int8),
                 np.concatenate([_pad_columns(p.primitive, d, -1) for p in (first, second)]),
                 np.concatenate([_pad_columns(p.triangle, d, -1) for p in (first, second)]),
                 np.concatenate([first.wedge_faces, second.wedge_faces]),
                 np.concatenate([_pad_vertices(p.vertices, d + 2) for p in (first, second)]), dict(first.stats),
                 first.scene_fingerprint if first.scene_fingerprint == second.scene_fingerprint else "")


def assemble(tx: np.ndarray, rx: np.ndarray, batches: list[PathBatch], stats: dict, sort: bool = True,
             merge_tol: float | None = None) -> Paths:
    """Concatenate path batches of different depths into one padded :class:`Paths`.

    ``sort``: in the order of :func:`path_order`, deterministic and independent of the
    batches' order. Without it the paths come batch after batch, and ``path_order(...)``
    of their arrays gives that order (a coverage tile sorts only its per-path values).
    ``merge_tol`` [m]: with ``sort``, paths repeating another within it are dropped
    (:func:`coincident_paths`) and counted in ``stats["paths_dropped_coincident"]``.
    """
    batches = [b for b in batches if len(b.tx_index)]
    dmax = max([b.interactions.shape[1] for b in batches], default=0)
    if not batches:
        z = np.zeros(0, np.int64)
        return Paths(tx, rx, z, z, z, np.zeros((0, dmax), np.int8), np.zeros((0, dmax), np.int64),
                     np.zeros((0, dmax), np.int64), np.zeros((0, 2), np.int64), np.zeros((0, dmax + 2, 3)), stats)

    verts = [_pad_vertices(b.vertices, dmax + 2) for b in batches]
    depth = np.concatenate([np.full(len(b.tx_index), b.interactions.shape[1]) for b in batches])
    txi = np.concatenate([b.tx_index for b in batches])
    rxi = np.concatenate([b.rx_index for b in batches])
    vertices = np.concatenate(verts)
    kinds = np.concatenate([_pad_columns(b.interactions, dmax, 0) for b in batches]).astype(np.int8)
    prims = np.concatenate([_pad_columns(b.primitive, dmax, -1) for b in batches])
    tri = np.concatenate([_pad_columns(b.triangle, dmax, -1) for b in batches])
    wedge = np.concatenate([b.wedge_faces for b in batches])
    if sort:
        d = np.diff(vertices, axis=1)
        lengths = np.sqrt(np.einsum("nsj,nsj->ns", d, d)).sum(axis=1)
        order = path_order(txi, rxi, depth, lengths, kinds, prims, len(rx))
        if merge_tol is not None:
            drop = coincident_paths(txi, rxi, depth, kinds, lengths, vertices, order, merge_tol)
            if drop.any():
                stats["paths_dropped_coincident"] = stats.get("paths_dropped_coincident", 0) + int(drop.sum())
                order = order[~drop[order]]
        txi, rxi, depth, kinds, prims, tri, wedge, vertices = (a[order] for a in (txi, rxi, depth, kinds, prims, tri,
                                                                                  wedge, vertices))
    return Paths(tx_positions=tx, rx_positions=rx, tx_index=txi, rx_index=rxi, depth=depth, interactions=kinds,
                 primitive=prims, triangle=tri, wedge_faces=wedge, vertices=vertices, stats=stats)
