"""Per-receiver work, vectorised over (receivers in a tile x candidates).

Every function here takes the scene, a :class:`~wavepaths.search.context.TxContext`
and a tile of receivers, builds the candidate arrays, applies the tests in order of
cost (sectors, segment parameter, point-in-polygon, occlusion), compacting the
survivors after each test, and casts the surviving segments in one batch. Each test
adds to the ``stats`` counters what it rejected.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..topology.sectors import FACE_ANGLE_TOL, sector_lookup
from . import kernels
from .beams import morton_order, reflection_candidates
from .context import TxContext
from .geometry import diffraction_point_reduced
from .images import ImageLevel, backtrace, build_image_levels
from .paths import InteractionType, PathBatch
from .visibility import VisibilityWindows

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene

CANDIDATE_BUDGET = 1 << 21  # candidates held at once (bounds temporaries to ~100 MB)
# the receiver side of order >= 1 is dense (matrix products over images x dihedra) up to this
# many dihedra, tree queries above: dense was 2.6x faster with 640 (etoile_crop, R3+D2) and
# 1.5x with ~100 (simple_street_canyon map, R2+D1); the tree's cost grows as log(dihedra)
DENSE_RECEIVER_SIDE_MAX_DIHEDRA = 4096


def _leg_order(legs: int) -> list[int]:
    """Legs of a chain in casting order: the last (to the receiver), the first, then the others."""
    return list(dict.fromkeys([legs - 1, 0, *range(1, legs - 1)]))


def _occluded_chains(scene: "Scene", vertices: np.ndarray, stats: Counter, exact: np.ndarray | None = None) -> np.ndarray:
    """(k,) bool: whether any segment of the chains ``vertices`` (k, s, 3) is blocked.

    A chain with a degenerate segment (shorter than the weld tolerance: two interactions
    at one point, e.g. a reflection on a face exactly at the edge it then diffracts on)
    counts as blocked: its geometry is undefined.
    """
    k, s, _ = vertices.shape
    seg = np.linalg.norm(np.diff(vertices, axis=1), axis=2)
    # only segments joining two interactions can be degenerate; a transmitter or receiver may
    # sit as close to a surface as it likes
    inner = seg[:, 1:-1] if s > 3 else np.zeros((k, 0))
    degenerate = (inner <= scene.length_tolerance(scene.tolerances.weld)).any(axis=1)
    if s > 2:
        # ... but one exactly on the face or edge it would interact with (within the casters'
        # plane tolerance, i.e. rounding) takes part in no interaction there (docs/search.md)
        from ..raycast import plane_tolerance

        degenerate |= (seg[:, [0, -1]] <= plane_tolerance(scene)).any(axis=1)
    # the true vertices: by the casters' rule (wavepaths.raycast) an end on a surface does not
    # hit it, and a face next to it still blocks (no lifted or shortened copies)
    # one leg at a time, each cast only for the chains still clear (compaction): the leg to
    # the receiver first (most often blocked), then from the transmitter, then the inner ones
    blocked = np.zeros((k, s - 1), dtype=bool)
    alive = np.nonzero(~degenerate)[0]
    for j in _leg_order(s - 1):
        if len(alive) == 0:
            break
        hit = scene.raycaster.occluded(vertices[alive, j], vertices[alive, j + 1])
        stats["rays_cast"] += len(alive)
        blocked[alive[hit], j] = True
        alive = alive[~hit]
    if exact is not None and exact.any():
        # chains of (tx, rx) pairs that sit on a shadow or reflection boundary: float64 casts
        sel = np.nonzero(exact)[0]
        blocked[sel] = scene.exact_raycaster.occluded(
            vertices[sel, :-1].reshape(-1, 3), vertices[sel, 1:].reshape(-1, 3)
        ).reshape(len(sel), s - 1)
        stats["rays_cast_float64"] += len(sel) * (s - 1)
    return blocked.any(axis=1) | degenerate


def _triangle_of(scene: "Scene", polygons: np.ndarray) -> np.ndarray:
    return scene.polygon_tris[scene.polygon_tri_ptr[polygons]]


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
    blocked[ok] = _occluded_chains(scene, np.stack([a[ok], b[ok]], axis=1), stats, grazing[ti[ok], ri[ok]])
    ok &= ~blocked
    stats["los_rejected_occluded"] += int(blocked.sum())
    k = int(ok.sum())
    return PathBatch(
        ti[ok], ri[ok] + rx_offset, np.zeros((k, 0), np.int8), np.zeros((k, 0), np.int64),
        np.zeros((k, 0), np.int64), np.full((k, 2), -1, np.int64), np.stack([a[ok], b[ok]], axis=1),
    )


def reflection_tile(
    scene: "Scene", ctx: TxContext, order: int, rx: np.ndarray, rx_offset: int, stats: Counter, grazing: np.ndarray
) -> list[PathBatch]:
    """Specular paths of one order: image method backwards from each receiver.

    Only the (receiver, chain) pairs whose chain's last-leg beam can reach the receiver are
    back-traced (:func:`~wavepaths.search.beams.reflection_candidates`; the others are
    counted in ``reflection_order_{k}_culled_beam``).
    """
    lv = ctx.levels[order]
    c, n = len(lv), len(rx)
    out = []
    if c == 0 or n == 0:
        return out
    tag = f"reflection_order_{order}"
    # (receiver, chain) pairs whose chain's last-leg beam can reach the receiver (beams.py)
    for ri, ci in reflection_candidates(scene, ctx, order, rx, stats, CANDIDATE_BUDGET):
        stats[f"{tag}_candidates"] += len(ri)
        if ctx.options.prune_db is not None:
            # |a| <= lambda / (4 pi |rx - I_k|) for |Gamma| <= 1: drop chains below the tolerance
            direct = np.linalg.norm(rx[ri] - ctx.tx[lv.source[ci]], axis=1)
            unfolded = np.linalg.norm(rx[ri] - lv.images[ci, -1], axis=1)
            weak = unfolded > 10 ** (ctx.options.prune_db / 20) * direct
            if weak.any():
                # count only those that would have been paths, so the stated bound uses the true number
                okw, _, _ = backtrace(scene, rx[ri[weak]], lv, ci[weak])
                stats["pruned_paths_upper_bound"] += len(okw)
                stats[f"{tag}_pruned_candidates"] += int(weak.sum())
            ri, ci = ri[~weak], ci[~weak]
        ok, pts, rej = backtrace(scene, rx[ri], lv, ci)
        stats[f"{tag}_rejected_segment"] += rej["segment"]
        stats[f"{tag}_rejected_outside_polygon"] += rej["outside_polygon"]
        ri, ci = ri[ok], ci[ok]
        verts = np.concatenate([lv.images[ci, :1], pts, rx[ri][:, None, :]], axis=1)
        blocked = _occluded_chains(scene, verts, stats, grazing[lv.source[ci], ri])
        stats[f"{tag}_rejected_occluded"] += int(blocked.sum())
        keep = ~blocked
        ri, ci, verts = ri[keep], ci[keep], verts[keep]
        polys = lv.polygons[ci]
        k = len(ri)
        out.append(
            PathBatch(
                lv.source[ci], ri + rx_offset, np.full((k, order), InteractionType.REFLECTION, np.int8), polys,
                _triangle_of(scene, polys), np.full((k, 2), -1, np.int64), verts,
            )
        )
    return out


def _cull_sources_by_keller_cone(dihedra, src, sources: np.ndarray, targets: np.ndarray):
    """The (source, dihedron) pairs whose Keller cones can reach a sphere around ``targets``.

    Along an edge from A (t = 0) to B (t = L), a receiver R is reached at some point iff
    ``w.(R - A)/|R - A| >= cos beta_A`` and ``w.(R - B)/|R - B| <= cos beta_B`` with
    ``cos beta_X = w.(X - S)/|X - S|`` (the diffracted cone's opening equals the incident
    angle, and both sides are monotonic in t). For a sphere (C, r) each side is tested
    with the angular margin ``asin(r / |C - X|)``: conservative, so no path is lost.
    """
    if len(src.chain) == 0 or len(targets) == 0:
        return src
    c = targets.mean(axis=0)
    r = float(np.linalg.norm(targets - c, axis=1).max()) * (1 + 1e-9) + 1e-9
    d = src.dihedron
    w = dihedra.direction[d]
    A = dihedra.origin[d]
    B = A + dihedra.length[d][:, None] * w

    def cos_to(x_from, x_to):
        v = x_to - x_from
        return np.einsum("ij,ij->i", v, w) / np.maximum(np.linalg.norm(v, axis=1), 1e-300)

    cos_a = cos_to(sources, A)
    cos_b = cos_to(sources, B)

    def angle_range(X):
        v = c - X
        dist = np.linalg.norm(v, axis=1)
        theta = np.arccos(np.clip(np.einsum("ij,ij->i", v, w) / np.maximum(dist, 1e-300), -1, 1))
        delta = np.where(dist > r, np.arcsin(np.clip(r / np.maximum(dist, 1e-300), 0, 1)), np.pi)
        return theta, delta

    th_a, de_a = angle_range(A)
    th_b, de_b = angle_range(B)
    slack = 1e-9
    reach_a = np.cos(np.maximum(th_a - de_a, 0.0)) >= cos_a - slack
    reach_b = np.cos(np.minimum(th_b + de_b, np.pi)) <= cos_b + slack
    keep = reach_a & reach_b
    if keep.all():
        return src
    return src.take(np.nonzero(keep)[0])


def _join_chunks(src, keys: np.ndarray, budget: int = CANDIDATE_BUDGET):
    """For each receiver-side key, all transmitter-side sources with the same key, in chunks.

    Yields ``(rows, src_rows)``: the receiver-side row and the transmitter-side row of every
    match, at most about ``budget`` matches per chunk (a single key with more matches than
    that comes in one chunk of its own), so that memory stays bounded however many image
    sources share a (dihedron, sector).
    """
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
        c = count[lo:hi]
        rows = np.repeat(np.arange(lo, hi), c)
        offs = np.arange(len(rows)) - np.repeat(np.cumsum(c) - c, c)
        yield rows, np.repeat(first[lo:hi], c) + offs
        lo = hi


@dataclass(frozen=True)
class _EndSide:
    """One end of the diffracted path (image of order a or b), projected on edges.

    Per row: the edge's ``dihedron`` and ``sector`` (around the edge line), the UTD angle
    ``phi`` from the sector's first face, and the end point's coordinate along the edge
    ``t`` [m from the edge origin] and distance to the edge line ``rho`` [m]. These are
    the seed's ``t_e, d_e`` (or ``t_r, d_r``) of §2.3: with them the diffraction point of
    any (E, R) pair is a scalar formula, so the 3-D work is done once per (end, edge).
    """

    row: np.ndarray
    dihedron: np.ndarray
    sector: np.ndarray
    phi: np.ndarray
    t: np.ndarray
    rho: np.ndarray
    visible: VisibilityWindows | None = None  # transmitter side: the part of each edge its incident leg may reach


def _keller_window(scene: "Scene", tside: _EndSide) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per dihedron, the window of receiver coordinates some transmitter-side source can reach on the edge.

    The closed-form point ``t = (t_e d_r + t_r d_e) / (d_e + d_r)`` (seed §2.3) lies in a
    part ``v_lo <= t <= v_hi`` of the edge (the whole edge ``[0, L]``, or the part the
    transmitter may see, :mod:`wavepaths.search.visibility`) iff
    ``t_r - v_lo >= ((v_lo - t_e) / d_e) d_r`` and ``t_r - v_hi <= ((v_hi - t_e) / d_e) d_r``.
    Returns ``(v_lo, lo, v_hi, hi)`` (n_dihedra,) each: per dihedron the smallest ``v_lo``
    and ``(v_lo - t_e) / d_e``, the largest ``v_hi`` and ``(v_hi - t_e) / d_e`` over its
    sources (``+inf``, ``-inf`` without one). As ``d_r >= 0``, a receiver-side pair that
    fails ``t_r >= v_lo + lo d_r`` or ``t_r <= v_hi + hi d_r`` has no source whose point
    lies on that part of the edge (:func:`_in_keller_window`). The bounds may come from
    different sources: conservative.
    """
    n = len(scene.dihedra.length)
    L = scene.dihedra.length[tside.dihedron]
    if tside.visible is None:
        v_lo, v_hi = np.zeros(len(L)), L
    else:
        v_lo, v_hi = tside.visible.bounds(L)
        tau = tside.visible.tau
        v_lo, v_hi = v_lo - tau, v_hi + tau
    out = [np.full(n, np.inf), np.full(n, np.inf), np.full(n, -np.inf), np.full(n, -np.inf)]
    with np.errstate(divide="ignore", invalid="ignore"):
        np.minimum.at(out[0], tside.dihedron, v_lo)
        np.minimum.at(out[1], tside.dihedron, (v_lo - tside.t) / tside.rho)
        np.maximum.at(out[2], tside.dihedron, v_hi)
        np.maximum.at(out[3], tside.dihedron, (v_hi - tside.t) / tside.rho)
    return tuple(out)


