"""Wedge diffraction coefficients: UTD (Kouyoumjian-Pathak), Luebbers, Keller GTD, Sionna.

This module is the public face of the wedge diffraction: the uniform coefficients of
Kouyoumjian & Pathak (:func:`kp_coefficients`, Proc. IEEE 62(11), 1974) and Luebbers'
lossy-wedge form (:func:`luebbers_coefficients`, IEEE TAP 32(1), 1984; ITU-R P.526), the
edge diffraction Jones matrices (:func:`diffraction_jones`, and
:func:`diffraction_jones_matrices` with the faces' reflections as 2x2 matrices) and the
bound :func:`utd_magnitude_bound` on ``|D|``. The parts they are built from live beside it
and are re-exported here under their old names:

* :mod:`wavepaths.em.utd_terms`: the transition function ``F``, the boundary offsets and
  the four KP terms (their numerics), :class:`WedgeCoefficients`;
* :mod:`wavepaths.em.wedge_faces`: the faces' reflections (Luebbers' ``R0``, ``Rn`` and the
  edge-fixed reflection matrices), :class:`FaceCoefficients`;
* :mod:`wavepaths.em.gtd`: Keller's GTD coefficient and the seed paper's formulas;
* :mod:`wavepaths.em.sionna_compat`: Sionna RT's coefficients (``"sionna"`` model).

Conventions (``docs/conventions.md``): time factor ``exp(+jwt)``; the wedge's 0-face is at
``phi = 0`` and its n-face at ``phi = n pi`` (exterior angle ``n pi``, ``1 < n <= 2``);
``phi_prime`` is the direction of the source and ``phi`` that of the observer, both from
the 0-face about the edge unit vector ``e`` (right-handed: ``t0 = n0 x e`` points into the
0-face, ``n0`` its normal into free space); ``beta_0`` is the angle between the incident ray
and ``e``. Soft = E parallel to the edge = ``D_s`` (``beta_0`` components); hard = ``D_h``
(``phi`` components).

The diffracted field is ``E^d = J E^i(Q) A(s) exp(-jks)`` with, for UTD and GTD,
``J = diag(-D_s, -D_h)`` acting on ``(E_beta0', E_phi')`` -> ``(E_beta0, E_phi)``, which is
KP's dyadic ``-b0' b0 D_s - phi' phi D_h`` with ``phi' = unit(s' x e)``,
``b0' = s' x phi'``, ``phi = unit(e x s)``, ``b0 = s x phi`` (``s'``, ``s`` the incident and
diffracted propagation directions). For scalar fields (soft ``u = E_z``, hard ``u = H_z``)
this is ``u^d = D u^i(Q) A exp(-jks)``.

The numerics of the four terms (no cancellation, the mean of the one-sided limits exactly
on a boundary) are described in :mod:`wavepaths.em.utd_terms`.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from wavepaths.em.gtd import keller_coefficients, seed_keller_coefficient, seed_scalar_radiance
from wavepaths.em.utd_terms import (
    Array,
    BoundaryOffsets,
    CArray,
    WedgeCoefficients,
    SIN_BETA_0_FLOOR,
    _check_floor,
    _check_r,
    _epsilons,
    _four_terms,
    _prepare,
    boundary_offsets,
    transition_function,
)
from wavepaths.em.wedge_faces import (
    FaceCoefficients,
    edge_fixed_reflection,
    luebbers_face_coefficients,
    wedge_reflection_matrices,
)
from wavepaths.errors import WavepathsError

__all__ = [
    "BoundaryOffsets",
    "FaceCoefficients",
    "WedgeCoefficients",
    "boundary_offsets",
    "diffraction_jones",
    "diffraction_jones_matrices",
    "edge_fixed_reflection",
    "keller_coefficients",
    "kp_coefficients",
    "luebbers_coefficients",
    "luebbers_face_coefficients",
    "seed_keller_coefficient",
    "seed_scalar_radiance",
    "sionna_compat_coefficients",
    "sionna_face_coefficients",
    "transition_function",
    "utd_magnitude_bound",
    "wedge_reflection_matrices",
]

DiffractionModel = Literal["utd", "gtd", "sionna"]
_MODELS: tuple[str, ...] = ("utd", "gtd", "sionna")



# --------------------------------------------------------------------------- UTD / Luebbers
def luebbers_coefficients(
    phi: ArrayLike, phi_prime: ArrayLike, beta_0: ArrayLike, n: ArrayLike, k: ArrayLike,
    L: ArrayLike, r0_s: ArrayLike, r0_h: ArrayLike, rn_s: ArrayLike, rn_h: ArrayLike,
    *, sin_beta_0_floor: float = SIN_BETA_0_FLOOR,
) -> WedgeCoefficients:
    """Luebbers (IEEE TAP 32(1):70-76, 1984) heuristic UTD coefficient, ITU-R P.526 wedge form.

    ::

        D = -e^{-j pi/4}/(2n sqrt(2 pi k) sin b0) [D1 + D2 + R0 D4 + Rn D3]

    with the four KP terms (see :func:`kp_coefficients`). ``R = -1`` (soft) / ``+1`` (hard)
    is KP exactly. ``r*_s`` multiply ``D_s`` and ``r*_h`` ``D_h``; in this package's Jones
    convention (``e_p = e_s x k``, see :mod:`wavepaths.em.fresnel`) these are ``r_te`` and
    ``r_tm`` *without* a sign change: PEC gives ``(-1, +1)``. A convention in which a PEC
    has ``r_parallel = -1`` would need ``R_h = -r_parallel``.
    Use :func:`luebbers_face_coefficients` for Luebbers' angles.

    Parameters
    ----------
    phi, phi_prime : array_like [rad]
        Observer and source directions from the 0-face, in ``[0, n pi]``.
    beta_0 : array_like [rad]
        Angle between incident ray and edge; ``|sin beta_0|`` is floored at
        ``sin_beta_0_floor`` (grazing incidence along the edge, where D diverges).
    n : array_like
        Exterior angle / pi, in ``(1, 2]``.
    k : array_like [rad/m]
        Wavenumber, > 0.
    L : array_like [m]
        Distance parameter (KP Table; plane wave ``s sin^2 beta_0``), >= 0.
    r0_s, r0_h, rn_s, rn_h : complex array_like
        Face reflection coefficients (0-face at D4's reflection boundary, n-face at D3's).
    sin_beta_0_floor : float
        Floor for ``|sin beta_0|`` (default 1e-6: D is at most ~1e6 times its broadside value).

    Returns
    -------
    WedgeCoefficients
        ``(D_s, D_h)`` [sqrt(m)], complex128 of the broadcast shape; finite for finite input.
    """
    _check_floor(sin_beta_0_floor, "sin_beta_0_floor")
    p, pp, b0, nn, kk, ll = _prepare(phi, phi_prime, beta_0, n, k, L)
    d1, d2, d3, d4 = _four_terms(p, pp, b0, nn, kk, ll, sin_beta_0_floor, None)
    rs = _check_r(r0_s, r0_h, rn_s, rn_h)
    base = d1 + d2
    return WedgeCoefficients(base + rs[0] * d4 + rs[2] * d3, base + rs[1] * d4 + rs[3] * d3)


def kp_coefficients(
    phi: ArrayLike, phi_prime: ArrayLike, beta_0: ArrayLike, n: ArrayLike, k: ArrayLike,
    L: ArrayLike, *, sin_beta_0_floor: float = SIN_BETA_0_FLOOR,
) -> WedgeCoefficients:
    """Kouyoumjian & Pathak (Proc. IEEE 62(11):1448-1461, 1974) PEC wedge coefficient.

    ::

        D_{s,h} = -e^{-j pi/4} / (2n sqrt(2 pi k) sin b0) *
                  [ cot((pi+b-)/2n) F(kL a+(b-)) + cot((pi-b-)/2n) F(kL a-(b-))
                    -+ { cot((pi+b+)/2n) F(kL a+(b+)) + cot((pi-b+)/2n) F(kL a-(b+)) } ]
        b-+ = phi -+ phi',  a+-(b) = 2 cos^2((2 n pi N+- - b)/2),  N+- = round((b +- pi)/(2 pi n))

    (upper sign soft). Exactly on a shadow/reflection boundary the singular term takes the
    mean of its one-sided limits (0); see :mod:`wavepaths.em.utd_terms`. Parameters and returns as
    :func:`luebbers_coefficients` (which this is, with ``R = -1`` soft, ``+1`` hard).
    """
    return luebbers_coefficients(
        phi, phi_prime, beta_0, n, k, L, -1.0, 1.0, -1.0, 1.0, sin_beta_0_floor=sin_beta_0_floor
    )


def diffraction_jones_matrices(
    phi: ArrayLike, phi_prime: ArrayLike, beta_0: ArrayLike, n: ArrayLike, k: ArrayLike, L: ArrayLike,
    model: DiffractionModel, g0: ArrayLike, gn: ArrayLike, *, sin_beta_0_floor: float = SIN_BETA_0_FLOOR,
    gtd_floor: float = 1e-12,
) -> CArray:
    """:func:`diffraction_jones` (``"utd"`` or ``"gtd"``) with the faces' reflections as 2x2
    matrices in the edge-fixed bases (:func:`wedge_reflection_matrices`)::

        J = -[(D1 + D2) I + D4 G0 + D3 Gn]

    (``D1..D4`` the four terms with their prefactor, as in :func:`luebbers_coefficients`).
    With ``G0 = diag(r0_s, r0_h)`` and ``Gn = diag(rn_s, rn_h)`` it is ``diag(-D_s, -D_h)``,
    Luebbers; with the full matrices the jump of ``D4`` (``D3``) at the 0-face's (n-face's)
    reflection boundary is the geometrical-optics reflection itself at every ``beta_0``, so
    the total field is continuous there for dielectric faces at oblique incidence too.

    Returns
    -------
    (..., 2, 2) complex128
    """
    if model not in ("utd", "gtd"):
        raise WavepathsError(f"`model` must be 'utd' or 'gtd' here, got {model!r}")
    _check_floor(sin_beta_0_floor, "sin_beta_0_floor")
    _check_floor(gtd_floor, "gtd_floor")
    p, pp, b0, nn, kk, ll = _prepare(phi, phi_prime, beta_0, n, k, L)
    d1, d2, d3, d4 = _four_terms(p, pp, b0, nn, kk, ll, sin_beta_0_floor, None if model == "utd" else gtd_floor)
    G0, Gn = np.asarray(g0, dtype=complex), np.asarray(gn, dtype=complex)
    if not (np.all(np.isfinite(G0)) and np.all(np.isfinite(Gn))):
        raise WavepathsError("face reflection matrices must be finite")
    base = d1 + d2
    out = d4[..., None, None] * G0 + d3[..., None, None] * Gn
    out[..., 0, 0] += base
    out[..., 1, 1] += base
    return -out


def utd_magnitude_bound(
    phi: ArrayLike, phi_prime: ArrayLike, sin_beta_0: ArrayLike, n: ArrayLike, k: ArrayLike, L: ArrayLike,
    *, sin_beta_0_floor: float = SIN_BETA_0_FLOOR,
) -> Array:
    """An upper bound on ``max(|D_s|, |D_h|)`` of the UTD coefficient for passive faces.

    For :func:`luebbers_coefficients` with any face coefficients ``|R| <= 1`` (passive
    materials; KP's ``R = -+1`` included), hence for :func:`diffraction_jones`'s ``"utd"``
    model, whose Jones matrix ``diag(-D_s, -D_h)`` has norm ``max(|D_s|, |D_h|)``, and for
    :func:`diffraction_jones_matrices` (the field chain's), whose face matrices have norms
    ``max(|r_te|, |r_tm|) <= 1``, so that its norm is at most the same sum::

        |D| <= sum_i min(|cot(eps_i / 2n)|, n sqrt(2 pi k L))
               / (2 n sqrt(2 pi k) max(|sin beta_0|, floor))

    Each of the four terms is ``cot(eps/2n) F(2 k L sin^2(eps/2))`` (:mod:`wavepaths.em.utd_terms`), and
    the transition function obeys ``|F(x)| <= min(1, sqrt(pi x))`` (``|F|`` rises
    monotonically from 0 to 1, and ``F(x) ~ sqrt(pi x) e^{j pi/4}`` below; checked on a dense
    grid by the tests), so a term is at most ``|cot(eps/2n)|`` and at most
    ``sqrt(2 pi k L) |cos(eps/2n)| |sin(eps/2) / sin(eps/2n)| <= n sqrt(2 pi k L)`` (as
    ``|sin(n y)| <= n |sin y|``): the bound used is the smaller of ``|cot(eps/2n)|`` and
    ``n sqrt(2 pi k L)``, finite on the boundaries. It does not grow with ``k`` (the first
    form falls as ``k^{-1/2}`` with the prefactor, the second does not depend on it): one
    computed at the lowest frequency holds at every higher one.

    Parameters
    ----------
    phi, phi_prime : array_like [rad]
        Observer and source directions from the 0-face, in ``[0, n pi]``.
    sin_beta_0 : array_like
        ``|sin beta_0|`` of the incident ray on the edge (floored as the coefficients do).
    n : array_like
        Exterior angle / pi, in ``(1, 2]``.
    k : float or array_like [rad/m]
        Wavenumber.
    L : array_like [m]
        Distance parameter (with the same floored ``sin beta_0`` as the coefficients).

    Returns
    -------
    ndarray, float64 [sqrt(m)], the broadcast shape.
    """
    p, pp, sb, nn, kk, ll = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in
                                                 (phi, phi_prime, sin_beta_0, n, k, L)))
    sb = np.maximum(np.abs(sb), sin_beta_0_floor)
    cap = nn * np.sqrt(2.0 * np.pi * kk * ll)
    total = np.zeros(p.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        for eps in _epsilons(p, pp, nn):
            x = eps / (2.0 * nn)
            total += np.minimum(np.abs(np.cos(x)) / np.abs(np.sin(x)), cap)  # 1/0 = inf -> cap
    return total / (2.0 * nn * np.sqrt(2.0 * np.pi * kk) * sb)


# --------------------------------------------------------------------------- Jones matrix
def diffraction_jones(
    phi: ArrayLike, phi_prime: ArrayLike, beta_0: ArrayLike, n: ArrayLike, k: ArrayLike,
    L: ArrayLike, model: DiffractionModel, r0_s: ArrayLike = -1.0, r0_h: ArrayLike = 1.0,
    rn_s: ArrayLike = -1.0, rn_h: ArrayLike = 1.0, *, sin_beta_0_floor: float = SIN_BETA_0_FLOOR,
    gtd_floor: float = 1e-12,
) -> CArray:
    """Edge diffraction Jones matrix ``(E_b0', E_phi')`` at the edge -> ``(E_b0, E_phi)``.

    The diffracted field is ``E^d(s) = J E^i(Q) A(s) exp(-jks)`` (spreading ``A`` and phase
    applied by the caller). Bases as in the module docstring.

    * ``"utd"``: ``diag(-D_s, -D_h)`` with Luebbers' coefficients
      (:func:`luebbers_coefficients`); the default ``R``'s (``-1``, ``+1``) give KP exactly.
    * ``"gtd"``: the same with ``F = 1`` (Keller's non-uniform limit, with the ``R``'s);
      huge but finite on the boundaries (``|sin|`` floored at ``gtd_floor``).
    * ``"sionna"``: :func:`sionna_compat_coefficients`, the ``r*_s``/``r*_h`` being the
      TE/TM slab coefficients at Sionna's angles; a full (generally non-diagonal) matrix.

    Returns
    -------
    (..., 2, 2) complex128
    """
    if model not in _MODELS:
        raise WavepathsError(f"`model` must be one of {_MODELS}, got {model!r}")
    if model == "sionna":
        from .sionna_compat import sionna_compat_coefficients

        return sionna_compat_coefficients(
            phi, phi_prime, beta_0, n, k, L, r0_s, r0_h, rn_s, rn_h, sin_beta_0_floor=sin_beta_0_floor
        )
    if model == "utd":
        d_s, d_h = luebbers_coefficients(
            phi, phi_prime, beta_0, n, k, L, r0_s, r0_h, rn_s, rn_h, sin_beta_0_floor=sin_beta_0_floor
        )
    else:
        _check_floor(sin_beta_0_floor, "sin_beta_0_floor")
        _check_floor(gtd_floor, "gtd_floor")
        p, pp, b0, nn, kk, ll = _prepare(phi, phi_prime, beta_0, n, k, L)
        d1, d2, d3, d4 = _four_terms(p, pp, b0, nn, kk, ll, sin_beta_0_floor, gtd_floor)
        rs = _check_r(r0_s, r0_h, rn_s, rn_h)
        d_s = d1 + d2 + rs[0] * d4 + rs[2] * d3
        d_h = d1 + d2 + rs[1] * d4 + rs[3] * d3
    d_s, d_h = np.broadcast_arrays(d_s, d_h)
    out = np.zeros(d_s.shape + (2, 2), dtype=np.complex128)
    out[..., 0, 0] = -d_s
    out[..., 1, 1] = -d_h
    return out


def __getattr__(name: str):
    # the Sionna RT compat functions live in wavepaths.em.sionna_compat; keep the old names working
    if name in ("sionna_compat_coefficients", "sionna_face_coefficients"):
        from . import sionna_compat

        return getattr(sionna_compat, name)
    raise AttributeError(name)
