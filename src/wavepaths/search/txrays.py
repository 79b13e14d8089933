"""Launched reflection candidates: the transmitter's rays (``reflection_candidates="launched"``).

A Fibonacci lattice of rays from the transmitter is traced through ``max_reflections``
specular reflections, once per context for the box of the query points
(:func:`ray_segments`); each segment after ``k`` reflections carries its mirror chain to the
points within its tube (:func:`reflection_candidates_launched`), and the exhaustive search's
:func:`~wavepaths.search.tile.reflection_tile` solves those (point, chain) pairs exactly.
The Keller fans of the diffracted candidates are in :mod:`wavepaths.search.launch`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..errors import WavepathsError
from .launch import LaunchOptions
from .rays import fibonacci_directions, first_hits, first_hits_past, reflect_and_branch
from .tubes import BoxSegments, PointGrid, reaches_box, tube_pairs, unique_rows

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene
    from .context import TxContext


def chain_rows(polygons: np.ndarray, query: np.ndarray) -> np.ndarray:
    """(q,) int64: the row of ``polygons`` (c, k) equal to each row of ``query`` (q, k), -1 if none."""
    c, k = polygons.shape
    if len(query) == 0 or c == 0:
        return np.full(len(query), -1, np.int64)
    if k == 0:
        return np.zeros(len(query), np.int64)
    both = unique_rows(np.ascontiguousarray(polygons, dtype=np.int64))
    if len(both) != c:  # one chain per row (a single source): otherwise not a lookup
        raise WavepathsError("chain_rows needs distinct chains (one transmitter per context)")
    rec = np.dtype((np.void, 8 * k))
    table = np.ascontiguousarray(polygons, dtype=np.int64).view(rec).ravel()
    order = np.argsort(table)
    q = np.ascontiguousarray(query, dtype=np.int64).view(rec).ravel()
    pos = np.minimum(np.searchsorted(table[order], q), c - 1)
    found = table[order][pos] == q
    return np.where(found, order[pos], -1)


@dataclass(frozen=True)
class RaySegments(BoxSegments):
    """The segments of the transmitter's launched rays whose tubes reach a box of query
    points (:class:`~wavepaths.search.tubes.BoxSegments`; round tubes, radius ``r0`` to
    ``r1``), over ``n`` segments.

    Attributes
    ----------
    order : (n,) int64
        Reflections before the segment (``k >= 1``).
    chain : (n,) int64
        Row of its mirror chain in ``ctx.levels[order]``.
    """

    order: np.ndarray
    chain: np.ndarray


def ray_segments(scene: "Scene", ctx: "TxContext", rays: int, lo: np.ndarray, hi: np.ndarray,
                 options: LaunchOptions = LaunchOptions()) -> RaySegments:
    """Trace ``rays`` directions from the transmitter (:func:`fibonacci_directions`) through
    ``max_reflections`` specular reflections, and keep the segments after ``k >= 1``
    reflections whose tubes (``radius_factor`` times the rays' angular spacing
    ``sqrt(4 pi / rays)`` times the unfolded distance from the transmitter) may reach the
    box ``[lo, hi]``. Chains the context's image tree does not hold (proven hidden) are
    dropped: the exhaustive search would not test them."""
    lo = np.asarray(lo, dtype=np.float64).reshape(3)
    hi = np.asarray(hi, dtype=np.float64).reshape(3)
    centre = 0.5 * (lo + hi)
    K = ctx.options.max_reflections
    if len(ctx.tx) != 1:
        raise WavepathsError("launched candidates take one transmitter per context")
    far = 2.0 * scene.diagonal
    eps = 1e-6 * scene.diagonal
    grow = options.radius_factor * np.sqrt(4.0 * np.pi / rays)
    parts: list[tuple] = []
    directions = fibonacci_directions(rays)
    for s0 in range(0, rays, options.fan_rays):
        u = directions[s0:s0 + options.fan_rays]
        origin = np.repeat(ctx.tx, len(u), axis=0)
        travelled = np.zeros(len(u))
        chain = np.zeros((len(u), 0), np.int64)
        for k in range(K + 1):
            if k == 0:
                poly, dist = first_hits(scene, origin, u, far, eps)
            else:
                poly, dist = first_hits_past(scene, origin, u, far, eps, chain[:, -1:])
            if k >= 1:
                end = origin + dist[:, None] * u
                r0, r1 = grow * travelled, grow * (travelled + dist)
                keep = np.nonzero(reaches_box(origin, end, r0, r1, lo, hi))[0]
                row = chain_rows(ctx.levels[k].polygons, chain[keep]) if len(keep) else np.zeros(0, np.int64)
                keep, row = keep[row >= 0], row[row >= 0]
                parts.append((origin[keep] - centre, end[keep] - centre, r0[keep], r1[keep],
                              np.full(len(keep), k, np.int64), row))
            hit = poly >= 0
            if k == K or not hit.any():
                break
            sel, mirror, origin, u, travelled = reflect_and_branch(scene, origin, u, poly, dist, travelled,
                                                                   0.0, grow, options.radius_factor)
            chain = np.column_stack([chain[sel], mirror])
    if parts:
        cols = [np.concatenate(c) for c in zip(*parts)]
    else:
        cols = [np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0), np.zeros(0, np.int64),
                np.zeros(0, np.int64)]
    f32 = np.float32
    return RaySegments(centre, lo, hi, cols[0].astype(f32), cols[1].astype(f32), cols[2].astype(f32),
                       cols[3].astype(f32), cols[4], cols[5])


def reflection_candidates_launched(scene: "Scene", ctx: "TxContext", points: np.ndarray, rays: int,
                                   options: LaunchOptions = LaunchOptions(),
                                   segments: RaySegments | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per reflection order ``k`` (index ``k - 1``), the (point, chain row of ``ctx.levels[k]``)
    pairs that launched transmitter rays carry to ``points``: each segment of
    :func:`ray_segments` (traced for the points' own box when ``segments`` is not given)
    gives its mirror chain to the points within its tube."""
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    K = ctx.options.max_reflections
    out = [(np.zeros(0, np.int64), np.zeros(0, np.int64)) for _ in range(K)]
    if K == 0 or len(points) == 0:
        return out
    if segments is None:
        segments = ray_segments(scene, ctx, rays, points.min(axis=0), points.max(axis=0), options)
    elif not segments.covers(points):
        raise WavepathsError("the ray segments were kept for a box that does not hold every query point")
    from . import kernels

    local = points - segments.centre
    grid = PointGrid(local) if kernels.available() else None
    seg, pt = tube_pairs(segments.start, segments.end, segments.r0, segments.r1, local, grid)
    for k in range(1, K + 1):
        sel = segments.order[seg] == k
        if sel.any():
            rows = unique_rows(np.column_stack([pt[sel], segments.chain[seg[sel]]]))
            out[k - 1] = (rows[:, 0], rows[:, 1])
    return out