def _in_keller_window(scene: "Scene", window, d: np.ndarray, t: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """(k,) bool: the receiver-side pairs (dihedron ``d``, coordinates ``t``, ``rho``) inside ``window``
    (:func:`_keller_window`), with a margin of ``1e-9`` of the scene size."""
    v_lo, lo, v_hi, hi = window
    tol = scene.length_tolerance(1e-9)
    with np.errstate(invalid="ignore", over="ignore"):
        return (t - v_lo[d] - lo[d] * rho >= -tol) & (t - v_hi[d] - hi[d] * rho <= tol)


def _sector_in_table(ctx: TxContext, d: np.ndarray, x: np.ndarray, y: np.ndarray):
    """:func:`~wavepaths.topology.sectors.sector_lookup` on the context's sector table."""
    return sector_lookup(ctx.sectors, d, x, y)


def _kept_pairs_end_side(scene: "Scene", ctx: TxContext, rx_lv: ImageLevel, e: np.ndarray, d: np.ndarray, window,
                         stats: Counter, tag: str) -> _EndSide:
    """The last tests of the receiver side on the (receiver image ``e``, dihedron ``d``) pairs that
    passed the culling: the Keller window (with ``window``), then the sector (not on a face,
    wider than pi), each per pair from ``R - A`` in the edge's frame.

    Without a window and with the compiled kernels, the frame, sector and width test run as
    one compiled loop per pair (:func:`wavepaths.search._numba.end_sides`, the same
    expressions)."""
    if window is None and ctx.options.compiled and kernels.available():
        from . import _numba

        c = np.ascontiguousarray
        k = len(e)
        keep, sec, t = np.empty(k, np.int64), np.empty(k, np.int64), np.empty(k)
        phi, rho = np.empty(k), np.empty(k)
        tab = ctx.sectors
        n = _numba.end_sides(c(rx_lv.images), c(e, dtype=np.int64), c(d, dtype=np.int64), c(scene.dihedra.origin),
                             c(scene.dihedra.direction), c(tab.x_hat), c(tab.y_hat), c(tab.angles),
                             c(tab.count, dtype=np.int64), c(tab.width), FACE_ANGLE_TOL,
                             np.pi + scene.tolerances.coplanar_angle, keep, sec, phi, t, rho)
        stats[f"{tag}_receiver_pairs_rejected_sector"] += k - n
        keep = keep[:n]
        return _EndSide(e[keep], d[keep], sec[:n], phi[:n], t[:n], rho[:n])
    x, y, t = _edge_frame(scene, ctx, rx_lv.last[e], d)
    rho = np.hypot(x, y)
    if window is not None:
        inside = _in_keller_window(scene, window, d, t, rho)
        stats[f"{tag}_receiver_pairs_rejected_keller_window"] += int((~inside).sum())
        e, d, x, y, t, rho = e[inside], d[inside], x[inside], y[inside], t[inside], rho[inside]
    sec, width, phi = _sector_in_table(ctx, d, x, y)
    good = (sec >= 0) & (width > np.pi + scene.tolerances.coplanar_angle)
    stats[f"{tag}_receiver_pairs_rejected_sector"] += int((~good).sum())
    return _EndSide(e[good], d[good], sec[good], phi[good], t[good], rho[good])


def _receiver_side_by_tree(scene: "Scene", ctx: TxContext, rx_lv: ImageLevel, e_rows: np.ndarray, diffr: np.ndarray,
                           edges, stats: Counter, tag: str, window=None) -> _EndSide:
    """Step 1 of :func:`diffraction_tile` for receiver images of order ``b >= 1``, through the edge tree.

    Seen from the receiver, the legs after the diffraction are a reflected chain from the
    receiver that ends on the edge: the (image, dihedron) pairs whose last leg can reach
    the edge are those of :func:`~wavepaths.search.beams.chains_meeting_edges` (beyond the
    last mirror, inside the beams through the mirrors; a tree query, conservative), the
    same test as for the transmitter's images. Then the sector, per pair.
    """
    from .beams import chains_meeting_edges

    sub = ImageLevel(rx_lv.source[e_rows], rx_lv.polygons[e_rows], rx_lv.images[e_rows])
    wanted = np.zeros(len(scene.dihedra), dtype=bool)
    wanted[diffr] = True
    ch, dd = [], []
    for c, d in chains_meeting_edges(scene, sub, ctx.apertures, edges, compiled=ctx.options.compiled):
        keep = wanted[d]
        ch.append(c[keep])
        dd.append(d[keep])
    e = e_rows[np.concatenate(ch)] if ch else np.zeros(0, np.int64)
    d = np.concatenate(dd) if dd else np.zeros(0, np.int64)
    stats[f"{tag}_receiver_pairs_rejected_beam"] += len(e_rows) * len(diffr) - len(e)
    return _kept_pairs_end_side(scene, ctx, rx_lv, e, d, window, stats, tag)


def _last_mirror_planes(scene: "Scene", rx_lv: ImageLevel, e_rows: np.ndarray):
    """For the mirror-side test: the last mirrors' unit normals ``n`` (E, 3) and offsets ``off``
    (E,) on coordinates recentred on the scene centre, the side ``side`` (E,) of the previous
    image, and the plane tolerance [m]."""
    c0 = scene.center
    q = rx_lv.polygons[e_rows, -1]
    n, off = scene.polygon_normal[q], scene.polygon_offset[q] - scene.polygon_normal[q] @ c0
    side = np.sign(np.einsum("ij,ij->i", rx_lv.images[e_rows, -2] - c0, n) - off)
    return n, off, side, scene.length_tolerance(scene.tolerances.plane_distance)


def _receiver_side(scene: "Scene", ctx: TxContext, rx_lv: ImageLevel, e_rows: np.ndarray, diffr: np.ndarray,
                   stats: Counter, tag: str, window=None) -> _EndSide:
    """Step 1 of :func:`diffraction_tile`, dense over (receiver images ``e_rows``) x (dihedra ``diffr``).

    The culling tests are outer products of a per-image and a per-edge vector (matrix
    products on coordinates recentred on the scene centre, so that float64 keeps the
    scene's resolution at any offset), so nothing is gathered per pair for them; the
    sector is then computed per surviving pair, from ``R - A``. Tests:

    * for ``b >= 1``, *mirror side*: the edge must have a point on the real side of the
      image's last mirror ``q`` (the leg from the diffraction point to the last image
      must cross ``q``'s plane, image method); both edge ends beyond the plane (within
      the plane tolerance) drop the pair;
    * for ``b >= 1``, *beam*: the reflection point on ``q`` lies on the ray from the
      image toward the diffraction point, so the directions from the image to ``q``'s
      bounding sphere and to the edge's bounding sphere must overlap (the bounding-sphere
      beam of :mod:`wavepaths.search.images`; conservative);
    * *Keller window* (with ``window``, :func:`_keller_window`): some source's
      diffraction point lies on the edge;
    * the sector: not on a face, and wider than pi.
    """
    if ctx.options.compiled and kernels.available():
        return _receiver_side_compiled(scene, ctx, rx_lv, e_rows, diffr, stats, tag, window)
    dihedra = scene.dihedra
    c0 = scene.center
    I = rx_lv.last[e_rows] - c0  # (E, 3)
    A = dihedra.origin[diffr] - c0  # (D, 3)
    w = dihedra.direction[diffr]
    L = dihedra.length[diffr]
    ok = np.ones((len(e_rows), len(diffr)), dtype=bool)
    disabled = ctx.options.disable_culling
    if rx_lv.order >= 1 and "receiver_mirror_side" not in disabled:
        n, off, side, tol = _last_mirror_planes(scene, rx_lv, e_rows)
        sa = side[:, None] * (n @ A.T - off[:, None])
        sb = side[:, None] * (n @ (A + L[:, None] * w).T - off[:, None])
        reach = np.maximum(sa, sb) > -tol
        stats[f"{tag}_receiver_pairs_rejected_mirror_side"] += int((~reach).sum())
        ok &= reach
    if rx_lv.order >= 1 and "receiver_beam" not in disabled:
        q = rx_lv.polygons[e_rows, -1]
        centre, radius = scene.polygon_spheres
        to_q = centre[q] - c0 - I  # (E, 3)
        dist_q = np.linalg.norm(to_q, axis=1)
        M = A + 0.5 * L[:, None] * w  # edge midpoints (D, 3)
        h = 0.5 * L
        dist_m = np.sqrt(np.maximum((I * I).sum(1)[:, None] - 2 * (I @ M.T) + (M * M).sum(1)[None, :], 0.0))
        cos = (to_q @ M.T - (to_q * I).sum(1)[:, None]) / np.maximum(dist_q[:, None] * dist_m, 1e-300)
        # angle(to q, to M) <= half_q + half_m, in the cosine domain (no arccos per pair):
        # cos(half_q + half_m) = cos_q cos_m - sin_q sin_m, with sin = radius / distance
        sin_q = np.clip(radius[q] / np.maximum(dist_q, 1e-300), 0, 1)[:, None]
        sin_m = np.clip(h[None, :] / np.maximum(dist_m, 1e-300), 0, 1)
        cos_q, cos_m = np.sqrt(1 - sin_q * sin_q), np.sqrt(1 - sin_m * sin_m)
        # both half-angles lie in [0, pi/2], their sum in [0, pi] where cos decreases; the margin
        # is 1e-9 rad (cos(s + 1e-9) ~ cos s - 1e-9 sin s) plus 1e-12 for rounding
        cos_sum = cos_q * cos_m - sin_q * sin_m
        sin_sum = sin_q * cos_m + cos_q * sin_m
        beam = cos >= cos_sum - 1e-9 * sin_sum - 1e-12
        beam |= (dist_q <= radius[q])[:, None] | (dist_m <= h[None, :])
        stats[f"{tag}_receiver_pairs_rejected_beam"] += int((ok & ~beam).sum())
        ok &= beam
    # the sector, per surviving pair, from R - A (the dense products above lose digits
    # relative to a small distance to the edge line: an end point almost on it)
    ie, idd = np.nonzero(ok)
    return _kept_pairs_end_side(scene, ctx, rx_lv, e_rows[ie], diffr[idd], window, stats, tag)


def _receiver_side_compiled(scene: "Scene", ctx: TxContext, rx_lv: ImageLevel, e_rows: np.ndarray,
                            diffr: np.ndarray, stats: Counter, tag: str, window=None) -> _EndSide:
    """:func:`_receiver_side` with the mirror-side, beam and Keller-window tests fused per pair
    (:func:`wavepaths.search.kernels.receiver_pairs`, numba); the same tests and margins, then
    the sector per surviving pair, as the numpy reference does.

    One test more, after the beam (``receiver_aperture``): the edge must meet the beams
    from the image through its mirrors' rectangles (the test of
    :func:`~wavepaths.search.beams.chain_beams_meet`, which the tree-based receiver side
    applies too). In numpy it would cost four plane tests per pair and mirror over every
    pair; fused, it costs the planes a pair needs before it fails one.
    """
    dihedra = scene.dihedra
    c0 = scene.center
    R = rx_lv.last[e_rows]
    I = R - c0
    A = dihedra.origin[diffr] - c0
    w = dihedra.direction[diffr]
    L = dihedra.length[diffr]
    B = A + L[:, None] * w
    disabled = ctx.options.disable_culling
    mirror = beam = aperture = None
    if rx_lv.order >= 1:
        q = rx_lv.polygons[e_rows, -1]
        if "receiver_mirror_side" not in disabled:
            mirror = _last_mirror_planes(scene, rx_lv, e_rows)
        if "receiver_beam" not in disabled:
            centre, radius = scene.polygon_spheres
            to_q = centre[q] - c0 - I
            beam = (to_q, np.linalg.norm(to_q, axis=1), radius[q], A + 0.5 * L[:, None] * w, 0.5 * L)
        if "receiver_aperture" not in disabled and ctx.apertures is not None:
            planes = kernels.chain_side_planes(rx_lv.last[e_rows], rx_lv.polygons[e_rows], ctx.apertures.quads,
                                               scene.polygon_normal, scene.polygon_offset)
            aperture = (planes, scene.length_tolerance(1e-9))
    frame = (dihedra.origin[diffr], w, ctx.sectors.x_hat[diffr], ctx.sectors.y_hat[diffr])
    win = None
    if window is not None:
        v_lo, lo, v_hi, hi = window
        win = (v_lo[diffr], lo[diffr], v_hi[diffr], hi[diffr], scene.length_tolerance(1e-9))
    ie, idd, n_mirror, n_beam, n_aperture, n_window = kernels.receiver_pairs(I, mirror, A, B, beam, aperture, R,
                                                                             frame, win)
    if mirror is not None:
        stats[f"{tag}_receiver_pairs_rejected_mirror_side"] += n_mirror
    if beam is not None:
        stats[f"{tag}_receiver_pairs_rejected_beam"] += n_beam
    if aperture is not None:
        stats[f"{tag}_receiver_pairs_rejected_aperture"] += n_aperture
    if win is not None:
        stats[f"{tag}_receiver_pairs_rejected_keller_window"] += n_window
    return _kept_pairs_end_side(scene, ctx, rx_lv, e_rows[ie], diffr[idd], None, stats, tag)


def _edge_frame(scene: "Scene", ctx: TxContext, points: np.ndarray, d: np.ndarray):
    """Coordinates of ``points`` (k, 3) in the frame of edges ``d`` (k,): ``x``, ``y`` in the
    plane perpendicular to the edge (``x`` along its first face), ``t`` along it [m]."""
    v = points - scene.dihedra.origin[d]
    x = np.einsum("ij,ij->i", v, ctx.sectors.x_hat[d])
    y = np.einsum("ij,ij->i", v, ctx.sectors.y_hat[d])
    t = np.einsum("ij,ij->i", v, scene.dihedra.direction[d])
    return x, y, t


def _transmitter_side(scene: "Scene", ctx: TxContext, tx_lv: ImageLevel, src) -> _EndSide:
    """Projections of the transmitter-side sources (image, dihedron) on their edges (see :class:`_EndSide`)."""
    d = src.dihedron
    x, y, t = _edge_frame(scene, ctx, tx_lv.last[src.chain], d)
    sec, _, phi = _sector_in_table(ctx, d, x, y)
    return _EndSide(src.chain, d, sec, phi, t, np.hypot(x, y), src.visible)


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

    ``edges``: the context's :func:`~wavepaths.search.beams.edge_tree` over ``ctx.diffracting``; with it
    (and the context's apertures) the receiver side of order ``b >= 1`` is found by tree
    queries instead of the dense product when there are more than
    ``DENSE_RECEIVER_SIDE_MAX_DIHEDRA`` candidate dihedra.

    Also marks in ``grazing`` (m, n) the (tx, rx) pairs for which a candidate lies within
    the float32 uncertainty of a shadow or reflection boundary of its edge: the geometrical
    optics paths of those pairs are then cast in float64, so that the UTD field, whose
    boundary terms switch by the float64 angles, stays continuous.

    Order of the tests, cheapest and most selective first:

    1. per (receiver image, dihedron), dense: the mirror side and beam of the image's
       last mirror, the sector around the edge (:func:`_receiver_side`);
    2. the join with the transmitter side on (dihedron, sector): FindDihedron (seed
       §3.3) accepts E-P-R exactly when E and R lie in the same sector of the edge (a
       sector is a prism around the edge line), whose bounding faces are the true
       dihedron, so the join *is* the seed's test, evaluated once per end, not per path
       (:func:`~wavepaths.topology.sectors.sector_angle`; tests/search check it against
       :func:`~wavepaths.topology.find_dihedron.find_dihedron`);
    3. the closed-form diffraction point (seed §2.3) in the reduced coordinates of the
       two ends, ``t = (t_e d_r + t_r d_e) / (d_e + d_r)``, on the edge segment;
    4. the reflection points on both sides by the image method (back-traces);
    5. occlusion of every leg, cast in one batch.
    """
    dihedra = scene.dihedra
    tx_lv = ctx.levels[a]
    rx_lv = rx_levels[b]
    tag = f"diffraction_{a}r_{b}r"
    out: list[PathBatch] = []
    if len(rx_lv) == 0 or len(ctx.diffraction_sources[a].chain) == 0:
        return out
    src_all = ctx.diffraction_sources[a]
    m = int(ctx.sectors.angles.shape[1])
    # receiver images per chunk: the numpy receiver side holds about m + 4 (images x dihedra)
    # temporaries, the compiled one a single int32 array of the survivors' columns
    per_pair = 1 if (ctx.options.compiled and kernels.available()) else m + 4
    step = max(1, CANDIDATE_BUDGET // (max(len(np.unique(src_all.dihedron)), 1) * per_pair))
    # receiver images in Morton order: each chunk is then compact in space, and the Keller-cone
    # culling below keeps fewer dihedra for it (etoile_crop at depth 3: 608 M -> 327 M pairs
    # at b = 2); the paths found do not depend on the chunking
    order = morton_order(rx_lv.last) if b >= 1 else np.arange(len(rx_lv))
    for s in range(0, len(rx_lv), step):
        e_rows = order[s : s + step]
        # Keller-cone culling for this chunk of receivers (or receiver images): keep the
        # (source, dihedron) pairs whose diffracted cones can reach the chunk's bounding sphere
        src = src_all
        if "keller_cone" not in ctx.options.disable_culling:
            src = _cull_sources_by_keller_cone(dihedra, src_all, tx_lv.last[src_all.chain], rx_lv.last[e_rows])
        stats[f"{tag}_source_pairs_culled_keller_cone"] += len(src_all.chain) - len(src.chain)
        diffr = np.unique(src.dihedron)
        if len(diffr) == 0:
            continue
        stats[f"{tag}_receiver_pairs"] += len(e_rows) * len(diffr)
        tside = _transmitter_side(scene, ctx, tx_lv, src)
        window = None if "keller_window" in ctx.options.disable_culling else _keller_window(scene, tside)
        if (b >= 1 and edges is not None and len(diffr) > DENSE_RECEIVER_SIDE_MAX_DIHEDRA
                and not {"receiver_mirror_side", "receiver_beam"} & ctx.options.disable_culling):
            rside = _receiver_side_by_tree(scene, ctx, rx_lv, e_rows, diffr, edges, stats, tag, window)
        else:
            rside = _receiver_side(scene, ctx, rx_lv, e_rows, diffr, stats, tag, window)
        for rows, src_rows in _join_chunks(src, rside.dihedron * ctx.key_stride + rside.sector):
            out += _diffraction_candidates(scene, ctx, a, b, rx, rx_lv, rx_offset, stats, grazing, tag,
                                           rside, rows, tside, src_rows, pending)
    return out


def _diffraction_amplitude_bound(ctx: TxContext, phi: np.ndarray, phi_prime: np.ndarray, n: np.ndarray,
                                 te: np.ndarray, de: np.ndarray, tr: np.ndarray, dr: np.ndarray,
                                 t: np.ndarray) -> np.ndarray:
    """(k,) float64 [1/m]: an upper bound on ``|a| / (lambda / 4 pi)`` of diffracted candidates.

    With passive reflections (``|Gamma| <= 1``) before and after the edge and unit antenna
    patterns, a diffracted path's coefficient is at most
    ``(lambda / 4 pi) |D| / sqrt(s s' (s + s'))`` (UTD, spherical incidence; ``s'``, ``s`` the
    unfolded lengths before and after the edge, from the images' reduced coordinates:
    ``s' = hypot(t_e - t, d_e)``, ``s = hypot(t_r - t, d_r)``), with ``|D|`` at most
    :func:`~wavepaths.em.utd.utd_magnitude_bound` at the lowest frequency the fields will
    use (``prune_frequency_hz``; the bound does not grow with frequency). The result carries
    a 1 % margin for the rounding between the search's angles and the fields'.
    """
    from ..em.utd import utd_magnitude_bound
    from ..fields.chain import SIN_BETA_0_FLOOR
    from .paths import SPEED_OF_LIGHT

    k = 2.0 * np.pi * ctx.options.prune_frequency_hz / SPEED_OF_LIGHT
    s_in = np.hypot(te - t, de)
    s_out = np.hypot(tr - t, dr)
    with np.errstate(divide="ignore", invalid="ignore"):
        sin_b = np.maximum(de / s_in, SIN_BETA_0_FLOOR)
        L = s_in * s_out / (s_in + s_out) * sin_b**2
        amp = 1.01 * utd_magnitude_bound(phi, phi_prime, sin_b, n, k, L) / np.sqrt(s_in * s_out * (s_in + s_out))
    return np.where(np.isfinite(amp), amp, np.inf)


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
        (:func:`_diffraction_amplitude_bound`).
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
                            rows: np.ndarray, tside: _EndSide, src_rows: np.ndarray,
                            pending: list | None = None) -> list[PathBatch]:
    """Steps 3-5 of :func:`diffraction_tile` on joined candidates (receiver side ``rside[rows]``,
    transmitter side ``tside[src_rows]``)."""
    dihedra = scene.dihedra
    tx_lv = ctx.levels[a]
    stats[f"{tag}_candidates"] += len(rows)
    if len(rows) == 0:
        return []
    # closed-form point in the reduced coordinates (seed §2.3), then on the segment
    d = rside.dihedron[rows]
    te, de = tside.t[src_rows], tside.rho[src_rows]
    tr, dr = rside.t[rows], rside.rho[rows]
    t = diffraction_point_reduced(te, de, tr, dr)
    on = (t >= 0) & (t <= dihedra.length[d])
    stats[f"{tag}_rejected_off_edge"] += int((~on).sum())
    if tside.visible is not None:
        # order 0: the point lies in a shadow proven from the transmitter (the first leg is
        # blocked); order >= 1: the leg to the last image cannot cross the last mirror
        seen = tside.visible.may_see(src_rows, t, dihedra.length[d])
        stats[f"{tag}_rejected_{'hidden' if a == 0 else 'aperture'}"] += int((on & ~seen).sum())
        on &= seen
    rows, src_rows, d, t = rows[on], src_rows[on], d[on], t[on]
    phi, phi_prime = rside.phi[rows], tside.phi[src_rows]
    sec = rside.sector[rows]
    ok = np.ones(len(rows), dtype=bool)
    if not ctx.options.lit_region:
        shadow = np.abs(phi - phi_prime) > np.pi
        stats[f"{tag}_rejected_lit_region"] += int((~shadow).sum())
        ok &= shadow
    # GO rays within the float32 uncertainty of the edge: the angular distance to the shadow
    # or reflection boundary times the shorter leg
    wedge = ctx.sectors.width[d, sec]
    leg = np.minimum(np.hypot(te[on] - t, de[on]), np.hypot(tr[on] - t, dr[on]))
    offs = np.minimum(np.abs(np.abs(phi - phi_prime) - np.pi), np.abs(phi + phi_prime - np.pi))
    offs = np.minimum(offs, np.abs(phi + phi_prime - (2 * wedge - np.pi)))
    near = (offs * leg < 4 * scene.length_tolerance(scene.tolerances.ray_offset)) & ok
    e, c = rside.row[rows], tside.row[src_rows]
    if near.any():
        grazing[tx_lv.source[c[near]], rx_lv.source[e[near]]] = True
        stats["pairs_on_boundaries"] += int(near.sum())
    e, d, sec, c, t = e[ok], d[ok], sec[ok], c[ok], t[ok]
    amp = None
    if ctx.options.prune_frequency_hz is not None and (ctx.options.prune_db is not None or pending is not None):
        amp = _diffraction_amplitude_bound(ctx, phi[ok], phi_prime[ok], wedge[ok] / np.pi, te[on][ok], de[on][ok],
                                           tr[on][ok], dr[on][ok], t)
    P = dihedra.origin[d] + t[:, None] * dihedra.direction[d]
    # reflections after (receiver images) and before (transmitter images)
    ok2, post, rej2 = backtrace(scene, P, rx_lv, e)
    e, d, sec, c, P = e[ok2], d[ok2], sec[ok2], c[ok2], P[ok2]
    ok1, pre, rej1 = backtrace(scene, P, tx_lv, c)
    e, d, sec, c, P, post = e[ok1], d[ok1], sec[ok1], c[ok1], P[ok1], post[ok1]
    stats[f"{tag}_rejected_segment"] += rej1["segment"] + rej2["segment"]
    stats[f"{tag}_rejected_outside_polygon"] += rej1["outside_polygon"] + rej2["outside_polygon"]
    if amp is not None:
        amp = amp[ok2][ok1]
    if amp is not None and ctx.options.prune_db is not None:
        # pruned after the back-traces, so that the count bounds the paths dropped (not the
        # candidates): before the casts and the fields, which cost the most per path
        direct = np.linalg.norm(rx[rx_lv.source[e]] - ctx.tx[tx_lv.source[c]], axis=1)
        weak = amp * direct < 10 ** (-ctx.options.prune_db / 20)
        stats["pruned_paths_upper_bound"] += int(weak.sum())
        stats[f"{tag}_pruned_candidates"] += int(weak.sum())
        keep = ~weak
        e, d, sec, c, P, pre, post, amp = (e[keep], d[keep], sec[keep], c[keep], P[keep], pre[keep], post[keep],
                                           amp[keep])
    # the true dihedron: the faces bounding the sector (seed §3.3)
    f0 = ctx.sectors.face[d, sec]
    fn = ctx.sectors.face[d, np.mod(sec + 1, ctx.sectors.count[d])]
    post = post[:, ::-1]  # path order after the diffraction
    post_polys = rx_lv.polygons[e][:, ::-1]
    rx_pos = rx[rx_lv.source[e]]
    verts = np.concatenate([tx_lv.images[c, :1], pre, P[:, None, :], post, rx_pos[:, None, :]], axis=1)
    pend = PendingDiffraction(a, b, tx_lv.source[c], rx_lv.source[e], amp, (d, c, f0, fn, verts, post_polys))
    if pending is not None:
        pending.append(pend)
        return []
    return [finish_diffraction(scene, ctx, pend, rx_offset, stats)]


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
    if keep is not None:
        rx_i, d, c, f0, fn, verts, post_polys = (x[keep] for x in (rx_i, d, c, f0, fn, verts, post_polys))
    blocked = _occluded_chains(scene, verts, stats)
    stats[f"{tag}_rejected_occluded"] += int(blocked.sum())
    keep = ~blocked
    rx_i, d, c, f0, fn, verts, post_polys = (x[keep] for x in (rx_i, d, c, f0, fn, verts, post_polys))
    k = len(d)
    kinds = np.full((k, a + 1 + b), InteractionType.REFLECTION, np.int8)
    kinds[:, a] = InteractionType.DIFFRACTION
    prims = np.concatenate([tx_lv.polygons[c], d[:, None], post_polys], axis=1)
    tris = np.concatenate(
        [_triangle_of(scene, tx_lv.polygons[c]), dihedra.face_triangle[f0][:, None], _triangle_of(scene, post_polys)],
        axis=1,
    )
    return PathBatch(tx_lv.source[c], rx_i + rx_offset, kinds, prims, tris, np.stack([f0, fn], axis=1), verts)


def trace_tile(scene: "Scene", ctx: TxContext, rx: np.ndarray, rx_offset: int = 0,
               pending: list | None = None) -> tuple[list[PathBatch], Counter]:
    """All paths of ``ctx.options`` from the context's transmitters to the receivers ``rx``.

    With a ``pending`` list, the diffracted candidates are not cast but appended to it
    (:class:`PendingDiffraction`, see :func:`diffraction_tile`); the other paths are traced.
    """
    opts = ctx.options
    stats: Counter = Counter()
    batches: list[PathBatch] = []
    grazing = np.zeros((len(ctx.tx), len(rx)), dtype=bool)
    if opts.diffraction and len(ctx.diffracting):
        rx_levels = build_image_levels(scene, rx, opts.diffraction_reflections, opts.skip_absorbers,
                                       compiled=None if opts.compiled else False)
        edges = ctx.edges if opts.diffraction_reflections >= 1 and ctx.apertures is not None else None
        for a in range(opts.diffraction_reflections + 1):
            for b in range(opts.diffraction_reflections + 1 - a):
                batches += diffraction_tile(scene, ctx, a, b, rx, rx_levels, rx_offset, stats, grazing, edges,
                                            pending)
    if opts.los:
        batches.append(los_tile(scene, ctx, rx, rx_offset, stats, grazing))
    for k in range(1, opts.max_reflections + 1):
        batches += reflection_tile(scene, ctx, k, rx, rx_offset, stats, grazing)
    return batches, stats
