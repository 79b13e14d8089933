"""Launched candidates: the diffracted sequences that Keller fans from sampled edge points carry.

The exhaustive search (:mod:`wavepaths.search.diffraction`) enumerates every (source image,
edge, receiver image) triple that no conservative test rules out. In a dense city most of
them are occluded: munich at two reflections around the edge keeps some 400,000 candidates
per receiver for about 15 paths. This module finds candidates in proportion to the paths
instead, by sampling, in three steps:

1. **Edge samples** (:func:`edge_samples`). For each order ``a`` of reflections before the
   edge, the context's (source image, dihedron) pairs and their windows (the parts of each
   edge that the transmitter, or its image through the last mirror, may reach;
   :class:`~wavepaths.search.context.DiffractionSources`) are sampled along the edge, every
   ``max(spacing, angular * distance to the image)`` metres. Each sample is back-traced
   through its mirrors (:func:`~wavepaths.search.images.backtrace`: every reflection point
   inside its polygon) and its legs are cast; a sample is kept when it, or a neighbour on
   the same window, is lit. No transmitter rays are launched: the sources and windows are
   the exact engine's, so no edge is missed for being seen at a grazing angle. The end
   samples stand ``END_INSET`` spacings inside the window: a window end is a shadow's
   boundary, where the occlusion rule hides the point, and an edge seen only through a slit
   has the slit's lit stretch as its window (``tests/search/test_launch.py``). A lit
   stretch shorter than the spacing *inside* a window, between two hidden samples, still
   starts no fan: the chains with a reflection over it are missed (its E-D-R paths are
   enumerated). The spacing is absolute (0.25 m): on room-sized scenes the exhaustive
   search, the default, is the one to use.
2. **Keller fans** (:func:`fan_segments`, once for the box of the query points). From
   every kept sample, ``fan`` rays on the Keller cone of the incident direction (seed
   §2.1: ``v . w = u . w``), in the wedge's exterior, are traced through up to ``D - a``
   specular reflections (first hits from the ray caster, reflected in float64). The
   segments whose tubes may reach the box are kept (float32, recentred): a coverage map
   traces its fans once for all its tiles. The first leg of an order-0 sample's ray is not
   kept: it carries an E-D-R sequence, which the tiles enumerate
   (:mod:`wavepaths.search.launched`); its reflections are.
3. **Tubes** (:func:`candidate_sequences`, per set of points). Every segment carries its
   sequence (mirrors before, dihedron, mirrors after so far) to the query points within
   its tube. The tube is an ellipse in cross-section: ``radius_factor`` times the fan's
   spacing across the cone (the sample spacing plus ``sin(beta) x 2 pi / fan`` per metre
   of unfolded distance) and times the samples' spacing along it (the sample spacing plus
   their angular spacing per metre); past the end of a ray stopped by a face, a cap as long
   as the semi-axis across. On munich the round tubes of the first version carried 28 times the
   candidates (3.16 M against 111 k on a 1,024-cell strip) for 0.2 % more of the paths.

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

from .._ragged import ranks
from ..errors import WavepathsError
from .chains import occluded_chains
from .images import backtrace
from .rays import first_hits_past, reflect_and_branch
from .tubes import BoxSegments, PointGrid, reaches_box, tube_pairs, unique_rows

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


END_INSET = 1e-3
"""How far inside its window an end sample stands, in sample spacings (at most a quarter of
the window): 0.25 mm at the 0.25 m spacing, far above the occlusion rule's tolerances."""

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
    j = ranks(count)
    frac = np.where(count[row] > 1, j / np.maximum(count[row] - 1, 1), 0.5)
    # the end samples stand just inside the window: an end the visibility march stopped at
    # lies on a face's shadow boundary (within its margins), where the segment from the
    # source grazes that face and the occlusion rule calls it hidden
    inset = np.minimum(END_INSET * spacing, 0.25 * (hi - lo))
    t = (lo + inset)[row] + (hi - lo - 2 * inset)[row] * frac
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


@dataclass(frozen=True)
class FanSegments(BoxSegments):
    """The segments of the Keller fans' rays whose tubes reach a box of query points
    (:class:`~wavepaths.search.tubes.BoxSegments`: ``centre``, ``lo``, ``hi``, ``start``,
    ``end``, and ``r0``, ``r1`` the semi-axis of the tube across the Keller cone, the fan's
    spacing), over ``n`` segments and ``m`` distinct sequences.

    Traced once (:func:`fan_segments`) and queried by any set of points in the box
    (:func:`candidate_sequences`): a coverage map traces its fans once for all its tiles.

    Attributes
    ----------
    s0, s1 : (n,) float32
        Semi-axis along the cone's other normal direction (the samples' spacing) [m].
    across : (n, 3) float32
        Unit vector normal to the segment across the cone (mirrored with the ray).
    sequence : (n,) int32
        Row of the segment's sequence in the tables below.
    order, source, before, dihedron, after : (m,) and (m, D) int64
        The sequences, as in :class:`CandidateSequences`.
    """

    s0: np.ndarray
    s1: np.ndarray
    across: np.ndarray
    sequence: np.ndarray
    order: np.ndarray
    source: np.ndarray
    before: np.ndarray
    dihedron: np.ndarray
    after: np.ndarray


