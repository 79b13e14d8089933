"""Per-receiver work, vectorised over (receivers in a tile x candidates).

Every function here takes the scene, a :class:`~wavepaths.search.context.TxContext`
and a tile of receivers, builds the candidate arrays, applies the tests in order of
cost (segment parameter, point-in-polygon, FindDihedron, occlusion), compacting the
survivors after each test, and casts the surviving segments in one batch. Each test
adds to the ``stats`` counters what it rejected.
"""

from __future__ import annotations

from collections import Counter
from typing import TYPE_CHECKING

import numpy as np

from ..topology.find_dihedron import find_dihedron
from ..topology.sectors import sector_of
from .context import TxContext
from .geometry import diffraction_point_parameter
from .images import ImageLevel, backtrace, build_image_levels
from .paths import InteractionType, PathBatch

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene

CANDIDATE_BUDGET = 1 << 21  # candidates held at once (bounds temporaries to ~100 MB)


def _lift_reflections(scene: "Scene", verts: np.ndarray, polys: np.ndarray, first: int) -> None:
    """Move reflection points (vertices ``first .. first + k - 1``) off their planes, in place.

    Both legs of a reflection lie on one side of the mirror: the point is lifted toward that
    side by ``2 ray_offset``, so that a leg grazing the mirror does not hit it in float32.
    """
    lift = 2 * scene.length_tolerance(scene.tolerances.ray_offset)
    for j in range(polys.shape[1]):
        v = first + j
        n = scene.polygon_normal[polys[:, j]]
        side = np.sign(np.einsum("ij,ij->i", verts[:, v - 1] - verts[:, v], n))
        verts[:, v] += (lift * side)[:, None] * n


def _lift_diffraction(scene: "Scene", points: np.ndarray, dihedron: np.ndarray, face_0: np.ndarray,
                      face_n: np.ndarray) -> np.ndarray:
    """Diffraction points moved off their edge along the bisector of the true dihedron's sector.

    The legs leave the edge inside that sector, possibly grazing one of its faces; starting
    them ``2 ray_offset`` inside the sector keeps float32 casts from hitting those faces.
    """
    dih = scene.dihedra
    w = dih.direction[dihedron]
    x = dih.face_direction[face_0]
    y = np.cross(w, x)
    pn = dih.face_direction[face_n]
    ang = np.mod(np.arctan2(np.einsum("ij,ij->i", pn, y), np.einsum("ij,ij->i", pn, x)), 2 * np.pi)
    ang = np.where(ang < 1e-9, 2 * np.pi, ang)
    bis = np.cos(ang / 2)[:, None] * x + np.sin(ang / 2)[:, None] * y
    return points + 2 * scene.length_tolerance(scene.tolerances.ray_offset) * bis


