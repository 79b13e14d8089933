"""Fresnel reflection and transmission coefficients (ITU-R P.2040).

Equation numbers are those of P.2040-3 as cited by the brief and by Sionna RT (which cites
the same numbers for P.2040-4): eq. (37) half-space, eqs. (43)-(44) single-layer slab.

Time factor ``exp(+jwt)``; the incident wave comes from vacuum; ``eta`` is the complex
relative permittivity of the material (``Im eta <= 0`` for a lossy medium).

Jones basis and sign convention
-------------------------------
For an incident propagation direction ``k_i`` on a surface with unit normal ``n``:

* ``e_s = unit(k_i x n)`` is the TE ("s", perpendicular) basis vector; the *same* vector is
  used for the incident, reflected and transmitted waves;
* ``e_p = e_s x k`` is the TM ("p", parallel) basis vector of each wave, with ``k`` the
  propagation direction of that wave (``k_i``, ``k_r`` or ``k_t``).

A field ``E = E_s e_s + E_p e_p`` reflects to ``r_te E_s e_s + r_tm E_p e_p_r``. In this
basis ``e_p``'s magnetic field is along ``e_s`` for every wave, so ``r_tm`` is the ratio of
tangential magnetic fields, and P.2040 eq. (37) gives it with the signs below: a perfect
conductor has ``(r_te, r_tm) = (-1, +1)`` at every angle, and at normal incidence
``r_tm = -r_te``. Using ``e_p = k x e_s`` for every wave (Sionna RT) flips both ``e_p`` and
leaves the coefficients unchanged. See ``docs/conventions.md``.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.constants import speed_of_light

from wavepaths.em.materials import Material, relative_permittivity
from wavepaths.errors import WavepathsError

__all__ = [
    "FresnelCoefficients",
    "SlabCoefficients",
    "fresnel_half_space",
    "reflection_coefficients",
    "slab_coefficients",
]

ReflectionModel = Literal["slab", "half_space"]
_MODELS: tuple[str, ...] = ("slab", "half_space")

# |cos(theta)| may exceed 1 by this much from rounding in the caller's dot products.
_COS_ROUNDING = 1e-9
# Below this a slab denominator is treated as 0 (exact grazing incidence).
_TINY = 1e-200
# Above this |eta| the coefficients are a perfect conductor's: r_te = -1 + 2c/sqrt(eta) and
# r_tm = 1 - 2/(c sqrt(eta)) to first order, within 1e-16 of (-1, +1) for cos(theta) >= 1e-34,
# and a slab transmits e^{-jq} ~ 0. Past |eta| ~ 1e154 the rationalised form's squares overflow.
_HUGE = 1e100


class FresnelCoefficients(NamedTuple):
    """Reflection coefficients ``(r_te, r_tm)``, complex arrays of a common shape."""

    r_te: NDArray[np.complex128]
    r_tm: NDArray[np.complex128]


class SlabCoefficients(NamedTuple):
    """Single-layer slab coefficients (P.2040-3 eqs. 43-44), complex arrays of one shape.

    ``t_te``, ``t_tm`` multiply the incident field to give the field leaving the far side,
    with the phase of P.2040 eq. (43b) (propagation ``exp(-jq)`` through the slab).
    """

    r_te: NDArray[np.complex128]
    r_tm: NDArray[np.complex128]
    t_te: NDArray[np.complex128]
    t_tm: NDArray[np.complex128]


def _check_cos(cos_theta: ArrayLike) -> NDArray[np.float64]:
    c = np.asarray(cos_theta, dtype=float)
    if not np.all(np.isfinite(c)):
        raise WavepathsError("`cos_theta` must be finite")
    ac = np.abs(c)
    if np.any(ac > 1.0 + _COS_ROUNDING):
        raise WavepathsError(
            f"`cos_theta` must lie in [-1, 1], got values up to {float(np.max(ac))!r}"
        )
    return np.minimum(ac, 1.0)


def _check_eta(eta: ArrayLike) -> NDArray[np.complex128]:
    e = np.asarray(eta, dtype=np.complex128)
    if not np.all(np.isfinite(e)):
        raise WavepathsError("`eta` must be finite (use Material kind 'pec' for a conductor)")
    return e


def _root(eta: NDArray[np.complex128], c: NDArray[np.float64]) -> NDArray[np.complex128]:
    """sqrt(eta - sin^2 theta) = sqrt((eta - 1) + cos^2 theta), the branch with ``Im <= 0``
    (the transmitted wave decays or is evanescent, exp(+jwt)).

    Written with ``eta - 1`` so that it stays exact for eta near 1 at grazing incidence.
    The principal root has ``Im <= 0`` for ``Im eta < 0``; for a lossless ``eta`` below
    ``sin^2 theta`` (total reflection) the argument is a negative real with ``Im = +0``,
    whose principal root ``+j sqrt(.)`` grows in a slab: the imaginary part is signed
    ``-0`` there, which gives ``-j sqrt(.)`` (the limit of a vanishing loss).
    """
    w = np.array((eta - 1.0) + c * c, dtype=np.complex128, ndmin=1)  # a writable copy
    w.imag[w.imag == 0.0] = -0.0
    return np.sqrt(w).reshape(np.broadcast_shapes(np.shape(eta), np.shape(c)))


class _HalfSpaceParts(NamedTuple):
    r_te: NDArray[np.complex128]
    r_tm: NDArray[np.complex128]
    one_minus_sq_te: NDArray[np.complex128]  # 1 - r_te^2, without cancellation
    one_minus_sq_tm: NDArray[np.complex128]  # 1 - r_tm^2


def _half_space_parts(eta: NDArray[np.complex128], c: NDArray[np.float64]) -> _HalfSpaceParts:
    """Eq. (37) in rationalised form, with no cancellation near eta = 1 or grazing.

    With ``root^2 = eta - 1 + c^2``: ``r_te = (1 - eta)/(c + root)^2``,
    ``r_tm = (eta - 1)((eta + 1)c^2 - 1)/(eta c + root)^2``,
    ``1 - r_te^2 = 4 c root/(c + root)^2`` and ``1 - r_tm^2 = 4 eta c root/(eta c + root)^2``.
    Above ``|eta| = 1e100`` (a conductivity of about 2e99 S/m at 3.5 GHz) the coefficients
    are a perfect conductor's, ``(-1, +1)`` with ``1 - r^2 = 0``: within 1e-16 of the formula
    for ``cos theta >= 1e-34``, where the formula's squares would overflow from ``|eta| ~ 1e154``.
    """
    huge = np.abs(eta) > _HUGE  # a perfect conductor to rounding (see _HUGE)
    eta = np.where(huge, 2.0, eta)  # a stand-in that keeps the squares below finite
    root = _root(eta, c)
    den_te = (c + root) ** 2
    den_tm = (eta * c + root) ** 2
    # den ~ 0 only for eta ~ 1 at grazing: no interface, r = 0 (avoids subnormal division).
    same = (eta == 1.0) | (np.abs(den_te) < _TINY) | (np.abs(den_tm) < _TINY)
    d_te = np.where(same, 1.0, den_te)
    d_tm = np.where(same, 1.0, den_tm)
    r_te = np.where(same, 0.0, (1.0 - eta) / d_te)
    r_tm = np.where(same, 0.0, (eta - 1.0) * ((eta + 1.0) * c * c - 1.0) / d_tm)
    om_te = np.where(same, 1.0, 4.0 * c * root / d_te)
    om_tm = np.where(same, 1.0, 4.0 * eta * c * root / d_tm)
    if np.any(huge):
        r_te, r_tm = np.where(huge, -1.0 + 0j, r_te), np.where(huge, 1.0 + 0j, r_tm)
        om_te, om_tm = np.where(huge, 0j, om_te), np.where(huge, 0j, om_tm)
    return _HalfSpaceParts(r_te, r_tm, om_te, om_tm)


def _half_space(eta: NDArray[np.complex128], c: NDArray[np.float64]) -> FresnelCoefficients:
    p = _half_space_parts(eta, c)
    return FresnelCoefficients(p.r_te, p.r_tm)


def fresnel_half_space(eta: ArrayLike, cos_theta: ArrayLike) -> FresnelCoefficients:
    """Fresnel reflection from a vacuum / half-space interface, ITU-R P.2040-3 eq. (37).

    ::

        r_te = (cos t - sqrt(eta - sin^2 t)) / (cos t + sqrt(eta - sin^2 t))
        r_tm = (eta cos t - sqrt(eta - sin^2 t)) / (eta cos t + sqrt(eta - sin^2 t))

    with the principal square root (``Re >= 0``; for ``Im eta < 0`` the transmitted wave
    decays). Basis and signs: see the module docstring.

    Parameters
    ----------
    eta : complex or array_like
        Complex relative permittivity, finite, broadcastable with ``cos_theta``.
    cos_theta : float or array_like
        Cosine of the angle of incidence from the normal; only ``|cos_theta|`` is used.

    Returns
    -------
    FresnelCoefficients
        ``(r_te, r_tm)``, complex128 of the broadcast shape.
    """
    e = _check_eta(eta)
    c = _check_cos(cos_theta)
    e, c = np.broadcast_arrays(e, c)
    return _half_space(e, c)


def _slab(
    eta: NDArray[np.complex128], c: NDArray[np.float64], thickness_m: NDArray[np.float64],
    wavelength_m: NDArray[np.float64],
) -> SlabCoefficients:
    root = _root(eta, c)
    q = (2.0 * np.pi * thickness_m / wavelength_m) * root  # eq. (44)
    hs = _half_space_parts(eta, c)
    e1 = np.exp(-1j * q)  # |e1| <= 1 because Im(root) <= 0 (_root's branch)
    e2 = e1 * e1
    one_minus_e2 = -np.expm1(-2j * q)  # accurate for thin slabs
    out = []
    for rp, om in ((hs.r_te, hs.one_minus_sq_te), (hs.r_tm, hs.one_minus_sq_tm)):
        # 1 - rp^2 e2 = (1 - e2) + (1 - rp^2) e2: no cancellation for thin slabs or grazing.
        den = one_minus_e2 + om * e2
        # |den| ~ 0 only at exact grazing (|rp| = 1) with e2 ~ 1: there the limit is R = rp,
        # T = 0 whatever q. The threshold keeps complex division away from subnormals.
        bad = np.abs(den) < _TINY
        den = np.where(bad, 1.0, den)
        r = np.where(bad, rp, rp * one_minus_e2 / den)  # eq. (43a)
        t = np.where(bad, 0.0, om * e1 / den)  # eq. (43b)
        # a slab of thickness 0 is no slab: R = 0, T = 1 at every angle (at exact grazing the
        # limits d -> 0 and cos -> 0 disagree; the slab's absence decides)
        r = np.where(thickness_m == 0, 0.0, r)
        t = np.where(thickness_m == 0, 1.0, t)
        out.append((r, t))
    (r_te, t_te), (r_tm, t_tm) = out
    return SlabCoefficients(r_te, r_tm, t_te, t_tm)


def slab_coefficients(
    eta: ArrayLike, cos_theta: ArrayLike, thickness_m: ArrayLike, wavelength_m: ArrayLike
) -> SlabCoefficients:
    """Single-layer slab in vacuum, ITU-R P.2040-3 eqs. (43)-(44).

    ::

        q = (2 pi d / lambda) sqrt(eta - sin^2 t)
        R = R' (1 - e^{-j2q}) / (1 - R'^2 e^{-j2q})
        T = (1 - R'^2) e^{-jq} / (1 - R'^2 e^{-j2q})

    where ``R'`` is the half-space coefficient of :func:`fresnel_half_space` for the same
    polarisation. ``d -> 0`` gives ``R -> 0, T -> 1`` (``d = 0``: exactly, at grazing
    incidence too); a lossless slab has
    ``|R|^2 + |T|^2 = 1``; a thick lossy slab gives ``R -> R'``.

    Parameters
    ----------
    eta : complex or array_like
        Complex relative permittivity (``Im eta <= 0``).
    cos_theta : float or array_like
        Cosine of the angle of incidence (``|cos_theta|`` is used).
    thickness_m : float or array_like
        Slab thickness ``d`` [m], >= 0.
    wavelength_m : float or array_like
        Free-space wavelength [m], > 0.

    Returns
    -------
    SlabCoefficients
        ``(r_te, r_tm, t_te, t_tm)``, complex128 of the broadcast shape.
    """
    e = _check_eta(eta)
    if np.any(e.imag > 0):
        raise WavepathsError("`eta` must have Im(eta) <= 0 (exp(+jwt) convention, passive)")
    c = _check_cos(cos_theta)
    d = np.asarray(thickness_m, dtype=float)
    lam = np.asarray(wavelength_m, dtype=float)
    if not np.all(np.isfinite(d) & (d >= 0)):
        raise WavepathsError("`thickness_m` must be finite and >= 0")
    if not np.all(np.isfinite(lam) & (lam > 0)):
        raise WavepathsError("`wavelength_m` must be finite and > 0")
    e, c, d, lam = np.broadcast_arrays(e, c, d, lam)
    return _slab(e, c, d, lam)


def reflection_coefficients(
    material: Material,
    frequency_hz: float,
    cos_theta: ArrayLike,
    model: ReflectionModel = "slab",
) -> FresnelCoefficients:
    """Reflection coefficients ``(r_te, r_tm)`` of a material, vectorised over angle.

    Parameters
    ----------
    material : Material
        PEC gives exactly ``(-1, +1)``, an absorber ``(0, 0)``; otherwise ``eta`` comes
        from :func:`wavepaths.em.materials.relative_permittivity`.
    frequency_hz : float
        Frequency [Hz].
    cos_theta : float or array_like, any shape
        Cosine of the angle of incidence from the normal (``|cos_theta|`` is used).
    model : {"slab", "half_space"}
        ``"slab"``: single-layer slab of ``material.thickness_m`` (P.2040 eqs. 43-44, as
        Sionna RT); ``"half_space"``: P.2040 eq. (37).

    Returns
    -------
    FresnelCoefficients
        ``(r_te, r_tm)``, complex128 with the shape of ``cos_theta``. Basis and signs: see
        the module docstring.
    """
    if model not in _MODELS:
        raise WavepathsError(f"`model` must be one of {_MODELS}, got {model!r}")
    c = _check_cos(cos_theta)
    if material.kind == "pec":
        return FresnelCoefficients(
            np.full(c.shape, -1.0 + 0j, dtype=np.complex128),
            np.full(c.shape, 1.0 + 0j, dtype=np.complex128),
        )
    if material.kind == "absorber":
        zero = np.zeros(c.shape, dtype=np.complex128)
        return FresnelCoefficients(zero, zero.copy())
    eta = np.complex128(relative_permittivity(material, frequency_hz))
    e = np.broadcast_to(eta, c.shape)
    if model == "half_space":
        return _half_space(e, c)
    wavelength = speed_of_light / float(frequency_hz)
    d = np.broadcast_to(np.float64(material.thickness_m), c.shape)
    lam = np.broadcast_to(np.float64(wavelength), c.shape)
    s = _slab(e, c, d, lam)
    return FresnelCoefficients(s.r_te, s.r_tm)