def fan_segments(scene: "Scene", ctx: "TxContext", lo: np.ndarray, hi: np.ndarray,
                 options: LaunchOptions = LaunchOptions(), samples: EdgeSamples | None = None) -> FanSegments:
    """Trace the Keller fans of every sample (step 2 of the module) and keep the segments
    whose tubes reach the box ``[lo, hi]`` of the query points.

    From each sample, ``options.fan`` directions per turn on its Keller cone, in the wedge's
    exterior (:func:`keller_fan`), go through up to ``D - a`` specular reflections (first hits
    from the ray caster, passing through the faces the ray leaves; reflected in float64, with
    the branches of :func:`~wavepaths.search.rays.reflect_and_branch`). A segment's tube is
    an ellipse: across the cone, ``radius_factor x (spacing + sin(beta) x dphi x t)``; along
    it, ``radius_factor x (spacing + angular x t)``, with ``t`` the unfolded distance from
    the edge, ``dphi = 2 pi / fan`` and the sample's ``spacing`` and ``angular`` spacing
    (neighbouring samples' rays are displaced along the edge, which projects on the second
    axis only; neighbouring directions of one fan, on the first).

    Parameters
    ----------
    scene : Scene
    ctx : TxContext
        Built with diffraction for one transmitter; ``ctx.options.diffraction_reflections``
        (``D``) bounds the reflections before plus after the edge.
    lo, hi : (3,) float64
        The box of the query points [m].
    options : LaunchOptions
    samples : EdgeSamples, optional
        From :func:`edge_samples` (computed when not given).

    Returns
    -------
    FanSegments
    """
    lo = np.asarray(lo, dtype=np.float64).reshape(3)
    hi = np.asarray(hi, dtype=np.float64).reshape(3)
    centre = 0.5 * (lo + hi)
    if samples is None:
        samples = edge_samples(scene, ctx, options)
    Dmax = ctx.options.diffraction_reflections
    far = 2.0 * scene.diagonal
    eps = 1e-6 * scene.diagonal  # rays leave an edge or a mirror: skip the float32 re-hit of their own face
    dphi = 2 * np.pi / options.fan
    D_ = scene.dihedra
    parts: list[tuple] = []
    for rows in _fan_chunks(samples, options.fan, options.fan_rays):
        P, V, ext, sb = keller_fan(scene, samples.dihedron[rows], samples.t[rows], samples.incident[rows], options.fan)
        si, fi = np.nonzero(ext)
        origin, u = P[si], V[si, fi]
        sample = rows[si]
        # the fan's direction of increasing angle, normal to the ray: -sin(phi) f0 + cos(phi) w x f0
        w = D_.direction[samples.dihedron[sample]]
        f0 = D_.face_direction[D_.face_ptr[samples.dihedron[sample]]]
        phi = (fi + 0.5) * dphi
        across = -np.sin(phi)[:, None] * f0 + np.cos(phi)[:, None] * np.cross(w, f0)
        base = options.radius_factor * samples.spacing[sample]
        grow_r = options.radius_factor * sb[si] * dphi
        grow_s = options.radius_factor * samples.angular[sample]
        travelled = np.zeros(len(si))
        after = np.full((len(si), Dmax), -1, np.int64)
        fp = D_.face_ptr[samples.dihedron[sample]]
        nf = D_.face_ptr[samples.dihedron[sample] + 1] - fp
        skip = np.stack([D_.face_polygon[fp], np.where(nf > 1, D_.face_polygon[np.minimum(fp + 1, len(D_.face_polygon) - 1)],
                                                        -1)], axis=1)
        for b in range(Dmax + 1):
            live = samples.order[sample] + b <= Dmax
            if not live.all():
                origin, u, sample, base, grow_r, grow_s, travelled, after, skip, across = (
                    x[live] for x in (origin, u, sample, base, grow_r, grow_s, travelled, after, skip, across))
            if len(origin) == 0:
                break
            poly, dist = first_hits_past(scene, origin, u, far, eps, skip)
            end = origin + dist[:, None] * u
            t1 = travelled + dist
            r0, r1 = base + grow_r * travelled, base + grow_r * t1
            s0, s1 = base + grow_s * travelled, base + grow_s * t1
            reach = reaches_box(origin, end, np.maximum(r0, s0), np.maximum(r1, s1), lo, hi)
            if b == 0:
                # a first leg from an order-0 sample carries E-D-R, which the tiles enumerate
                # (wavepaths.search.launched): only its reflections are kept
                reach &= samples.order[sample] > 0
            keep = np.nonzero(reach)[0]
            if len(keep):
                f32 = np.float32  # stored as float32 at once: munich keeps 6 M segments
                parts.append(((origin[keep] - centre).astype(f32), (end[keep] - centre).astype(f32),
                              r0[keep].astype(f32), r1[keep].astype(f32), s0[keep].astype(f32), s1[keep].astype(f32),
                              across[keep].astype(f32), sample[keep], after[keep]))
            hit = poly >= 0
            if b == Dmax or not hit.any():
                break
            sel, mirror, origin, u, travelled = reflect_and_branch(
                scene, origin, u, poly, dist, travelled, base, grow_r + grow_s, options.radius_factor)
            sample, base, grow_r, grow_s, after = sample[sel], base[sel], grow_r[sel], grow_s[sel], after[sel]
            n = scene.polygon_normal[mirror]
            across = across[sel]
            across = across - 2.0 * np.einsum("ij,ij->i", across, n)[:, None] * n
            after[:, b] = mirror
            skip = np.stack([mirror, np.full(len(mirror), -1)], axis=1)  # the mirror just left
    A = samples.chain.shape[1]
    if parts:
        cols = [np.concatenate(c) for c in zip(*parts)]
    else:
        cols = [np.zeros((0, 3)), np.zeros((0, 3)), *(np.zeros(0),) * 4, np.zeros((0, 3)), np.zeros(0, np.int64),
                np.zeros((0, Dmax), np.int64)]
    start, end, r0, r1, s0, s1, across, sample, after = cols
    # the distinct sequences: (order, source, after) names the mirrors before and the dihedron too
    key = np.column_stack([samples.order[sample], samples.source[sample], after]).astype(np.int64)
    table, inverse = unique_rows(key, return_inverse=True)
    first = np.zeros(len(table), np.int64)
    first[inverse] = np.arange(len(key))
    rep = sample[first]
    before = np.full((len(table), Dmax), -1, np.int64)
    before[:, :min(A, Dmax)] = samples.chain[rep][:, :min(A, Dmax)]
    start, end, r0, r1, s0, s1, across = (x.astype(np.float32, copy=False) for x in (start, end, r0, r1, s0, s1, across))
    return FanSegments(centre, lo, hi, start, end, r0, r1, s0, s1, across, inverse.astype(np.int32),
                       table[:, 0].copy(), table[:, 1].copy(), before, samples.dihedron[rep], table[:, 2:].copy())


