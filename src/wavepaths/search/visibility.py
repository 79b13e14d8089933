"""Which part of an edge a point source can see: proven shadows, once per transmitter.

A diffracted path ``S -> P -> ...`` whose first leg leaves the transmitter ``S`` needs the
diffraction point ``P`` on the edge to be visible from ``S``. Most edges of a city are
hidden from a transmitter (on Sionna RT's ``munich``, about 88 % of the diffracting
dihedra, by sampling), and every one of them otherwise costs a (receiver, dihedron)
candidate per receiver, cast and rejected. This module finds, per (source, edge) pair, a
*window* ``[lo, hi]`` of the edge parameter ``t`` (metres from the edge origin) outside
which every point is proven hidden, in float64, by the occlusion rule of
:mod:`wavepaths.raycast`; a pair whose window is empty is hidden along its whole edge.

How (:func:`visibility_windows`). Two marches per edge, one from each end. Each step casts
one ray, from ``S`` to a probe just inside the current window end; Embree (float32)
names the first triangle on it, a hint only. The *shadow interval* of that triangle
(:func:`shadow_intervals`: the edge points whose segment from ``S`` crosses the triangle's
interior by a margin, solved exactly as the intersection of four half-lines in ``t``) is
computed in float64; when it covers the window end, the end moves to the far side of
the interval and the march goes on from just beyond that face's nominal shadow;
otherwise (nothing hit, a graze, a face at the probe itself) that end stops. Each step
skips a whole face's shadow, so a wall of a few triangles takes a few steps.

The same half-spaces, with the margins reversed, give the *aperture window* of an image
(:mod:`wavepaths.search.aperture_windows`): where on an edge a leg toward the image can
cross the image's last mirror.

Image sources (``through``). For a transmitter image of order ``a >= 1`` the leg to the
edge starts on the image's last mirror, where the segment from the image crosses the
mirror's plane; the same march runs from the image, within the aperture window, with the
hint rays starting just beyond the mirror and only faces lying wholly beyond the mirror's
plane admitted, each with a check that the leg's start stands off the face's plane by its
tolerance (:func:`_beyond_mirror`). On munich, half of the 794 k order-1 (image, dihedron)
pairs are proven hidden this way (7 s once per transmitter).

What is proven. The shadow intervals are shrunk by margins so that the occlusion rule
blocks every point of them. The shadows of two triangles of one wall meet at their common
edge, where the rule's closed triangles block the segment, but their proven intervals
leave a sliver between them; so a march steps on when the next face's *nominal* shadow
(no margins) reaches back to within ``tau`` (1e-9 of the scene diagonal) of the current
end. A point outside the window is thus proven hidden, or lies within the nominal shadow
of a face (its segment crosses the face's plane within about 1e-9 of its length of the
face's boundary) or within ``tau`` of one: an opening that narrow between two faces
could be skipped, far below the float32 limit the Embree caster already has
(:mod:`wavepaths.raycast`). The end points of each edge are decided by the rule itself
(:attr:`VisibilityWindows.open0`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .geometry import segment_plane_intersection

if TYPE_CHECKING:  # pragma: no cover
    from ..raycast.numpy_caster import ExactSegments
    from ..scene.model import Scene

MAX_ROUNDS = 32
"""March steps per edge end; an end still moving after them stops where it is (conservative)."""


@dataclass(frozen=True)
class VisibilityWindows:
    """Per (source, edge) pair, the part of the edge not proven hidden from the source.

    Attributes
    ----------
    lo, hi : (k,) float64
        The window ``[lo, hi]`` along the edge [m from its origin], within ``[0, L]``.
        Each end is open once it has moved (the shadow that moved it covers it), so
        ``lo >= hi`` when the edge's inside is proven hidden.
    open0, open1 : (k,) bool
        The edge's end point at ``t = 0`` (at ``t = L``) is seen from the source, by the
        occlusion rule itself. An end vertex can be seen while the shadow of a face through
        that vertex hides the rest of the edge (a roof hides its own far edge, whose ends
        touch the roof's plane): the march bridges such an end, and these flags keep it.
    tau : float
        The bridging tolerance [m]: openings narrower than this between proven shadows
        are taken as hidden.
    rays : int
        Rays cast to find them.
    rounds : int
        March steps taken (the longest march).
    """

    lo: np.ndarray
    hi: np.ndarray
    open0: np.ndarray
    open1: np.ndarray
    tau: float
    rays: int
    rounds: int

    @property
    def hidden(self) -> np.ndarray:
        """(k,) bool: the whole edge, its ends included, is proven hidden from the source."""
        return (self.lo >= self.hi) & ~self.open0 & ~self.open1

    def take(self, rows: np.ndarray) -> "VisibilityWindows":
        """The windows of pairs ``rows``."""
        return VisibilityWindows(self.lo[rows], self.hi[rows], self.open0[rows], self.open1[rows], self.tau,
                                 self.rays, self.rounds)

    def bounds(self, L: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(k,) lowest and highest ``t`` that may be visible: the window, widened to an open end."""
        return np.where(self.open0, 0.0, self.lo), np.where(self.open1, L, self.hi)

    def may_see(self, rows: np.ndarray, t: np.ndarray, L: np.ndarray) -> np.ndarray:
        """(k,) bool: the points ``t`` on the edges of pairs ``rows`` (of length ``L``) are not proven hidden.

        Inside the window within ``tau``, or within ``tau`` of an end that is seen.
        """
        lo, hi, tau = self.lo[rows], self.hi[rows], self.tau
        return (((t >= lo - tau) & (t <= hi + tau)) | (self.open0[rows] & (t <= tau))
                | (self.open1[rows] & (t >= L - tau)))


def _side_planes(c: np.ndarray, S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (k, 3, 3) of the planes through ``S`` (k, 3) and each side ``i`` (corners
    ``i``, ``i + 1``) of the triangles ``c`` (k, 3, 3), oriented toward the third corner, all
    recentred alike; and (k,) bool: every plane is defined (``S`` not on a side's line nor in
    the triangle's plane)."""
    sides = np.empty_like(c)
    valid = np.ones(len(c), dtype=bool)
    for i in range(3):
        ci, cj, ck = c[:, i] - S, c[:, (i + 1) % 3] - S, c[:, (i + 2) % 3] - S
        m = np.cross(ci, cj)
        norm = np.linalg.norm(m, axis=1)
        m = m / np.where(norm > 0, norm, 1.0)[:, None]
        orient = np.sign(np.einsum("ij,ij->i", m, ck))
        valid &= (norm > 0) & (orient != 0)
        sides[:, i] = orient[:, None] * m
    return sides, valid


def shadow_intervals(exact: "ExactSegments", S: np.ndarray, tri: np.ndarray, A: np.ndarray, w: np.ndarray,
                     L: np.ndarray, mode: str = "proven") -> tuple[np.ndarray, np.ndarray]:
    """Edge parameters ``t`` whose segment from ``S`` passes through triangle ``tri``.

    Parameters
    ----------
    exact : ExactSegments
        The occlusion rule (triangle planes and tolerances, coordinates recentred on
        ``exact.center``).
    S, A : (k, 3) float64
        Sources and edge origins, recentred.
    tri : (k,) int64
    w : (k, 3) float64
        Unit edge directions.
    L : (k,) float64
        Edge lengths [m].
    mode : {"proven", "nominal"}
        ``proven``: with margins, so that the occlusion rule blocks every ``t`` of the
        interval (below). ``nominal``: the crossing anywhere in the closed triangle, used
        only to tell whether two shadows abut.

    Returns
    -------
    lo, hi : (k,) float64
        ``[lo, hi]`` within ``[0, L]``; ``lo > hi`` when empty.

    Notes
    -----
    With ``E(t) = A + t w``, ``s_S = n.S - o`` the source's signed distance to the
    triangle's plane and ``tol`` its plane tolerance, the segment ``S -> E(t)`` crosses the
    triangle's interior when (each condition linear in ``t``):

    * ``|s_S| > 4 tol`` and ``sign(s_S) (n.E(t) - o) <= -2 tol`` (it crosses the plane,
      both ends beyond the tolerance);
    * for each side ``i`` of the triangle, with ``m_i`` the unit normal of the plane
      through ``S`` and that side, oriented toward the third corner:
      ``m_i.(E(t) - S) >= eps D``, ``D = max(|A - S|, |E(L) - S|)``.

    The crossing point ``X`` is then inside each side by at least ``eps |X - S| >= eps |s_S|``
    (its distance to the side's line is at least its distance to the plane through ``S``),
    and ``eps = max(1e-9, 2 (tol + edge_tol) / |s_S|)`` puts it clear of the rule's edge
    tolerance and of its grazing case, so every ``t`` of the interval is blocked by the
    rule itself. The nominal interval drops the margin inside the sides (``eps = 0``) and
keeps the plane's, so that a face whose plane holds the edge (a roof beside its own top
edge) shadows nothing.
    """
    k = len(tri)
    lo, hi = np.zeros(k), L.astype(np.float64).copy()
    if k == 0:
        return lo, hi
    c = exact.corners[tri]
    n, off, tol = exact.normal[tri], exact.offset[tri], exact.tol[tri]
    s_s = np.einsum("ij,ij->i", n, S) - off
    sigma = np.sign(s_s)
    valid = np.abs(s_s) > 4 * tol
    B = A + L[:, None] * w
    dmax = np.maximum(np.linalg.norm(A - S, axis=1), np.linalg.norm(B - S, axis=1))
    with np.errstate(divide="ignore", invalid="ignore"):
        eps = np.maximum(1e-9, 2 * (tol + exact.edge_tol) / np.abs(s_s))
    if mode == "nominal":
        eps = np.zeros_like(eps)
    elif mode != "proven":
        raise ValueError(f"unknown mode {mode!r}")
    alphas = [-sigma * (np.einsum("ij,ij->i", n, A) - off) - 2 * tol]
    betas = [-sigma * np.einsum("ij,ij->i", n, w)]
    sides, ok = _side_planes(c, S)
    valid &= ok
    for i in range(3):
        alphas.append(np.einsum("ij,ij->i", sides[:, i], A - S) - eps * dmax)
        betas.append(np.einsum("ij,ij->i", sides[:, i], w))
    alpha, beta = np.stack(alphas, axis=1), np.stack(betas, axis=1)  # alpha + beta t >= 0
    with np.errstate(divide="ignore", invalid="ignore"):
        root = -alpha / beta
    lo = np.maximum(lo, np.where(beta > 0, root, -np.inf).max(axis=1))
    hi = np.minimum(hi, np.where(beta < 0, root, np.inf).min(axis=1))
    valid &= ~((beta == 0) & (alpha < 0)).any(axis=1)
    valid &= np.isfinite(lo) & np.isfinite(hi)
    return np.where(valid, lo, np.inf), np.where(valid, hi, -np.inf)


def both_shadow_intervals(exact: "ExactSegments", S: np.ndarray, tri: np.ndarray, A: np.ndarray, w: np.ndarray,
                          L: np.ndarray, compiled: bool = False) -> tuple[np.ndarray, ...]:
    """:func:`shadow_intervals` in both modes: ``(proven lo, proven hi, nominal lo, nominal hi)``.

    ``compiled``: pair by pair in :func:`wavepaths.search._numba_windows.shadow_intervals`
    (the numpy function is its reference), without the (k, 4) temporaries of each mode.
    """
    if not compiled:
        return (*shadow_intervals(exact, S, tri, A, w, L), *shadow_intervals(exact, S, tri, A, w, L, mode="nominal"))
    from ._numba_windows import shadow_intervals as kernel

    k = len(tri)
    out = [np.empty(k) for _ in range(4)]
    c = np.ascontiguousarray
    kernel(exact.corners, exact.normal, exact.offset, exact.tol, float(exact.edge_tol), c(S, dtype=np.float64),
           c(tri, dtype=np.int64), c(A, dtype=np.float64), c(w, dtype=np.float64), c(L, dtype=np.float64), *out)
    return tuple(out)


def visibility_windows(scene: "Scene", S: np.ndarray, d: np.ndarray, max_rounds: int = MAX_ROUNDS,
                       start: tuple[np.ndarray, np.ndarray] | None = None,
                       through: np.ndarray | None = None, compiled: bool | None = None) -> VisibilityWindows:
    """The part of edge ``d[i]`` not proven hidden from the point ``S[i]`` (see the module docstring).

    Parameters
    ----------
    scene : Scene
    S : (k, 3) float64
        Source points [m] (a transmitter, or any point whose first leg goes to the edge).
    d : (k,) int64
        Dihedra.
    max_rounds : int
        March steps per edge end.
    start : ((k,), (k,)) float64, optional
        The windows to start from (``[lo, hi]`` in metres along the edge; default the whole
        edge): the result lies within them, and an edge end outside them (by more than
        ``tau``) is never open.
    through : (k,) int64, optional
        For image sources (order >= 1): the polygon of each source's last mirror. The leg
        to the edge then starts on that mirror, where the segment ``S -> E`` crosses its
        plane, and only what lies beyond the mirror can block it (see
        :func:`_beyond_mirror`): the hint rays start there, and a face is used only when
        all of it lies beyond the mirror's plane and the leg's start is proven off the
        face's plane. The ends are decided by the occlusion rule on the leg from the
        mirror's plane (an end whose segment from ``S`` does not cross it is kept open).
    compiled : bool, optional
        The shadow intervals pair by pair (:func:`both_shadow_intervals`): by default when
        numba is installed; ``False`` runs the numpy reference.

    Returns
    -------
    VisibilityWindows
        With a caster that gives no first-triangle hints (the numpy caster), every
        window is the starting one.
    """
    S = np.asarray(S, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(d, dtype=np.int64)
    dihedra = scene.dihedra
    L = dihedra.length[d].astype(np.float64)
    if start is None:
        lo, hi = np.zeros(len(d)), L.copy()
    else:
        lo, hi = np.array(start[0], dtype=np.float64), np.array(start[1], dtype=np.float64)
    caster = scene.raycaster
    from . import kernels

    use_kernel = compiled is not False and kernels.available()
    first = getattr(caster, "first_triangle", None)
    exact = getattr(caster, "exact", None)
    tau = scene.length_tolerance(1e-9)
    seen = np.ones(len(d), dtype=bool)
    if first is None or exact is None or len(d) == 0:
        return VisibilityWindows(lo, hi, seen, seen.copy(), tau, 0, 0)
    c0 = exact.center
    Sr, A, w = S - c0, dihedra.origin[d] - c0, dihedra.direction[d]
    if through is not None:
        pn = scene.polygon_normal[through]
        po = scene.polygon_offset[through] - pn @ c0
        dmax = np.maximum(np.linalg.norm(A - Sr, axis=1), np.linalg.norm(A + L[:, None] * w - Sr, axis=1))
    step = 2 * tau
    moving = np.ones((2, len(d)), dtype=bool)  # left end, right end
    reach_l, reach_r = lo.copy(), hi.copy()  # nominal extent of the shadows that moved each end
    rays = rounds = 0

    def hint_intervals(idx: np.ndarray, probe: np.ndarray):
        """The shadow intervals (proven, nominal) on the edges ``idx`` of the first face the
        hint ray toward each probe meets (empty where it meets none that may prove one)."""
        nonlocal rays
        E = A[idx] + probe[:, None] * w[idx]
        if through is None:
            tri = first(S[idx], E + c0)
        else:  # from just beyond the mirror, where the leg starts
            X, _ = _mirror_crossing(Sr[idx], E, pn[idx], po[idx])
            tri = first(X + MIRROR_STEP * (E - X) + c0, E + c0)
        rays += len(idx)
        hit = tri >= 0
        s_lo, s_hi = np.full(len(idx), np.inf), np.full(len(idx), -np.inf)
        n_lo, n_hi = s_lo.copy(), s_hi.copy()
        if through is not None and hit.any():
            h = np.nonzero(hit)[0]
            hit[h] = _beyond_mirror(exact, tri[h], Sr[idx[h]], pn[idx[h]], po[idx[h]], dmax[idx[h]])
        if hit.any():
            h = np.nonzero(hit)[0]
            args = (exact, Sr[idx[h]], tri[h], A[idx[h]], w[idx[h]], L[idx[h]])
            s_lo[h], s_hi[h], n_lo[h], n_hi[h] = both_shadow_intervals(*args, compiled=use_kernel)
        return s_lo, s_hi, n_lo, n_hi

    def advance(il: np.ndarray, ir: np.ndarray, depth: float) -> tuple[np.ndarray, np.ndarray]:
        """One step of the left ends ``il`` and the right ends ``ir``, probing ``depth`` inside
        the extent of the shadows that moved them; (bool, bool) which moved."""
        idx = np.concatenate([il, ir])
        probe = np.concatenate([np.minimum(reach_l[il] + depth, hi[il]), np.maximum(reach_r[ir] - depth, lo[ir])])
        s_lo, s_hi, n_lo, n_hi = hint_intervals(idx, probe)
        nl = len(il)
        # left end: the face's nominal shadow reaches back to it (within tau), its proven
        # shadow beyond the probe; the end moves to the far side of the proven shadow
        adv_l = (n_lo[:nl] <= reach_l[il] + tau) & (s_hi[:nl] >= probe[:nl])
        lo[il[adv_l]] = s_hi[:nl][adv_l]
        reach_l[il[adv_l]] = np.maximum(n_hi[:nl], s_hi[:nl])[adv_l]
        adv_r = (n_hi[nl:] >= reach_r[ir] - tau) & (s_lo[nl:] <= probe[nl:])
        hi[ir[adv_r]] = s_lo[nl:][adv_r]
        reach_r[ir[adv_r]] = np.minimum(n_lo[nl:], s_lo[nl:])[adv_r]
        return adv_l, adv_r

    for rounds in range(1, max_rounds + 1):
        moving &= (lo < hi)[None, :]
        il, ir = np.nonzero(moving[0])[0], np.nonzero(moving[1])[0]
        if len(il) + len(ir) == 0:
            rounds -= 1
            break
        adv_l, adv_r = advance(il, ir, step)
        # an end whose hint ray passed a corner of two faces within float32's reach may have
        # been given the face whose shadow ends there: once more, deeper (a hint only; the
        # same rule proves the shadow)
        il2, ir2 = il[~adv_l], ir[~adv_r]
        il2, ir2 = il2[lo[il2] < hi[il2]], ir2[lo[ir2] < hi[ir2]]
        none = np.zeros(0, dtype=bool)
        adv_l2, adv_r2 = advance(il2, ir2, RETRY_DEPTH * tau) if len(il2) + len(ir2) else (none, none)
        moving[0, il2[~adv_l2]] = False
        moving[1, ir2[~adv_r2]] = False
    ends = np.concatenate([dihedra.origin[d], dihedra.origin[d] + L[:, None] * w])
    if through is None:
        open_ends = ~caster.occluded(np.concatenate([S, S]), ends)
    else:  # the leg from the mirror's plane; kept open where the segment does not cross it
        pn2, po2 = np.concatenate([pn, pn]), np.concatenate([po, po])
        X, crosses = _mirror_crossing(np.concatenate([Sr, Sr]), ends - c0, pn2, po2)
        # an end within tau of the mirror's own plane (an edge of the mirror or of a face
        # coplanar with it) is its own crossing point, up to rounding: the leg is no longer
        # than about tau over the sine of its grazing angle, and is kept open (a window only
        # proves hidden; the tiles cast every leg, launched samples included) instead of
        # being cast in float64
        in_plane = np.abs(np.einsum("ij,ij->i", ends - c0, pn2) - po2) <= tau
        cast = np.nonzero(crosses & ~in_plane)[0]
        open_ends = np.ones(len(ends), dtype=bool)
        open_ends[cast] = ~caster.occluded(X[cast] + c0, ends[cast])
    if start is not None:  # an end outside the starting window stays outside
        open_ends &= np.concatenate([np.asarray(start[0]) <= tau, np.asarray(start[1]) >= L - tau])
    rays += 2 * len(d)
    return VisibilityWindows(lo, hi, open_ends[: len(d)], open_ends[len(d):], tau, rays, rounds)


RETRY_DEPTH = 1e3
"""A march end whose first hint fails is probed once more this many ``tau`` inside (1e-6 of
the scene diagonal): past a corner where the float32 hint names the face whose shadow ends
there, not the next one (a slit's side face behind its wall, tests/search/test_visibility.py)."""

MIRROR_STEP = 1e-4
"""Where an image source's hint ray starts: this fraction of the leg beyond the mirror's
plane, clear of the mirror in float32 (a hint only: a face skipped is a shadow not used)."""


def _mirror_crossing(S: np.ndarray, E: np.ndarray, n: np.ndarray, off: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the segments ``S -> E`` (k, 3) cross the planes ``n.x = off``: points (k, 3), and
    (k,) bool whether they cross strictly between their ends
    (:func:`~wavepaths.search.geometry.segment_plane_intersection`)."""
    X, t = segment_plane_intersection(S, E, n, off)
    return X, (t > 0) & (t < 1)


def _beyond_mirror(exact: "ExactSegments", tri: np.ndarray, S: np.ndarray, pn: np.ndarray, po: np.ndarray,
                   dmax: np.ndarray) -> np.ndarray:
    """(k,) bool: triangle ``tri`` may prove a shadow for the leg of image ``S`` (recentred)
    that starts on the mirror plane ``pn.x = po`` (image sources, ``through``).

    The leg runs from ``X`` on the mirror's plane to ``E`` on the edge, along the segment
    ``S -> E``. If every corner of the triangle lies beyond that plane (on the side away
    from ``S``) by ``delta > 0``, the crossing ``Y`` of ``S -> E`` with the triangle, which
    the proven shadow puts inside it, lies beyond ``X``: ``Y`` is on the leg. The rule also
    needs ``X`` off the triangle's plane by its tolerance ``tol``: along the segment the
    signed distance to that plane falls linearly from ``s_S`` at ``S`` to 0 at ``Y``, so at
    ``X`` it is ``|s_S| |XY| / |SY|``, with ``|XY| >= delta`` and ``|SY| <= dmax`` (the
    farther edge end from ``S``); ``|s_S| delta > 4 tol dmax`` makes it at least ``4 tol``.
    """
    c = exact.corners[tri]  # (k, 3, 3), recentred like S
    side = np.sign(np.einsum("ij,ij->i", pn, S) - po)
    delta = (-side[:, None] * (np.einsum("kcj,kj->kc", c, pn) - po[:, None])).min(axis=1)
    s_s = np.abs(np.einsum("ij,ij->i", exact.normal[tri], S) - exact.offset[tri])
    return (side != 0) & (delta > 0) & (s_s * delta > 4 * exact.tol[tri] * dmax)
