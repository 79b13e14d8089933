"""Where on an edge a leg toward an image can cross the image's last mirror: aperture windows.

A diffracted path whose source is a transmitter image of order ``a >= 1`` leaves the image's
last mirror toward the edge, so only the edge points whose segment from the image crosses
that mirror's polygon can carry it. :func:`aperture_windows` gives, per (image, edge) pair,
the window ``[lo, hi]`` of the edge parameter outside which no such crossing exists: the
half-spaces of :func:`wavepaths.search.visibility.shadow_intervals` (the frustum from the
image through each of the mirror's triangles) with their margins reversed, a superset, so
nothing is lost. :func:`chain_aperture_windows` does the same through every mirror of a
chain, unfolded. The windows then bound the visibility march of
:func:`wavepaths.search.visibility.visibility_windows` (``through``).

Split from :mod:`wavepaths.search.visibility` (the shadow side of the same half-spaces).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .visibility import _side_planes

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene

APERTURE_MAX_TRIANGLES = 16
"""Mirrors with more triangles than this get no aperture window (the whole edge)."""


@dataclass(frozen=True)
class AperturePlanes:
    """The expanded frusta from images through their last mirrors' triangles.

    Row ``r`` of the CSR ``ptr`` (one per image) lists the image's triangles; each
    (image, triangle) gives four half-spaces in recentred coordinates, those of
    :func:`~wavepaths.search.visibility.shadow_intervals` with the margins reversed (a superset): the edge point ``E``
    beyond the mirror's plane or within its plane tolerance, ``N_0.E + O_0 >= 0``; and
    inside each side's plane through the image within an angle,
    ``N_i.E + O_i - eps D >= 0`` (``D`` the farthest edge end from the image).

    Attributes
    ----------
    ptr : (k + 1,) int64
    N : (r, 4, 3) float64
    O : (r, 4) float64
    eps : (r,) float64
        The sides' angular margin, ``-1e-7 (1 + diag / |s_I|)`` (``s_I`` the image's
        distance to the triangle's plane): the back-trace's barycentric margin (1e-9)
        puts its crossing at most about ``1e-9 diag`` outside a side, which is at most
        ``1e-9 diag / |s_I|`` in angle seen from the image.
    valid : (r,) bool
    whole : (k,) bool
        Images whose mirror has too many triangles: their window is the whole edge.
    I : (k, 3) float64
        The images, recentred.
    center : (3,) float64
    """

    ptr: np.ndarray
    N: np.ndarray
    O: np.ndarray
    eps: np.ndarray
    valid: np.ndarray
    whole: np.ndarray
    I: np.ndarray
    center: np.ndarray


def aperture_planes(scene: "Scene", I: np.ndarray, q: np.ndarray, unfold: np.ndarray | None = None) -> AperturePlanes | None:
    """:class:`AperturePlanes` of images ``I`` (k, 3) through their mirrors ``q`` (k,); ``None`` without the float64 rule.

    ``unfold`` (k,): the mirrors ``q`` are taken mirrored across the plane of polygon
    ``unfold[i]`` (their images in the unfolded path: see :func:`chain_aperture_windows`)."""
    exact = getattr(scene.raycaster, "exact", None)
    if exact is None:
        return None
    ptr_q = scene.polygon_tri_ptr
    count = ptr_q[q + 1] - ptr_q[q]
    whole = count > APERTURE_MAX_TRIANGLES
    count = np.where(whole, 0, count)
    ptr = np.concatenate([[0], np.cumsum(count)]).astype(np.int64)
    rows = np.repeat(np.arange(len(q)), count)
    offs = np.arange(len(rows)) - np.repeat(ptr[:-1], count)
    tri = scene.polygon_tris[ptr_q[q[rows]] + offs]
    c0 = exact.center
    S = I[rows] - c0
    c = exact.corners[tri]
    n, off, tol = exact.normal[tri], exact.offset[tri], exact.tol[tri]
    if unfold is not None:
        # x -> x - 2 (nL.x - dL) nL (recentred); a plane n.x = o becomes
        # (n - 2 (n.nL) nL).x = o - 2 (n.nL) dL
        nL = scene.polygon_normal[unfold[rows]]
        dL = scene.polygon_offset[unfold[rows]] - nL @ c0
        c = c - 2 * (np.einsum("kij,kj->ki", c, nL) - dL[:, None])[..., None] * nL[:, None, :]
        dot = np.einsum("ij,ij->i", n, nL)
        n = n - 2 * dot[:, None] * nL
        off = off - 2 * dot * dL
    s_s = np.einsum("ij,ij->i", n, S) - off
    sigma = np.sign(s_s)
    valid = s_s != 0
    N = np.empty((len(rows), 4, 3))
    O = np.empty((len(rows), 4))
    N[:, 0] = -sigma[:, None] * n
    O[:, 0] = sigma * off + tol
    sides, ok = _side_planes(c, S)
    valid &= ok
    N[:, 1:] = sides
    O[:, 1:] = -np.einsum("kij,kj->ki", sides, S)
    with np.errstate(divide="ignore", invalid="ignore"):
        eps = -1e-7 * (1 + exact.diagonal / np.abs(s_s))
    return AperturePlanes(ptr, N, O, np.where(valid, eps, 0.0), valid, whole, I - c0, c0)


def windows_through(scene: "Scene", planes: AperturePlanes, image: np.ndarray, d: np.ndarray,
                    compiled: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Per (image row ``image[i]`` of ``planes``, dihedron ``d[i]``), the aperture window on the edge.

    Returns ``lo, hi`` (k,): the hull over the mirror's triangles of the ``t`` in
    ``[0, L]`` satisfying their four half-spaces, widened by ``1e-9`` of the scene diagonal;
    ``lo > hi`` when empty (see :func:`aperture_windows`). ``compiled``: pair by pair in
    :func:`wavepaths.search._numba_windows.windows_through` (this code is its reference).
    """
    dihedra = scene.dihedra
    if compiled:
        from ._numba_windows import windows_through as kernel

        k = len(d)
        lo, hi = np.empty(k), np.empty(k)
        c = np.ascontiguousarray
        kernel(planes.ptr, planes.N, planes.O, planes.eps, planes.valid, planes.whole, c(planes.I),
               c(planes.center, dtype=np.float64), c(image, dtype=np.int64), c(d, dtype=np.int64), dihedra.origin,
               dihedra.direction, dihedra.length.astype(np.float64), float(scene.length_tolerance(1e-9)), lo, hi)
        return lo, hi
    L = dihedra.length[d].astype(np.float64)
    k = len(d)
    lo, hi = np.zeros(k), L.copy()
    if k == 0:
        return lo, hi
    count = planes.ptr[image + 1] - planes.ptr[image]
    sel = np.nonzero(~planes.whole[image])[0]
    c = count[sel]
    pair = np.repeat(sel, c)
    row = np.repeat(planes.ptr[image[sel]], c) + (np.arange(len(pair)) - np.repeat(np.cumsum(c) - c, c))
    A = dihedra.origin[d] - planes.center
    w = dihedra.direction[d]
    B = A + L[:, None] * w
    # D: the farthest edge end from the image, for the angular margin
    Ii = planes.I[image]
    D = np.maximum(np.linalg.norm(A - Ii, axis=1), np.linalg.norm(B - Ii, axis=1))
    N = planes.N[row]
    alpha = np.einsum("rij,rj->ri", N, A[pair]) + planes.O[row]
    beta = np.einsum("rij,rj->ri", N, w[pair])
    alpha[:, 1:] -= (planes.eps[row] * D[pair])[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        root = -alpha / beta
    t_lo = np.maximum(0.0, np.where(beta > 0, root, -np.inf).max(axis=1))
    t_hi = np.minimum(L[pair], np.where(beta < 0, root, np.inf).min(axis=1))
    ok = planes.valid[row] & ~((beta == 0) & (alpha < 0)).any(axis=1)
    t_lo, t_hi = np.where(ok, t_lo, np.inf), np.where(ok, t_hi, -np.inf)
    w_lo, w_hi = np.full(k, np.inf), np.full(k, -np.inf)
    np.minimum.at(w_lo, pair, t_lo)
    np.maximum.at(w_hi, pair, t_hi)
    tau = scene.length_tolerance(1e-9)
    lo[sel] = np.maximum(w_lo[sel] - tau, 0.0)
    hi[sel] = np.minimum(w_hi[sel] + tau, L[sel])
    return lo, hi


def chain_aperture_windows(scene: "Scene", images: np.ndarray, mirrors: np.ndarray, chain: np.ndarray, d: np.ndarray,
                           compiled: bool | None = None, previous: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`aperture_windows` of pairs (chain ``chain[i]``, dihedron ``d[i]``), for chains
    with last images ``images`` (n, 3) and last mirrors ``mirrors`` (n,): the same windows,
    with each chain's :class:`AperturePlanes` built once for all its pairs (not once per
    pair), then the windows pair by pair, compiled when numba is installed (``compiled``:
    ``None`` by default, ``False`` the numpy reference).

    ``previous`` (n,): the mirror before the last one, for chains of order 2 or more. The
    path ``... -> X_p (on p) -> X_q (on q) -> E`` unfolds across ``q`` into a straight line
    from the last image through ``X_q`` and through ``X_p'``, the image of ``X_p`` across
    ``q``'s plane, which lies in ``p'``, the image of ``p``: so the edge point ``E`` must also
    lie in the aperture of the last image through ``p'`` (:func:`aperture_planes` with
    ``unfold``), beyond ``p'``. The window is then the intersection of the two (each a
    superset of what the back-trace accepts on its mirror, so their intersection is one of
    what it accepts on both)."""
    from . import kernels

    chain = np.asarray(chain, dtype=np.int64)
    d = np.asarray(d, dtype=np.int64)
    u, inv = np.unique(chain, return_inverse=True)
    I = np.asarray(images, dtype=np.float64)[u]
    q = np.asarray(mirrors, dtype=np.int64)[u]
    planes = aperture_planes(scene, I, q)
    if planes is None:
        L = scene.dihedra.length[d].astype(np.float64)
        return np.zeros(len(d)), L.copy()
    use = compiled is not False and kernels.available()
    inv = inv.astype(np.int64)
    lo, hi = windows_through(scene, planes, inv, d, compiled=use)
    if previous is not None:
        unfolded = aperture_planes(scene, I, np.asarray(previous, dtype=np.int64)[u], unfold=q)
        lo2, hi2 = windows_through(scene, unfolded, inv, d, compiled=use)
        lo, hi = np.maximum(lo, lo2), np.minimum(hi, hi2)
    return lo, hi


def aperture_windows(scene: "Scene", I: np.ndarray, q: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where on edge ``d[i]`` a leg toward the image ``I[i]`` can cross its mirror ``q[i]``.

    For the image method, the leg from a point ``E(t)`` of the edge to the image ``I`` of
    the mirror ``q`` next to the edge must cross ``q``'s plane inside ``q``. The edge
    parameters for which it does form an interval per triangle of ``q`` (the half-spaces
    of :class:`AperturePlanes`: a superset of what the back-trace accepts, whose
    barycentric margin is 1e-9), hulled over the triangles.

    Parameters
    ----------
    scene : Scene
    I : (k, 3) float64
        Images [m].
    q : (k,) int64
        Their last mirrors (polygons).
    d : (k,) int64
        Dihedra.

    Returns
    -------
    lo, hi : (k,) float64
        The window, widened by ``1e-9`` of the scene diagonal; ``lo > hi`` when no point of
        the edge can reach the mirror (the pair carries no path). Mirrors with more than
        :data:`APERTURE_MAX_TRIANGLES` triangles, or a caster without the float64 rule,
        give the whole edge.
    """
    planes = aperture_planes(scene, np.asarray(I, dtype=np.float64).reshape(-1, 3), np.asarray(q, dtype=np.int64))
    if planes is None:
        L = scene.dihedra.length[d].astype(np.float64)
        return np.zeros(len(d)), L.copy()
    return windows_through(scene, planes, np.arange(len(d)), np.asarray(d, dtype=np.int64))
