"""The UTD transition function and the four terms of the wedge diffraction coefficient.

The job of this module is the numerics shared by every coefficient of
:mod:`wavepaths.em.utd` (and :mod:`wavepaths.em.sionna_compat`):

* the transition function ``F`` of Kouyoumjian & Pathak (Proc. IEEE 62(11), 1974), from the
  Faddeeva function below ``x = 100`` and its asymptotic series from there on
  (:func:`transition_function`, ``_g``, ``_f_series``);
* the signed offsets ``eps = pi +- beta - 2 pi n N^{+-}`` of the four KP terms from their
  shadow and reflection boundaries (:func:`boundary_offsets`, ``_epsilons``);
* the four terms ``D1..D4`` with KP's prefactor ``-e^{-j pi/4} / (2 n sqrt(2 pi k) sin
  beta_0)``, uniform (UTD) or in Keller's ``F -> 1`` limit (GTD) (``_four_terms``,
  ``_cot_f``, ``_cot_floored``, ``_prefactor``);
* the checks of the coefficients' arguments (``_prepare``, ``_check_r``, ``_check_floor``)
  and the array types and :class:`WedgeCoefficients` they return.

Conventions are those of :mod:`wavepaths.em.utd` (``docs/conventions.md``).

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

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import erfcx

from wavepaths.errors import WavepathsError

__all__ = [
    "Array",
    "BoundaryOffsets",
    "CArray",
    "WedgeCoefficients",
    "boundary_offsets",
    "transition_function",
]

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


SIN_BETA_0_FLOOR = 1e-6
"""The default floor of ``|sin beta_0|`` in the diffraction coefficients (grazing incidence
along the edge, where they diverge as ``1 / sin beta_0``): a coefficient is at most about
1e6 times its broadside value. The fields and the search's amplitude bounds use the same."""


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
