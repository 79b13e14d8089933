"""The two ends of a diffracted path, projected on the edges (seed §2.3's reduced coordinates).

The transmitter side (an image of order ``a`` and a dihedron, from the transmitter's
context) and the receiver side (an image of order ``b`` of a receiver of the tile and a
dihedron) are each reduced to the edge's frame: the sector the end lies in, its angle
from the sector's first face, its coordinate ``t`` along the edge and its distance
``rho`` to it. The receiver side is the densest stage of the diffraction search: the
(receiver image, dihedron) pairs are culled by the last mirror's side and beam, the
beams through the mirrors' rectangles and the Keller window (dense, in numpy or as a
compiled kernel, or by edge-tree queries) before their sectors are looked up.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .._vec import dot3
from ..topology.sectors import FACE_ANGLE_TOL, sector_lookup
from . import kernels
from .context import TxContext
from .images import ImageLevel
from .visibility import VisibilityWindows

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene


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

    def take(self, rows: np.ndarray) -> "_EndSide":
        """The rows ``rows``."""
        vis = None if self.visible is None else self.visible.take(rows)
        return _EndSide(self.row[rows], self.dihedron[rows], self.sector[rows], self.phi[rows], self.t[rows],
                        self.rho[rows], vis)


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
    rho = np.sqrt(x * x + y * y)
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
                   stats: Counter, tag: str, window=None, reach=None) -> _EndSide:
    """Step 1 of :func:`diffraction_tile`, dense over (receiver images ``e_rows``) x (dihedra ``diffr``).

    The culling tests are outer products of a per-image and a per-edge vector (matrix
    products on coordinates recentred on the scene centre, so that float64 keeps the
    scene's resolution at any offset), so nothing is gathered per pair for them; the
    sector is then computed per surviving pair, from ``R - A``. Tests:

    * for ``b >= 1`` with ``reach`` (:class:`~wavepaths.search.reach.MirrorReach`),
      *mirror reach*: the dihedron must be in the reach list of the image's last mirror
      (some source's Keller cone reaches that mirror's bounding sphere);
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
    if rx_lv.order == 0:
        reach = None
    if ctx.options.compiled and kernels.available():
        return _receiver_side_compiled(scene, ctx, rx_lv, e_rows, diffr, stats, tag, window, reach)
    dihedra = scene.dihedra
    c0 = scene.center
    I = rx_lv.last[e_rows] - c0  # (E, 3)
    A = dihedra.origin[diffr] - c0  # (D, 3)
    w = dihedra.direction[diffr]
    L = dihedra.length[diffr]
    ok = np.ones((len(e_rows), len(diffr)), dtype=bool)
    disabled = ctx.options.disable_culling
    if reach is not None:
        ok = reach.mask(rx_lv.polygons[e_rows, -1], _columns(scene, diffr), len(diffr))
        stats[f"{tag}_receiver_pairs_rejected_mirror_reach"] += int((~ok).sum())
    if rx_lv.order >= 1 and "receiver_mirror_side" not in disabled:
        n, off, side, tol = _last_mirror_planes(scene, rx_lv, e_rows)
        sa = side[:, None] * (n @ A.T - off[:, None])
        sb = side[:, None] * (n @ (A + L[:, None] * w).T - off[:, None])
        front = np.maximum(sa, sb) > -tol
        stats[f"{tag}_receiver_pairs_rejected_mirror_side"] += int((ok & ~front).sum())
        ok &= front
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


def _columns(scene: "Scene", diffr: np.ndarray) -> np.ndarray:
    """(num_dihedra,) int64: each dihedron's column among ``diffr``, -1 for the others."""
    col = np.full(len(scene.dihedra.length), -1, np.int64)
    col[diffr] = np.arange(len(diffr))
    return col


def _receiver_side_compiled(scene: "Scene", ctx: TxContext, rx_lv: ImageLevel, e_rows: np.ndarray,
                            diffr: np.ndarray, stats: Counter, tag: str, window=None, reach=None) -> _EndSide:
    """:func:`_receiver_side` with the mirror-side, beam and Keller-window tests fused per pair
    (:func:`wavepaths.search.kernels.receiver_pairs`, numba); the same tests and margins, then
    the sector per surviving pair, as the numpy reference does.

    One test more, after the beam (``receiver_aperture``): the edge must meet the beams
    from the image through its mirrors' rectangles (the test of
    :func:`~wavepaths.search.apertures.chain_beams_meet`, which the tree-based receiver side
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
    listed = None
    # (the kernel groups the images by last mirror and side; a parent image on the mirror's
    # plane, side 0, which the image trees never keep, would take the dense kernel)
    if reach is not None and rx_lv.order >= 1 and (mirror is None or bool(np.all(mirror[2] != 0))):
        listed = (rx_lv.polygons[e_rows, -1], reach.ptr, reach.dihedra, _columns(scene, diffr))
    ie, idd, n_mirror, n_beam, n_aperture, n_window, tested = kernels.receiver_pairs(
        I, mirror, A, B, beam, aperture, R, frame, win, listed=listed)
    if listed is not None:
        stats[f"{tag}_receiver_pairs_rejected_mirror_reach"] += len(e_rows) * len(diffr) - tested
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
    x = dot3(v, ctx.sectors.x_hat[d])  # the compiled end_sides' order
    y = dot3(v, ctx.sectors.y_hat[d])
    t = dot3(v, scene.dihedra.direction[d])
    return x, y, t


def _transmitter_side(scene: "Scene", ctx: TxContext, tx_lv: ImageLevel, src) -> _EndSide:
    """Projections of the transmitter-side sources (image, dihedron) on their edges (see :class:`_EndSide`)."""
    d = src.dihedron
    x, y, t = _edge_frame(scene, ctx, tx_lv.last[src.chain], d)
    sec, _, phi = _sector_in_table(ctx, d, x, y)
    return _EndSide(src.chain, d, sec, phi, t, np.sqrt(x * x + y * y), src.visible)
