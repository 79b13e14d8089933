"""ITU-R P.526 single knife edge: exact Fresnel-Kirchhoff (absorbing screen) diffraction.

ITU-R P.526-15, section 4.1 (single knife edge) and the Fresnel integrals of section 2.7.
Time factor ``exp(+jwt)`` (``docs/conventions.md``): an extra path delay is ``exp(-jk dl)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import fresnel

from wavepaths.errors import WavepathsError

__all__ = ["fresnel_nu", "knife_edge_field", "knife_edge_loss_db"]


def fresnel_nu(h: ArrayLike, d1: ArrayLike, d2: ArrayLike, wavelength: ArrayLike) -> NDArray[np.float64]:
    """Fresnel-Kirchhoff diffraction parameter of ITU-R P.526 (first of its four equivalent forms).

    ``nu = h sqrt(2 (d1 + d2) / (lambda d1 d2))``.

    Parameters
    ----------
    h : array_like [m]
        Height of the edge above the straight line joining the two ends (negative below).
    d1, d2 : array_like [m]
        Distances from the ends to the edge, > 0.
    wavelength : array_like [m]
        > 0.

    Returns
    -------
    float64 array, broadcast shape
    """
    h_, a, b, lam = (np.asarray(v, dtype=float) for v in (h, d1, d2, wavelength))
    if np.any(a <= 0) or np.any(b <= 0) or np.any(lam <= 0):
        raise WavepathsError("`d1`, `d2` and `wavelength` must be > 0")
    return np.asarray(h_ * np.sqrt(2.0 * (a + b) / (lam * a * b)))


def knife_edge_field(nu: ArrayLike) -> NDArray[np.complex128]:
    """Complex field behind an absorbing knife edge relative to free space, ``E/E0``.

    ::

        E/E0 = (1+j)/2 * int_nu^inf exp(-j pi t^2 / 2) dt
             = (1+j)/2 * [ (1/2 - C(nu)) - j (1/2 - S(nu)) ]

    with ``C``, ``S`` the Fresnel integrals ``int_0^nu cos/sin(pi t^2/2) dt``
    (``scipy.special.fresnel``). ``E/E0 -> 1`` for ``nu -> -inf`` and ``1/2`` at ``nu = 0``.

    Parameters
    ----------
    nu : array_like
        Diffraction parameter (:func:`fresnel_nu`), finite.

    Returns
    -------
    complex128 array, shape of ``nu``
    """
    v = np.asarray(nu, dtype=float)
    if not np.all(np.isfinite(v)):
        raise WavepathsError("`nu` must be finite")
    s, c = fresnel(v)
    return np.asarray(0.5 * (1.0 + 1.0j) * ((0.5 - c) - 1j * (0.5 - s)), dtype=np.complex128)


def knife_edge_loss_db(nu: ArrayLike) -> NDArray[np.float64]:
    """Knife-edge diffraction loss ``J(nu)`` [dB] relative to free space, ITU-R P.526 section 4.1.

    ``J(nu) = -20 log10( sqrt((1 - C - S)^2 + (C - S)^2) / 2 ) = -20 log10 |E/E0|``;
    ``J(0) = 20 log10(2) = 6.0206 dB``, ``J -> 0`` for ``nu -> -inf``.

    Returns
    -------
    float64 array, shape of ``nu``
    """
    v = np.asarray(nu, dtype=float)
    if not np.all(np.isfinite(v)):
        raise WavepathsError("`nu` must be finite")
    s, c = fresnel(v)
    return np.asarray(-20.0 * np.log10(np.sqrt((1.0 - c - s) ** 2 + (c - s) ** 2) / 2.0))