def _occluded_chains(scene: "Scene", vertices: np.ndarray, stats: Counter, exact: np.ndarray | None = None,
                     cast: np.ndarray | None = None) -> np.ndarray:
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
    cv = vertices if cast is None else cast  # the vertices to cast from (interaction points lifted)
    a = cv[:, :-1].reshape(-1, 3)
    b = cv[:, 1:].reshape(-1, 3)
    blocked = scene.raycaster.occluded(a, b).reshape(k, s - 1)
    stats["rays_cast"] += a.shape[0]
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
    """Specular paths of one order: image method backwards from each receiver."""
    lv = ctx.levels[order]
    c, n = len(lv), len(rx)
    out = []
    if c == 0 or n == 0:
        return out
    step = max(1, CANDIDATE_BUDGET // c)
    tag = f"reflection_order_{order}"
    for s in range(0, n, step):
        r = np.arange(s, min(n, s + step))
        ri = np.repeat(r, c)
        ci = np.tile(np.arange(c), len(r))
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
        cast = verts.copy()
        _lift_reflections(scene, cast, lv.polygons[ci], 1)
        blocked = _occluded_chains(scene, verts, stats, grazing[lv.source[ci], ri], cast)
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
    from .context import DiffractionSources

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
    chain, dih, key = src.chain[keep], src.dihedron[keep], src.key[keep]
    uk, start, count = np.unique(key, return_index=True, return_counts=True)
    return DiffractionSources(chain, dih, key, uk, start.astype(np.int64), count.astype(np.int64))


def _join(src, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each receiver-side key, all transmitter-side sources with the same key.

    Returns the receiver-side row and the transmitter-side row of every match.
    """
    pos = np.searchsorted(src.unique_keys, keys)
    pos = np.clip(pos, 0, max(len(src.unique_keys) - 1, 0))
    hit = len(src.unique_keys) > 0
    match = (src.unique_keys[pos] == keys) if hit else np.zeros(len(keys), bool)
    count = np.where(match, src.key_count[pos] if hit else 0, 0)
    rows = np.repeat(np.arange(len(keys)), count)
    start = np.repeat(np.where(match, src.key_start[pos] if hit else 0, 0), count)
    offs = np.arange(len(rows)) - np.repeat(np.cumsum(count) - count, count)
    return rows, start + offs


def _near_boundary(scene: "Scene", test, P: np.ndarray, E: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Candidates whose geometrical-optics ray passes within the float32 uncertainty of the edge.

    The angular distance to the incident shadow boundary (``|phi - phi'| = pi``) or to a
    reflection boundary (``phi + phi' = pi`` or ``(2n - 1) pi``), times the shorter leg,
    approximates how close the corresponding GO ray passes to the edge.
    """
    delta = 4 * scene.length_tolerance(scene.tolerances.ray_offset)
    phi, pp, wedge = test.phi, test.phi_prime, test.wedge_angle
    leg = np.minimum(np.linalg.norm(E - P, axis=1), np.linalg.norm(R - P, axis=1))
    offs = np.stack([np.abs(phi - pp) - np.pi, phi + pp - np.pi, phi + pp - (2 * wedge - np.pi)], axis=1)
    return (np.abs(offs).min(axis=1) * leg) < delta


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
) -> list[PathBatch]:
    """Diffracted paths with ``a`` reflections before and ``b`` after the diffraction.

    Also marks in ``grazing`` (m, n) the (tx, rx) pairs for which a candidate lies within
    the float32 uncertainty of a shadow or reflection boundary of its edge: the geometrical
    optics paths of those pairs are then cast in float64, so that the UTD field, whose
    boundary terms switch by the float64 angles, stays continuous.

    The diffraction point is found in closed form (seed §2.3) between the transmitter's
    image of order ``a`` and the receiver's image of order ``b``; FindDihedron (seed
    §3.3) checks that the path stays in one topological volume; the reflection points on
    both sides follow by the image method.
    """
    dihedra = scene.dihedra
    tx_lv = ctx.levels[a]
    rx_lv = rx_levels[b]
    tag = f"diffraction_{a}r_{b}r"
    out: list[PathBatch] = []
    if len(rx_lv) == 0 or len(ctx.diffraction_sources[a].chain) == 0:
        return out
    src_all = ctx.diffraction_sources[a]
    step = max(1, CANDIDATE_BUDGET // max(len(np.unique(src_all.dihedron)), 1))
    for s in range(0, len(rx_lv), step):
        e_rows = np.arange(s, min(len(rx_lv), s + step))
        # Keller-cone culling for this chunk of receivers (or receiver images): keep the
        # (source, dihedron) pairs whose diffracted cones can reach the chunk's bounding sphere
        src = _cull_sources_by_keller_cone(dihedra, src_all, tx_lv.last[src_all.chain], rx_lv.last[e_rows])
        stats[f"{tag}_source_pairs_culled_keller_cone"] += len(src_all.chain) - len(src.chain)
        diffr = np.unique(src.dihedron)
        if len(diffr) == 0:
            continue
        e = np.repeat(e_rows, len(diffr))
        d = np.tile(diffr, len(e_rows))
        sec, width = sector_of(ctx.sectors, d, rx_lv.last[e], dihedra.origin[d])
        keep = (sec >= 0) & (width > np.pi + scene.tolerances.coplanar_angle)
        stats[f"{tag}_receiver_pairs"] += len(e)
        stats[f"{tag}_receiver_pairs_rejected_sector"] += int((~keep).sum())
        e, d, sec = e[keep], d[keep], sec[keep]
        rows, src_rows = _join(src, d * ctx.key_stride + sec)
        e, d = e[rows], d[rows]
        c = src.chain[src_rows]
        stats[f"{tag}_candidates"] += len(e)
        if len(e) == 0:
            continue
        # closed-form point on the edge line, then on the segment
        E = tx_lv.last[c]
        R = rx_lv.last[e]
        t = diffraction_point_parameter(E, R, dihedra.origin[d], dihedra.direction[d])
        on = (t >= 0) & (t <= dihedra.length[d])
        stats[f"{tag}_rejected_off_edge"] += int((~on).sum())
        e, d, c, E, R, t = e[on], d[on], c[on], E[on], R[on], t[on]
        P = dihedra.origin[d] + t[:, None] * dihedra.direction[d]
        # FindDihedron: one topological volume, and the true dihedron's faces
        test = find_dihedron(dihedra, d, P, E, R)
        ok = test.valid
        stats[f"{tag}_rejected_find_dihedron"] += int((~ok).sum())
        if not ctx.options.lit_region:
            shadow = np.abs(test.phi - test.phi_prime) > np.pi
            stats[f"{tag}_rejected_lit_region"] += int((ok & ~shadow).sum())
            ok &= shadow
        near = _near_boundary(scene, test, P, E, R) & ok
        if near.any():
            grazing[tx_lv.source[c[near]], rx_lv.source[e[near]]] = True
            stats["pairs_on_boundaries"] += int(near.sum())
        e, d, c, P, f0, fn = e[ok], d[ok], c[ok], P[ok], test.face_0[ok], test.face_n[ok]
        # reflections before (transmitter images) and after (receiver images)
        ok1, pre, rej1 = backtrace(scene, P, tx_lv, c)
        e, d, c, P, f0, fn = e[ok1], d[ok1], c[ok1], P[ok1], f0[ok1], fn[ok1]
        ok2, post, rej2 = backtrace(scene, P, rx_lv, e)
        e, d, c, P, f0, fn, pre = e[ok2], d[ok2], c[ok2], P[ok2], f0[ok2], fn[ok2], pre[ok2]
        stats[f"{tag}_rejected_segment"] += rej1["segment"] + rej2["segment"]
        stats[f"{tag}_rejected_outside_polygon"] += rej1["outside_polygon"] + rej2["outside_polygon"]
        post = post[:, ::-1]  # path order after the diffraction
        post_polys = rx_lv.polygons[e][:, ::-1]
        rx_pos = rx[rx_lv.source[e]]
        verts = np.concatenate([tx_lv.images[c, :1], pre, P[:, None, :], post, rx_pos[:, None, :]], axis=1)
        cast = verts.copy()
        _lift_reflections(scene, cast, tx_lv.polygons[c], 1)
        cast[:, a + 1] = _lift_diffraction(scene, P, d, f0, fn)
        _lift_reflections(scene, cast, post_polys, a + 2)
        blocked = _occluded_chains(scene, verts, stats, None, cast)
        stats[f"{tag}_rejected_occluded"] += int(blocked.sum())
        keep = ~blocked
        e, d, c, f0, fn, verts, post_polys = e[keep], d[keep], c[keep], f0[keep], fn[keep], verts[keep], post_polys[keep]
        k = len(e)
        kinds = np.full((k, a + 1 + b), InteractionType.REFLECTION, np.int8)
        kinds[:, a] = InteractionType.DIFFRACTION
        prims = np.concatenate([tx_lv.polygons[c], d[:, None], post_polys], axis=1)
        tris = np.concatenate(
            [_triangle_of(scene, tx_lv.polygons[c]), dihedra.face_triangle[f0][:, None], _triangle_of(scene, post_polys)],
            axis=1,
        )
        out.append(
            PathBatch(tx_lv.source[c], rx_lv.source[e] + rx_offset, kinds, prims, tris, np.stack([f0, fn], axis=1), verts)
        )
    return out


def trace_tile(scene: "Scene", ctx: TxContext, rx: np.ndarray, rx_offset: int = 0) -> tuple[list[PathBatch], Counter]:
    """All paths of ``ctx.options`` from the context's transmitters to the receivers ``rx``."""
    opts = ctx.options
    stats: Counter = Counter()
    batches: list[PathBatch] = []
    grazing = np.zeros((len(ctx.tx), len(rx)), dtype=bool)
    if opts.diffraction and len(ctx.diffracting):
        rx_levels = build_image_levels(scene, rx, opts.diffraction_reflections, opts.skip_absorbers)
        for a in range(opts.diffraction_reflections + 1):
            for b in range(opts.diffraction_reflections + 1 - a):
                batches += diffraction_tile(scene, ctx, a, b, rx, rx_levels, rx_offset, stats, grazing)
    if opts.los:
        batches.append(los_tile(scene, ctx, rx, rx_offset, stats, grazing))
    for k in range(1, opts.max_reflections + 1):
        batches += reflection_tile(scene, ctx, k, rx, rx_offset, stats, grazing)
    return batches, stats
