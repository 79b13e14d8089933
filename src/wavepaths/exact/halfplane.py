"""Sommerfeld's exact solution for a PEC half-plane lit by a plane wave.

Sommerfeld, Math. Ann. 47:317 (1896); Born & Wolf, *Principles of Optics* section 11.5;
Bowman, Senior & Uslenghi (1969) ch. 8. Time factor ``exp(+jwt)`` (``docs/conventions.md``).

The half-plane occupies ``phi = 0`` (= ``2 pi``), ``rho >= 0``. The incident plane wave
``u_i = exp(jk rho cos(phi - phi'))`` comes *from* the direction ``phi'`` and has unit
amplitude at the edge. The total field is::

    u = U(phi - phi') -+ U(phi + phi')          (- soft/Dirichlet, + hard/Neumann)
    U(psi) = exp(jk rho cos psi) * 1/2 erfc(-e^{j pi/4} sqrt(2 k rho) cos(psi/2))
           = 1/2 exp(-jk rho) erfcx(-e^{j pi/4} sqrt(2 k rho) cos(psi/2))

(the second form uses ``z^2 = jk rho (1 + cos psi)`` for the erfc argument ``z``, and never
forms a large exponential). For a 3-D plane wave at angle ``beta_0`` to the edge the exact
field is this 2-D solution with ``k rho`` replaced by ``k sin(beta_0) rho``, times
``exp(-jkz cos(beta_0))``.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import erfcx

from wavepaths.errors import WavepathsError

__all__ = ["halfplane_plane_wave"]

Polarization = Literal["soft", "hard"]


def _sign_for(polarization: str) -> float:
    if polarization == "soft":
        return -1.0
    if polarization == "hard":
        return 1.0
    raise WavepathsError(f"`polarization` must be one of ('soft', 'hard'), got {polarization!r}")


def _big_u(k_rho: NDArray[np.float64], psi: NDArray[np.float64]) -> NDArray[np.complex128]:
    z = -np.exp(0.25j * np.pi) * np.sqrt(2.0 * k_rho) * np.cos(0.5 * psi)
    return 0.5 * np.exp(-1j * k_rho) * erfcx(z)


def halfplane_plane_wave(
    k_rho: ArrayLike, phi: ArrayLike, phi_prime: ArrayLike, polarization: Polarization
) -> NDArray[np.complex128]:
    """Exact total field of a unit plane wave diffracted by a PEC half-plane.

    Parameters
    ----------
    k_rho : array_like
        Wavenumber times distance from the edge [rad], >= 0.
    phi : array_like [rad]
        Observer direction, in ``[0, 2 pi]`` from the lit face.
    phi_prime : array_like [rad]
        Direction the plane wave comes from, in ``[0, 2 pi]``.
    polarization : {"soft", "hard"}
        ``"soft"``: Dirichlet (``E_z``, E parallel to the edge); ``"hard"``: Neumann
        (``H_z``).

    Returns
    -------
    complex128 array, broadcast shape
        Total field ``u`` (incident + reflected + diffracted), unit incident amplitude.
    """
    sign = _sign_for(polarization)
    kr, p, pp = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (k_rho, phi, phi_prime)))
    if not (np.all(np.isfinite(kr)) and np.all(np.isfinite(p)) and np.all(np.isfinite(pp))):
        raise WavepathsError("`k_rho`, `phi` and `phi_prime` must be finite")
    if np.any(kr < 0):
        raise WavepathsError("`k_rho` must be >= 0")
    check_angles(p, pp, 2.0)
    return _big_u(kr, p - pp) + sign * _big_u(kr, p + pp)


ANGLE_SLACK = 1e-9
"""[rad] How far outside ``[0, n pi]`` an angle may lie (rounding) before the exact solutions
refuse it."""


def check_angles(phi: np.ndarray, phi_prime: np.ndarray, n: float) -> None:
    """Refuse observer or source directions outside the free space ``[0, n pi]`` of the wedge
    (the series and Fresnel forms extend beyond it, into the wedge, with values that are no
    field: a review got 1.56 from ``wedge_plane_wave(10, -0.5, 1, 1.5, "soft")``)."""
    top = n * np.pi + ANGLE_SLACK
    for name, a in (("phi", phi), ("phi_prime", phi_prime)):
        if a.size and (a.min() < -ANGLE_SLACK or a.max() > top):
            raise WavepathsError(f"`{name}` must lie in [0, {n:g} pi] (the free space around the edge), got values "
                                 f"from {a.min():.6g} to {a.max():.6g} rad")
