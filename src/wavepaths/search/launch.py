"""Launched candidates: the diffracted sequences that Keller fans from sampled edge points carry.

The exhaustive search (:mod:`wavepaths.search.diffraction`) enumerates every (source image,
edge, receiver image) triple that no conservative test rules out. In a dense city most of
them are occluded: munich at two reflections around the edge keeps some 400,000 candidates
per receiver for about 15 paths. This module finds candidates in proportion to the paths
instead, by sampling, in two steps:

1. **Edge samples** (:func:`edge_samples`). For each order ``a`` of reflections before the
   edge, the context's (source image, dihedron) pairs and their windows (the parts of each
   edge that the transmitter, or its image through the last mirror, may reach;
   :class:`~wavepaths.search.context.DiffractionSources`) are sampled along the edge, every
   ``max(spacing, angular * distance to the image)`` metres. Each sample is back-traced
   through its mirrors (:func:`~wavepaths.search.images.backtrace`: every reflection point
   inside its polygon) and its legs are cast; a sample is kept when it, or a neighbour on
   the same window, is lit (so a lit stretch shorter than the spacing still starts a fan).
   No transmitter rays are launched: the sources and windows are the exact engine's, so no
   edge is missed for being seen at a grazing angle.
2. **Keller fans** (:func:`candidate_sequences`). From every kept sample, ``fan`` rays on
   the Keller cone of the incident direction (seed §2.1: ``v . w = u . w``), in the
   wedge's exterior, are traced through up to ``D - a`` specular reflections (first hits
   from the ray caster, reflected in float64). Every segment carries the sequence
   (mirrors before, dihedron, mirrors after so far) to the query points within its tube:
   a radius that grows from the sample spacing by the fan's and the samples' angular
   spacing, times ``radius_factor``.

What comes out is a set of *candidate sequences* per point, not paths: each must still be
solved exactly (closed-form diffraction point between the two unfolded ends, back-traces,
casts) by the exact engine. The sampling can miss a sequence (a mirror smaller than the
fan's spacing at its distance); how often is measured against the exhaustive search, on
the street canyon by ``tests/search/test_launch.py`` and on munich by
``benchmarks/launch_completeness.py``.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import TYPE_CHECKING, Iterator

import numpy as np

from ..errors import WavepathsError
from .chains import occluded_chains
from .images import backtrace
from .rays import fibonacci_directions, first_hits, first_hits_past, reflect_and_branch
from .tubes import PointGrid, tube_pairs, unique_rows

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene
    from .context import TxContext


@dataclass(frozen=True)
class LaunchOptions:
    """How densely the edges and the Keller cones are sampled.

    Attributes
    ----------
    fan : int
        Directions per full turn of a Keller cone (only those in the wedge's exterior are traced).
    spacing : float
        Smallest spacing of the samples along an edge [m].
    angular : float
        Spacing of the samples along an edge as seen from their source image [rad]:
        a sample every ``max(spacing, angular * distance)`` metres.
    radius_factor : float
        Tube radius over the sampling spacing (1 would just close the gaps of a regular grid).
    fan_rays : int
        Fan rays traced at once (bounds the working memory, about 200 B per ray).
    """

    fan: int = 256
    spacing: float = 0.25
    angular: float = 2.5e-3
    radius_factor: float = 2.0
    fan_rays: int = 1 << 21

    def __post_init__(self) -> None:
        if self.fan < 4:
            raise WavepathsError(f"LaunchOptions.fan must be at least 4 (got {self.fan})")
        if not (self.spacing > 0 and self.angular > 0 and self.radius_factor > 0):
            raise WavepathsError("LaunchOptions.spacing, angular and radius_factor must be positive")


@dataclass(frozen=True)
class EdgeSamples:
    """Lit points on the diffracting edges, struct of arrays over ``k`` samples.

    Attributes
    ----------
    order : (k,) int64
        Reflections before the edge (``a``).
    source : (k,) int64
        Row of the (source image, dihedron) pair in ``ctx.diffraction_sources[order]``.
    chain : (k, A) int64
        Mirrors before the edge in path order, ``-1`` past ``order``.
    dihedron : (k,) int64
    t : (k,) float64
        Position along the edge [m from its origin].
    incident : (k, 3) float64
        Unit direction of arrival (from the source's image to the point).
    spacing : (k,) float64
        Spacing of the samples on this window [m].
    angular : (k,) float64
        That spacing seen from the source image [rad].
    """

    order: np.ndarray
    source: np.ndarray
    chain: np.ndarray
    dihedron: np.ndarray
    t: np.ndarray
    incident: np.ndarray
    spacing: np.ndarray
    angular: np.ndarray

    def __len__(self) -> int:
        return len(self.order)


@dataclass(frozen=True)
class CandidateSequences:
    """Diffracted sequences that reach query points, struct of arrays over ``s`` rows.

    Attributes
    ----------
    point : (s,) int64
        Row of the query points.
    order : (s,) int64
        Reflections before the edge (``a``).
    source : (s,) int64
        Row of the (source image, dihedron) pair in ``ctx.diffraction_sources[order]``.
    before : (s, D) int64
        Mirrors before the edge in path order, ``-1`` padded.
    dihedron : (s,) int64
    after : (s, D) int64
        Mirrors after the edge in path order, ``-1`` padded.
    """

    point: np.ndarray
    order: np.ndarray
    source: np.ndarray
    before: np.ndarray
    dihedron: np.ndarray
    after: np.ndarray

    def __len__(self) -> int:
        return len(self.point)

    def keys(self) -> set[tuple]:
        """``{(point, (mirrors before..., dihedron), (mirrors after...))}``, for comparisons."""
        out = set()
        for p, bf, d, af in zip(self.point.tolist(), self.before.tolist(), self.dihedron.tolist(), self.after.tolist()):
            out.add((p, tuple(x for x in bf if x >= 0) + (d,), tuple(x for x in af if x >= 0)))
        return out


def _windows(scene: "Scene", src) -> tuple[np.ndarray, np.ndarray]:
    """The ``[lo, hi]`` part of each pair's edge to sample [m]: its window, the whole edge without one."""
    L = scene.dihedra.length[src.dihedron]
    v = src.visible
    if v is None:
        return np.zeros_like(L), L
    lo = np.where(v.open0, 0.0, np.clip(v.lo, 0.0, L))
    hi = np.where(v.open1, L, np.clip(v.hi, 0.0, L))
    return lo, np.maximum(hi, lo)


def edge_samples(scene: "Scene", ctx: "TxContext", options: LaunchOptions = LaunchOptions()) -> EdgeSamples:
    """Lit sample points on the edges of every source order of ``ctx`` (step 1 of the module).

    Parameters
    ----------
    scene : Scene
    ctx : TxContext
        Built with diffraction (its ``diffraction_sources``; one transmitter).
    options : LaunchOptions

    Returns
    -------
    EdgeSamples
    """
    A = max(len(ctx.diffraction_sources) - 1, 0)
    parts = []
    for a, src in enumerate(ctx.diffraction_sources):
        lv = ctx.levels[a]
        lo_all, hi_all = _windows(scene, src)
        # in chunks of pairs: munich's 11 M order-2 pairs hold some 50 M samples
        for p0 in range(0, len(src.dihedron), SAMPLE_PAIR_CHUNK):
            pr = np.arange(p0, min(len(src.dihedron), p0 + SAMPLE_PAIR_CHUNK))
            parts.append(_window_samples(scene, ctx, a, lv, src, pr, lo_all[pr], hi_all[pr], A, options))
    if not parts:
        z = np.zeros(0, np.int64)
        return EdgeSamples(z, z, np.zeros((0, A), np.int64), z, np.zeros(0), np.zeros((0, 3)), np.zeros(0), np.zeros(0))
    return EdgeSamples(*(np.concatenate(c) for c in zip(*parts)))


SAMPLE_PAIR_CHUNK = 1 << 18
"""(source, dihedron) pairs sampled at once (a few samples each: bounds the temporaries)."""


def _window_samples(scene: "Scene", ctx: "TxContext", a: int, lv, src, pr: np.ndarray, lo: np.ndarray,
                    hi: np.ndarray, A: int, options: LaunchOptions) -> tuple:
    """The kept samples of the pairs ``pr`` of ``src`` (order ``a``; see :func:`edge_samples`)."""
    D = scene.dihedra
    d = src.dihedron[pr]
    image = lv.images[src.chain[pr], -1]
    mid = D.origin[d] + (0.5 * (lo + hi))[:, None] * D.direction[d]
    dist = np.linalg.norm(mid - image, axis=1)
    spacing = np.maximum(options.spacing, options.angular * dist)
    count = np.ceil((hi - lo) / spacing).astype(np.int64) + 1
    row = np.repeat(np.arange(len(d)), count)
    j = np.arange(len(row)) - np.repeat(np.cumsum(count) - count, count)
    frac = np.where(count[row] > 1, j / np.maximum(count[row] - 1, 1), 0.5)
    t = lo[row] + (hi - lo)[row] * frac
    x = D.origin[d[row]] + t[:, None] * D.direction[d[row]]
    chain = src.chain[pr][row]
    lit = np.zeros(len(row), dtype=bool)
    if a == 0:
        verts = np.stack([image[row], x], axis=1)
        lit = ~occluded_chains(scene, verts, Counter())
    else:
        ok, pts, _ = backtrace(scene, x, lv, chain, compiled=ctx.options.compiled)
        if len(ok):
            verts = np.concatenate([lv.images[chain[ok], :1], pts, x[ok, None, :]], axis=1)
            lit[ok] = ~occluded_chains(scene, verts, Counter())
    # a sample also stands for its lit neighbours on the same window (a lit stretch
    # between two samples still starts a fan)
    same_prev = np.zeros(len(row), dtype=bool)
    same_prev[1:] = row[1:] == row[:-1]
    keep = lit.copy()
    keep[1:] |= lit[:-1] & same_prev[1:]
    keep[:-1] |= lit[1:] & same_prev[1:]
    k = np.nonzero(keep)[0]
    inc = x[k] - image[row[k]]
    length = np.linalg.norm(inc, axis=1)
    inc /= np.where(length > 0, length, 1.0)[:, None]
    pad = np.full((len(k), A), -1, np.int64)
    pad[:, :a] = lv.polygons[chain[k]]
    return (np.full(len(k), a, np.int64), pr[row[k]], pad, d[row[k]], t[k], inc, spacing[row[k]],
            spacing[row[k]] / np.maximum(length, 1e-9))


def __missing__(self, key):
        return 0


def keller_fan(scene: "Scene", dihedron: np.ndarray, t: np.ndarray, incident: np.ndarray, fan: int
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Directions on the Keller cone of each sample, in its wedge's exterior.

    With ``w`` the unit edge vector and ``u`` the incident direction, the diffracted
    directions are ``v = (u . w) w + sin(beta) (cos(phi) f0 + sin(phi) w x f0)``
    (seed §2.1, ``cos(beta) = u . w``), ``f0`` the first face's in-plane direction, for
    ``fan`` angles ``phi`` spaced evenly over a turn. For a wedge of two faces, the
    directions between the faces through the interior angle (below pi) are dropped.

    Returns
    -------
    point : (k, 3) float64
        The samples on their edges [m].
    direction : (k, fan, 3) float64
    exterior : (k, fan) bool
    sin_beta : (k,) float64
    """
    D = scene.dihedra
    w = D.direction[dihedron]
    point = D.origin[dihedron] + t[:, None] * w
    cb = np.einsum("ij,ij->i", incident, w)
    sb = np.sqrt(np.clip(1.0 - cb * cb, 0.0, 1.0))
    f0 = D.face_direction[D.face_ptr[dihedron]]
    g0 = np.cross(w, f0)
    phi = (np.arange(fan) + 0.5) * (2 * np.pi / fan)
    c, s = np.cos(phi), np.sin(phi)
    direction = (cb[:, None, None] * w[:, None, :]
                 + sb[:, None, None] * (c[None, :, None] * f0[:, None, :] + s[None, :, None] * g0[:, None, :]))
    two = (D.face_ptr[dihedron + 1] - D.face_ptr[dihedron]) == 2
    f1 = D.face_direction[np.minimum(D.face_ptr[dihedron] + 1, len(D.face_direction) - 1)]
    ang = np.mod(np.arctan2(np.einsum("ij,ij->i", f1, g0), np.einsum("ij,ij->i", f1, f0)), 2 * np.pi)
    lo = np.where(ang < np.pi, 0.0, ang)
    hi = np.where(ang < np.pi, ang, 2 * np.pi)
    interior = (phi[None, :] > lo[:, None]) & (phi[None, :] < hi[:, None]) & two[:, None]
    return point, direction, ~interior, sb


def _fan_chunks(samples: EdgeSamples, fan: int, fan_rays: int) -> Iterator[np.ndarray]:
    step = max(1, fan_rays // fan)
    for s0 in range(0, len(samples), step):
        yield np.arange(s0, min(len(samples), s0 + step))


def candidate_sequences(scene: "Scene", ctx: "TxContext", points: np.ndarray,
                        options: LaunchOptions = LaunchOptions(),
                        samples: EdgeSamples | None = None) -> CandidateSequences:
    """The diffracted sequences whose Keller fans pass near each of ``points`` (step 2).

    Parameters
    ----------
    scene : Scene
    ctx : TxContext
        Built with diffraction for one transmitter; ``ctx.options.diffraction_reflections``
        (``D``) bounds the reflections before plus after the edge.
    points : (p, 3) float64
        Query points (receivers) [m].
    options : LaunchOptions
    samples : EdgeSamples, optional
        From :func:`edge_samples` (computed when not given).

    Returns
    -------
    CandidateSequences
        Distinct rows (point, before, dihedron, after).
    """
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    if samples is None:
        samples = edge_samples(scene, ctx, options)
    Dmax = ctx.options.diffraction_reflections
    far = 2.0 * scene.diagonal
    eps = 1e-6 * scene.diagonal  # rays leave an edge or a mirror: skip the float32 re-hit of their own face
    dphi = 2 * np.pi / options.fan
    width = 4 + 2 * Dmax  # point, order, source, before (D), dihedron, after (D)
    from . import kernels

    grid = PointGrid(points) if kernels.available() else None
    found = []
    for rows in _fan_chunks(samples, options.fan, options.fan_rays):
        P, V, ext, sb = keller_fan(scene, samples.dihedron[rows], samples.t[rows], samples.incident[rows], options.fan)
        si, fi = np.nonzero(ext)
        origin, u = P[si], V[si, fi]
        sample = rows[si]
        # tube radius: the sample spacing, plus the fan's and the samples' angular spacing times the distance
        r_edge = options.radius_factor * samples.spacing[sample]
        grow = options.radius_factor * (sb[si] * dphi + samples.angular[sample])
        travelled = np.zeros(len(si))
        after = np.full((len(si), Dmax), -1, np.int64)
        D_ = scene.dihedra
        fp = D_.face_ptr[samples.dihedron[sample]]
        nf = D_.face_ptr[samples.dihedron[sample] + 1] - fp
        skip = np.stack([D_.face_polygon[fp], np.where(nf > 1, D_.face_polygon[np.minimum(fp + 1, len(D_.face_polygon) - 1)],
                                                        -1)], axis=1)
        for b in range(Dmax + 1):
            live = samples.order[sample] + b <= Dmax
            if not live.all():
                origin, u, sample, r_edge, grow, travelled, after, skip = (
                    x[live] for x in (origin, u, sample, r_edge, grow, travelled, after, skip))
            if len(origin) == 0:
                break
            poly, dist = first_hits_past(scene, origin, u, far, eps, skip)
            end = origin + dist[:, None] * u
            seg, pt = tube_pairs(origin, end, r_edge + grow * travelled, r_edge + grow * (travelled + dist), points, grid)
            if len(seg):
                s = sample[seg]
                row = np.empty((len(seg), width), np.int64)
                row[:, 0] = pt
                row[:, 1] = samples.order[s]
                row[:, 2] = samples.source[s]
                row[:, 3:3 + Dmax] = samples.chain[s][:, :Dmax] if samples.chain.shape[1] >= Dmax else np.pad(
                    samples.chain[s], ((0, 0), (0, Dmax - samples.chain.shape[1])), constant_values=-1)
                row[:, 3 + Dmax] = samples.dihedron[s]
                row[:, 4 + Dmax:] = after[seg]
                found.append(unique_rows(row))
            hit = poly >= 0
            if b == Dmax or not hit.any():
                break
            sel, mirror, origin, u, travelled = reflect_and_branch(scene, origin, u, poly, dist, travelled,
                                                                   r_edge, grow, options.radius_factor)
            sample, r_edge, grow = sample[sel], r_edge[sel], grow[sel]
            after = after[sel]
            after[:, b] = mirror
            skip = np.stack([mirror, np.full(len(mirror), -1)], axis=1)  # the mirror just left
    rows = unique_rows(np.concatenate(found)) if found else np.zeros((0, width), np.int64)
    return CandidateSequences(rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3:3 + Dmax], rows[:, 3 + Dmax],
                              rows[:, 4 + Dmax:])


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


def reflection_candidates_launched(scene: "Scene", ctx: "TxContext", points: np.ndarray, rays: int,
                                   options: LaunchOptions = LaunchOptions()) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per reflection order ``k`` (index ``k - 1``), the (point, chain row of ``ctx.levels[k]``)
    pairs that launched transmitter rays carry to ``points``.

    ``rays`` directions from the transmitter (:func:`fibonacci_directions`) are traced through
    ``max_reflections`` specular reflections; each segment after ``k`` reflections gives its
    mirror chain to the points within its tube (``radius_factor`` times the rays' angular
    spacing times the unfolded distance from the transmitter). Chains the context's image
    tree does not hold (proven hidden) are dropped: the exhaustive search would not test them.
    """
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    K = ctx.options.max_reflections
    out = [(np.zeros(0, np.int64), np.zeros(0, np.int64)) for _ in range(K)]
    if K == 0 or len(points) == 0:
        return out
    if len(ctx.tx) != 1:
        raise WavepathsError("launched candidates take one transmitter per context")
    from . import kernels

    grid = PointGrid(points) if kernels.available() else None
    far = 2.0 * scene.diagonal
    eps = 1e-6 * scene.diagonal
    dth = np.sqrt(4.0 * np.pi / rays)
    grow = options.radius_factor * dth
    found: list[list[np.ndarray]] = [[] for _ in range(K)]
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
                seg, pt = tube_pairs(origin, end, grow * travelled, grow * (travelled + dist), points, grid)
                if len(seg):
                    found[k - 1].append(unique_rows(np.column_stack([pt, chain[seg]])))
            hit = poly >= 0
            if k == K or not hit.any():
                break
            sel, mirror, origin, u, travelled = reflect_and_branch(scene, origin, u, poly, dist, travelled,
                                                                   0.0, grow, options.radius_factor)
            chain = np.column_stack([chain[sel], mirror])
    for k in range(1, K + 1):
        if not found[k - 1]:
            continue
        rows = unique_rows(np.concatenate(found[k - 1]))
        c = chain_rows(ctx.levels[k].polygons, rows[:, 1:])
        ok = c >= 0
        out[k - 1] = (rows[ok, 0], c[ok])
    return out