SEGMENT_CHUNK = 1 << 21
"""Cached segments queried at once (bounds the (segment, point) pairs held before their keys are made distinct)."""


def candidate_sequences(scene: "Scene", ctx: "TxContext", points: np.ndarray,
                        options: LaunchOptions = LaunchOptions(),
                        samples: EdgeSamples | None = None,
                        segments: FanSegments | None = None) -> CandidateSequences:
    """The diffracted sequences whose Keller fans pass near each of ``points`` (step 3).

    Parameters
    ----------
    scene : Scene
    ctx : TxContext
        Built with diffraction for one transmitter.
    points : (p, 3) float64
        Query points (receivers) [m].
    options : LaunchOptions
    samples : EdgeSamples, optional
        From :func:`edge_samples` (computed when not given).
    segments : FanSegments, optional
        From :func:`fan_segments`, kept for a box that holds ``points`` (traced for the
        points' own box when not given).

    Returns
    -------
    CandidateSequences
        Distinct rows (point, before, dihedron, after).
    """
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    if segments is None:
        lo, hi = (points.min(axis=0), points.max(axis=0)) if len(points) else (np.zeros(3), np.zeros(3))
        segments = fan_segments(scene, ctx, lo, hi, options, samples)
    elif not segments.covers(points):
        raise WavepathsError("the fan segments were kept for a box that does not hold every query point")
    from . import kernels

    local = points - segments.centre
    grid = PointGrid(local) if kernels.available() and len(points) else None
    m = max(len(segments.order), 1)
    keys = []
    for c0 in range(0, len(segments), SEGMENT_CHUNK):
        c = slice(c0, c0 + SEGMENT_CHUNK)
        seg, pt = tube_pairs(segments.start[c], segments.end[c], segments.r0[c], segments.r1[c], local, grid,
                             s0=segments.s0[c], s1=segments.s1[c], across=segments.across[c])
        if len(seg):
            keys.append(np.unique(pt * m + segments.sequence[c][seg]))
    k = np.unique(np.concatenate(keys)) if keys else np.zeros(0, np.int64)
    q = k % m
    return CandidateSequences(k // m, segments.order[q], segments.source[q], segments.before[q],
                              segments.dihedron[q], segments.after[q])
