"""Wedge diffraction coefficients: UTD (Kouyoumjian-Pathak), Luebbers, Keller GTD, Sionna.

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

Numerics. Each of the four terms ``cot((pi +- beta)/2n) F(kL a^{+-}(beta))`` equals
``cot(eps/2n) F(2kL sin^2(eps/2))`` with ``eps = pi +- beta - 2 pi n N^{+-}`` in
``[-n pi, n pi]`` (``eps = 0`` on the shadow or reflection boundary of that term). It is
evaluated as ``sgn(eps) n sqrt(2kL) cos(eps/2n) [sinc(eps/2pi)/sinc(eps/2n pi)]
G(2kL sin^2(eps/2))`` with ``G(x) = F(x)/sqrt(x)``, which has no cancellation and no
0 * inf anywhere; at ``eps = 0`` exactly it is 0, the mean of the one-sided limits
``+-n sqrt(2 pi kL) e^{j pi/4}`` (the boundary limit of KP 1974), to pair with a GO weight
of 1/2 exactly on the boundary.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import erfcx

from wavepaths._vec import dot3, unit_cross
from wavepaths.em.fresnel import ReflectionModel, reflection_coefficients
from wavepaths.em.materials import Material
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

Array = NDArray[np.float64]
CArray = NDArray[np.complex128]

_E_PI4 = np.exp(0.25j * np.pi)
# From this argument on F(x) is taken from its asymptotic series (_f_series), which is more
# accurate there than the Faddeeva form (about 1e-16 against 5e-15 relative, checked with mpmath)
_F_SERIES_X = 100.0


class WedgeCoefficients(NamedTuple):
    """Scalar wedge diffraction coefficients ``(D_s, D_h)`` [sqrt(m)], complex arrays."""

    d_s: CArray
    d_h: CArray


class FaceCoefficients(NamedTuple):
    """Face reflection coefficients for the diffraction coefficient, complex arrays.

    For Luebbers: ``r0_s, r0_h`` (0-face) and ``rn_s, rn_h`` (n-face), the soft ones being
    ``r_te`` and the hard ones ``r_tm`` of :mod:`wavepaths.em.fresnel`. For the Sionna
    compat mode the same fields hold ``r_te``/``r_tm`` at Sionna's angles.
    """

    r0_s: CArray
    r0_h: CArray
    rn_s: CArray
    rn_h: CArray


# --------------------------------------------------------------------------- transition function
def _f_series(x: Array) -> CArray:
    """F(x) for x >= 100 by its asymptotic series, to 12 terms.

    Integrating ``int_a^inf e^{-j t^2} dt`` by parts gives ``F(x) ~ sum_m (2m - 1)!! (j u)^m``
    with ``u = 1/(2x)``: ``1 + j/(2x) - 3/(4x^2) - 15j/(8x^3) + ...``. The terms fall while
    ``2m + 1 < 2x``; the first one left out, ``23!! u^12``, is below 8e-17 at x = 100.
    Real and imaginary parts are the even and odd terms, polynomials in ``u^2`` (Horner;
    :func:`wavepaths.fields._numba.f_series` is the same polynomial).
    """
    u = 0.5 / x
    v = u * u
    re = 1.0 + v * (-3.0 + v * (105.0 + v * (-10395.0 + v * (2027025.0 + v * -654729075.0))))
    im = u * (1.0 + v * (-15.0 + v * (945.0 + v * (-135135.0 + v * (34459425.0 + v * -13749310575.0)))))
    return re + 1j * im


def _g(x: Array) -> CArray:
    """G(x) = F(x)/sqrt(x) for x >= 0: e^{j pi/4} sqrt(pi) erfcx(e^{j pi/4} sqrt(x)) below
    x = 100, ``_f_series(x) / sqrt(x)`` from there on.

    Uses erfcx(z) = exp(z^2) erfc(z) with z^2 = jx, so exp(jx) erfc(z) = erfcx(z) exactly.
    """
    big = x >= _F_SERIES_X
    xs = np.where(big, 1.0, x)
    g_small = _E_PI4 * np.sqrt(np.pi) * erfcx(_E_PI4 * np.sqrt(xs))
    xb = np.where(big, x, _F_SERIES_X)
    g_big = _f_series(xb) / np.sqrt(xb)
    return np.where(big, g_big, g_small)


def transition_function(x: ArrayLike) -> CArray:
    """UTD transition function F of Kouyoumjian & Pathak (Proc. IEEE 62(11), 1974).

    ::

        F(x) = 2j sqrt(x) e^{jx} int_{sqrt(x)}^inf e^{-j t^2} dt
             = e^{j pi/4} sqrt(pi x) erfcx(e^{j pi/4} sqrt(x))

    evaluated with the Faddeeva function (``scipy.special.erfcx``) below ``x = 100``, and from
    there on with its asymptotic series ``1 + j/(2x) - 3/(4x^2) - 15j/(8x^3) + ...`` to 12
    terms (within 1e-16 relative of F there; the Faddeeva form is within about 5e-15).

    Parameters
    ----------
    x : float or array_like, any shape
        Argument, ``x >= 0`` (``+inf`` allowed).

    Returns
    -------
    complex128 array, shape of ``x``
        ``F(0) = 0``, ``F(x) -> sqrt(pi x) e^{j pi/4}`` for ``x -> 0``, ``F(inf) = 1``.
    """
    xa = np.asarray(x, dtype=float)
    if np.any(np.isnan(xa)) or np.any(xa < 0):
        raise WavepathsError("`x` must be >= 0 (and not NaN)")
    big = xa >= _F_SERIES_X
    xs = np.where(big, 1.0, xa)
    f_small = np.sqrt(xs) * _g(xs)
    f_big = _f_series(np.where(big, xa, _F_SERIES_X))
    return np.asarray(np.where(big, f_big, f_small), dtype=np.complex128)


# --------------------------------------------------------------------------- shared kernels
def _prepare(
    phi: ArrayLike, phi_prime: ArrayLike, beta_0: ArrayLike, n: ArrayLike, k: ArrayLike,
    L: ArrayLike | None,
) -> list[Array]:
    names = ["phi", "phi_prime", "beta_0", "n", "k", "L"]
    vals = [phi, phi_prime, beta_0, n, k, 1.0 if L is None else L]
    arrs = [np.asarray(v, dtype=float) for v in vals]
    for name, a in zip(names, arrs):
        if not np.all(np.isfinite(a)):
            raise WavepathsError(f"`{name}` must be finite")
    if np.any(arrs[3] <= 1.0) or np.any(arrs[3] > 2.0):
        raise WavepathsError("`n` (exterior angle / pi) must lie in (1, 2]")
    if np.any(arrs[4] <= 0.0):
        raise WavepathsError("`k` (wavenumber, rad/m) must be > 0")
    if np.any(arrs[5] < 0.0):
        raise WavepathsError("`L` (distance parameter, m) must be >= 0")
    return list(np.broadcast_arrays(*arrs))


def _check_r(*rs: ArrayLike) -> list[CArray]:
    out = [np.asarray(r, dtype=np.complex128) for r in rs]
    if not all(np.all(np.isfinite(r)) for r in out):
        raise WavepathsError("face reflection coefficients must be finite")
    return out


def _check_floor(value: float, name: str) -> None:
    if not (0.0 < value < 1.0):
        raise WavepathsError(f"`{name}` must lie in (0, 1), got {value!r}")


class BoundaryOffsets(NamedTuple):
    """Signed angular offsets ``eps_1..eps_4`` [rad] of the four UTD terms D1..D4.

    ``eps_i = 0`` exactly on the boundary of term i: D2 the incident shadow boundary
    ``phi = phi' + pi``, D1 ``phi = phi' - pi``, D4 the 0-face reflection boundary
    ``phi = pi - phi'``, D3 the n-face one ``phi = (2n - 1) pi - phi'``. Each lies in
    ``[-n pi, n pi]``; near its boundary it is positive on the GO-lit side.
    """

    eps_1: Array
    eps_2: Array
    eps_3: Array
    eps_4: Array


def boundary_offsets(phi: ArrayLike, phi_prime: ArrayLike, n: ArrayLike) -> BoundaryOffsets:
    """The offsets ``eps = pi +- beta - 2 pi n N^{+-}`` of the KP terms (Kouyoumjian & Pathak 1974).

    ``N^{+-} = round((beta +- pi) / (2 pi n))`` with ``beta = phi -+ phi'``. A GO
    computation that wants to agree *bit for bit* with the diffraction coefficients on
    which side of a boundary a point lies should test the sign of these values.

    Returns
    -------
    BoundaryOffsets
        Four float64 arrays of the broadcast shape.
    """
    p, pp, nn = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (phi, phi_prime, n)))
    return BoundaryOffsets(*_epsilons(p, pp, nn))


def _epsilons(phi: Array, phi_prime: Array, n: Array) -> tuple[Array, Array, Array, Array]:
    """eps_1..eps_4 of the terms D1..D4 (zero on the boundary of that term).

    D1: cot((pi+b-)/2n) F(kL a+(b-)), D2: cot((pi-b-)/2n) F(kL a-(b-)),
    D3: cot((pi+b+)/2n) F(kL a+(b+)), D4: cot((pi-b+)/2n) F(kL a-(b+)); b-+ = phi -+ phi'.
    N+- = round((b +- pi)/(2 pi n)) (KP 1974). D2 vanishes on the incident shadow
    boundary phi = phi' + pi, D1 on phi = phi' - pi, D4 on the 0-face reflection boundary
    phi = pi - phi', D3 on the n-face one phi = (2n-1) pi - phi'.
    """
    two_pi_n = 2.0 * np.pi * n

    def eps_plus(b: Array) -> Array:
        return (np.pi + b) - two_pi_n * np.round((b + np.pi) / two_pi_n)

    def eps_minus(b: Array) -> Array:
        return (np.pi - b) + two_pi_n * np.round((b - np.pi) / two_pi_n)

    bm = phi - phi_prime
    bp = phi + phi_prime
    return eps_plus(bm), eps_minus(bm), eps_plus(bp), eps_minus(bp)


def _cot_f(eps: Array, n: Array, kl: Array) -> CArray:
    """cot(eps/2n) F(2 kL sin^2(eps/2)) for |eps| <= n pi, finite everywhere (0 at eps=0)."""
    ratio = n * np.sinc(eps / (2.0 * np.pi)) / np.sinc(eps / (2.0 * np.pi * n))
    x = 2.0 * kl * np.sin(0.5 * eps) ** 2
    return np.sign(eps) * np.sqrt(2.0 * kl) * np.cos(eps / (2.0 * n)) * ratio * _g(x)


def _cot_floored(eps: Array, n: Array, floor: float) -> Array:
    """cot(eps/2n) with |sin(eps/2n)| floored (GTD: huge but finite on a boundary)."""
    s = np.sin(eps / (2.0 * n))
    s = np.where(np.abs(s) < floor, np.where(s < 0, -floor, floor), s)
    return np.cos(eps / (2.0 * n)) / s


def _prefactor(n: Array, k: Array, beta_0: Array, sin_beta_0_floor: float) -> CArray:
    """-e^{-j pi/4} / (2 n sqrt(2 pi k) sin beta_0), KP 1974, sin beta_0 floored."""
    sb = np.maximum(np.abs(np.sin(beta_0)), sin_beta_0_floor)
    return -np.exp(-0.25j * np.pi) / (2.0 * n * np.sqrt(2.0 * np.pi * k) * sb)


def _four_terms(
    phi: Array, phi_prime: Array, beta_0: Array, n: Array, k: Array, L: Array,
    sin_beta_0_floor: float, gtd_floor: float | None,
) -> tuple[CArray, CArray, CArray, CArray]:
    """pref * (D1, D2, D3, D4); with gtd_floor the F -> 1 (Keller) limit."""
    pref = _prefactor(n, k, beta_0, sin_beta_0_floor)
    eps = _epsilons(phi, phi_prime, n)
    if gtd_floor is None:
        kl = k * L
        t = [_cot_f(e, n, kl) for e in eps]
    else:
        t = [_cot_floored(e, n, gtd_floor) for e in eps]
    return pref * t[0], pref * t[1], pref * t[2], pref * t[3]


# --------------------------------------------------------------------------- UTD / Luebbers
def luebbers_coefficients(
    phi: ArrayLike, phi_prime: ArrayLike, beta_0: ArrayLike, n: ArrayLike, k: ArrayLike,
    L: ArrayLike, r0_s: ArrayLike, r0_h: ArrayLike, rn_s: ArrayLike, rn_h: ArrayLike,
    *, sin_beta_0_floor: float = 1e-6,
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
    L: ArrayLike, *, sin_beta_0_floor: float = 1e-6,
) -> WedgeCoefficients:
    """Kouyoumjian & Pathak (Proc. IEEE 62(11):1448-1461, 1974) PEC wedge coefficient.

    ::

        D_{s,h} = -e^{-j pi/4} / (2n sqrt(2 pi k) sin b0) *
                  [ cot((pi+b-)/2n) F(kL a+(b-)) + cot((pi-b-)/2n) F(kL a-(b-))
                    -+ { cot((pi+b+)/2n) F(kL a+(b+)) + cot((pi-b+)/2n) F(kL a-(b+)) } ]
        b-+ = phi -+ phi',  a+-(b) = 2 cos^2((2 n pi N+- - b)/2),  N+- = round((b +- pi)/(2 pi n))

    (upper sign soft). Exactly on a shadow/reflection boundary the singular term takes the
    mean of its one-sided limits (0); see the module docstring. Parameters and returns as
    :func:`luebbers_coefficients` (which this is, with ``R = -1`` soft, ``+1`` hard).
    """
    return luebbers_coefficients(
        phi, phi_prime, beta_0, n, k, L, -1.0, 1.0, -1.0, 1.0, sin_beta_0_floor=sin_beta_0_floor
    )


def luebbers_face_coefficients(
    material_0: Material, material_n: Material, frequency_hz: float, phi: ArrayLike,
    phi_prime: ArrayLike, n: ArrayLike, model: ReflectionModel = "half_space",
    *, beta_0: ArrayLike = np.pi / 2,
) -> FaceCoefficients:
    """Face reflection coefficients at Luebbers' angles (ITU-R P.526 wedge section).

    ``R0`` at grazing angle ``phi'`` on the 0-face (``cos theta = sin b0 |sin phi'|``) and
    ``Rn`` at grazing angle ``n pi - phi`` on the n-face (``cos theta = sin b0 |sin(n pi -
    phi)|``, the observer side). ``r_te`` goes with ``D_s`` and ``r_tm`` with ``D_h``, no sign
    change (PEC -> ``(-1, +1)``, exactly KP). With the default ``beta_0 = pi/2`` this is the
    2-D form of Luebbers / P.526; a ``beta_0`` uses the true 3-D angle of incidence on the
    face. Note: unlike KP, the result is not symmetric in ``phi <-> phi'``.

    Returns
    -------
    FaceCoefficients
        ``(r0_s, r0_h, rn_s, rn_h)``, complex128 of the broadcast shape.
    """
    p, pp, nn, b0 = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (phi, phi_prime, n, beta_0)))
    sb = np.abs(np.sin(b0))
    c0 = sb * np.abs(np.sin(pp))
    cn = sb * np.abs(np.sin(nn * np.pi - p))
    r0 = reflection_coefficients(material_0, frequency_hz, c0, model)
    rn = reflection_coefficients(material_n, frequency_hz, cn, model)
    return FaceCoefficients(r0.r_te, r0.r_tm, rn.r_te, rn.r_tm)


def edge_fixed_reflection(
    r_te: ArrayLike, r_tm: ArrayLike, k_in: ArrayLike, k_out: ArrayLike, normal: ArrayLike, e: ArrayLike,
    fallback: ArrayLike,
) -> CArray:
    """A face's reflection as a Jones matrix between KP's edge-fixed bases, in the sign
    convention of the ``R``'s of :func:`luebbers_coefficients`.

    The face (unit ``normal``, containing the edge ``e``) reflects the ray ``k_in`` into its
    mirror ``k_out`` with the Fresnel coefficients ``r_te``, ``r_tm``: ``E_r = R E_i``, ``R =
    r_te s s^T + r_tm p_r p_i^T`` (``s = unit(k_in x normal)``, ``p = s x k``; the chain's
    :func:`~wavepaths.fields.chain._apply_reflection`). Returned is ``G = -B_out^T R B_in``
    with ``B_in = (b0', phi')`` the edge-fixed basis of ``k_in`` as an incident ray and
    ``B_out = (b0, phi)`` that of ``k_out`` as a diffracted one (module docstring). With
    incidence normal to the edge (``beta_0 = pi/2``) ``G = diag(r_te, r_tm)``, Luebbers' scalar
    pairs; a PEC face gives ``diag(-1, +1)`` at every ``beta_0`` (KP). At oblique incidence on a
    dielectric face the face's TE/TM basis is turned against the edge-fixed one and ``G`` is
    full: it is the geometrical-optics reflection the term of that face's reflection boundary
    must cancel, which the diagonal pairs cannot (the total field then jumps there: 1.3 dB at
    ``beta_0 = 42`` deg on a lossy wedge). Sionna RT also writes its faces' reflections as
    2x2 matrices, in its own "shadow-boundary" bases (docs/sionna-diffraction.md).
    ``||G||_2 = max(|r_te|, |r_tm|)``: the two bases are orthonormal in the same planes.
    ``fallback``: the direction used where ``k`` runs along the edge (``beta_0 = 0``).

    Returns
    -------
    (..., 2, 2) complex128
    """
    ki, ko, nrm, ee, fb = (np.asarray(v, dtype=float) for v in (k_in, k_out, normal, e, fallback))
    z = np.zeros_like(nrm)
    z[..., 2] = 1.0
    x = np.zeros_like(nrm)
    x[..., 0] = 1.0
    s = unit_cross(ki, nrm, unit_cross(nrm, z, x))  # the TE direction (as the reflection kernel's)
    p_i = np.cross(s, ki)
    p_r = np.cross(s, ko)
    phi_i = unit_cross(ki, ee, fb)
    b_i = np.cross(ki, phi_i)
    phi_o = unit_cross(ee, ko, fb)
    b_o = np.cross(ko, phi_o)

    rte, rtm = np.asarray(r_te, dtype=complex), np.asarray(r_tm, dtype=complex)
    out = np.empty(np.broadcast_shapes(rte.shape, ki.shape[:-1]) + (2, 2), dtype=np.complex128)
    for a, u in enumerate((b_o, phi_o)):
        us, up = dot3(u, s), dot3(u, p_r)
        for b, v in enumerate((b_i, phi_i)):
            out[..., a, b] = -(rte * (us * dot3(s, v)) + rtm * (up * dot3(p_i, v)))
    return out


def wedge_reflection_matrices(
    r0_s: ArrayLike, r0_h: ArrayLike, rn_s: ArrayLike, rn_h: ArrayLike, e: ArrayLike, s_in: ArrayLike,
    s_out: ArrayLike, normal_0: ArrayLike, normal_n: ArrayLike, fallback: ArrayLike,
) -> tuple[CArray, CArray]:
    """``(G0, Gn)`` (..., 2, 2): the faces' reflections of :func:`edge_fixed_reflection` that
    replace Luebbers' scalar ``R0``, ``Rn`` (:func:`diffraction_jones_matrices`), each
    where its reflection boundary needs it.

    ``G0``: the 0-face reflecting the incident ray ``s_in`` into its mirror (the input basis
    is the incident ray's own; at the 0-face's reflection boundary the output basis is the
    diffracted ray's). ``Gn``: the n-face reflecting into the diffracted ray ``s_out`` the
    ray that is its mirror (the output basis is the diffracted ray's own; at the n-face's
    reflection boundary the input basis is the incident ray's). The Fresnel coefficients are
    Luebbers' (:func:`luebbers_face_coefficients`: the 0-face at the incident ray's angle,
    the n-face at the diffracted ray's, which are the angles of these two reflections).
    """
    si, so, n0, nn = (np.asarray(v, dtype=float) for v in (s_in, s_out, normal_0, normal_n))

    def mirror(k, nrm):
        return k - 2.0 * dot3(k, nrm)[..., None] * nrm

    g0 = edge_fixed_reflection(r0_s, r0_h, si, mirror(si, n0), n0, e, fallback)
    gn = edge_fixed_reflection(rn_s, rn_h, mirror(so, nn), so, nn, e, fallback)
    return g0, gn


def diffraction_jones_matrices(
    phi: ArrayLike, phi_prime: ArrayLike, beta_0: ArrayLike, n: ArrayLike, k: ArrayLike, L: ArrayLike,
    model: DiffractionModel, g0: ArrayLike, gn: ArrayLike, *, sin_beta_0_floor: float = 1e-6,
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
    *, sin_beta_0_floor: float = 1e-6,
) -> Array:
    """An upper bound on ``max(|D_s|, |D_h|)`` of the UTD coefficient for passive faces.

    For :func:`luebbers_coefficients` with any face coefficients ``|R| <= 1`` (passive
    materials; KP's ``R = -+1`` included), hence for :func:`diffraction_jones`'s ``"utd"``
    model, whose Jones matrix ``diag(-D_s, -D_h)`` has norm ``max(|D_s|, |D_h|)``, and for
    :func:`diffraction_jones_matrices` (the field chain's), whose face matrices have norms
    ``max(|r_te|, |r_tm|) <= 1``, so that its norm is at most the same sum::

        |D| <= sum_i min(|cot(eps_i / 2n)|, n sqrt(2 pi k L))
               / (2 n sqrt(2 pi k) max(|sin beta_0|, floor))

    Each of the four terms is ``cot(eps/2n) F(2 k L sin^2(eps/2))`` (module docstring), and
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


# --------------------------------------------------------------------------- GTD
def keller_coefficients(
    phi: ArrayLike, phi_prime: ArrayLike, beta_0: ArrayLike, n: ArrayLike, k: ArrayLike,
    *, sin_beta_0_floor: float = 1e-6, denominator_floor: float = 1e-12,
) -> WedgeCoefficients:
    """Keller's GTD PEC wedge coefficient (JOSA 52:116, 1962), the F -> 1 limit of KP.

    ::

        D_{s,h} = e^{-j pi/4} sin(pi/n) / (n sqrt(2 pi k) sin b0) *
                  [ 1/(cos(pi/n) - cos((phi-phi')/n)) -+ 1/(cos(pi/n) - cos((phi+phi')/n)) ]

    It diverges on the shadow and reflection boundaries: there a denominator smaller than
    ``denominator_floor`` in magnitude is replaced by ``+-denominator_floor``, so the result
    is huge (~1/denominator_floor) but finite. Vanishes for ``n = 1``.

    Returns
    -------
    WedgeCoefficients
        ``(D_s, D_h)`` [sqrt(m)], complex128 of the broadcast shape.
    """
    _check_floor(sin_beta_0_floor, "sin_beta_0_floor")
    _check_floor(denominator_floor, "denominator_floor")
    p, pp, b0, nn, kk, _ = _prepare(phi, phi_prime, beta_0, n, k, None)
    sb = np.maximum(np.abs(np.sin(b0)), sin_beta_0_floor)
    pref = np.exp(-0.25j * np.pi) * np.sin(np.pi / nn) / (nn * np.sqrt(2.0 * np.pi * kk) * sb)

    def inv(beta: Array) -> Array:
        den = np.cos(np.pi / nn) - np.cos(beta / nn)
        den = np.where(np.abs(den) < denominator_floor, np.where(den < 0, -denominator_floor, denominator_floor), den)
        return 1.0 / den

    a, b = inv(p - pp), inv(p + pp)
    return WedgeCoefficients(pref * (a - b), pref * (a + b))


def seed_keller_coefficient(
    wavelength: ArrayLike, n: ArrayLike, beta: ArrayLike, delta: ArrayLike, alpha: ArrayLike,
    C: ArrayLike,
) -> Array:
    """The seed paper's real GTD coefficient, exactly as written in its section 2.1.

    Aveneau & Meriaux, "Rendering polygonal scenes with diffraction account" (seed 000)::

        D = sqrt(lambda) cos(pi/4) sin(pi/n) / (2 n pi sin beta) *
            [ 1/(cos(pi/n) - cos((delta - alpha)/n)) + C / (cos(pi/n) - cos((delta + alpha + pi)/n)) ]

    ``delta``, ``alpha``: diffracted and incident directions measured from the *normal* of
    the incident face, so ``delta = phi - pi/2``, ``alpha = phi' - pi/2``; ``C = -1`` is
    Keller's soft and ``C = +1`` his hard coefficient. The result equals
    ``Re(e^{j pi/4} D_Keller) / sqrt(2)``: Keller's value without its ``e^{-j pi/4}`` phase
    and a factor ``1/sqrt(2)`` smaller in magnitude. No floor: it is infinite on boundaries.
    """
    lam, nn, b, de, al, c = (np.asarray(v, dtype=float) for v in (wavelength, n, beta, delta, alpha, C))
    with np.errstate(divide="ignore"):
        pref = np.sqrt(lam) * np.cos(np.pi / 4) * np.sin(np.pi / nn) / (2 * nn * np.pi * np.sin(b))
        t1 = 1.0 / (np.cos(np.pi / nn) - np.cos((de - al) / nn))
        t2 = c / (np.cos(np.pi / nn) - np.cos((de + al + np.pi) / nn))
    return np.asarray(pref * (t1 + t2))


def seed_scalar_radiance(
    L_inc: ArrayLike, wavelength: ArrayLike, n: ArrayLike, beta: ArrayLike, delta: ArrayLike,
    alpha: ArrayLike,
) -> Array:
    """The seed paper's unpolarised diffracted radiance, exactly as written (section 2.1).

    ::

        L_dif = L_inc lambda ( cos(pi/4) sin(pi/n) / (n pi sin beta (cos(pi/n) - cos((delta-alpha)/n))) )^2

    This is ``4 L_inc D_1^2`` with ``D_1`` the first (incident-boundary) term of
    :func:`seed_keller_coefficient`, i.e. ``2 L_inc |Keller's first term|^2``; the
    polarisation average of Keller's coefficients would be ``|A|^2 + |B|^2`` (first and
    second terms): the seed drops ``B`` and doubles ``|A|^2``.
    """
    li, lam, nn, b, de, al = (np.asarray(v, dtype=float) for v in (L_inc, wavelength, n, beta, delta, alpha))
    with np.errstate(divide="ignore"):
        x = np.cos(np.pi / 4) * np.sin(np.pi / nn) / (
            nn * np.pi * np.sin(b) * (np.cos(np.pi / nn) - np.cos((de - al) / nn))
        )
    return np.asarray(li * lam * x**2)


# --------------------------------------------------------------------------- Jones matrix
def diffraction_jones(
    phi: ArrayLike, phi_prime: ArrayLike, beta_0: ArrayLike, n: ArrayLike, k: ArrayLike,
    L: ArrayLike, model: DiffractionModel, r0_s: ArrayLike = -1.0, r0_h: ArrayLike = 1.0,
    rn_s: ArrayLike = -1.0, rn_h: ArrayLike = 1.0, *, sin_beta_0_floor: float = 1e-6,
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
