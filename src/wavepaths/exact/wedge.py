"""PEC wedge under plane-wave incidence: exact eigenfunction series and the UTD counterpart.

Time factor ``exp(+jwt)``; wedge faces at ``phi = 0`` and ``phi = n pi`` (exterior angle
``n pi``), free space ``0 < phi < n pi`` (``docs/conventions.md``). The incident plane wave
``u_i = exp(jk rho cos(phi - phi'))`` comes from direction ``phi'`` with unit amplitude at
the edge.

* :func:`wedge_plane_wave`: Macdonald's (1902) eigenfunction series, exact.
* :func:`utd_wedge_total_field`: geometrical optics (incident + one reflection per face,
  each in its lit region) plus the edge-diffracted ray, for comparisons and plots.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import jv

from wavepaths.em.sionna_compat import sionna_compat_coefficients
from wavepaths.em.utd import keller_coefficients, kp_coefficients
from wavepaths.errors import WavepathsError
from wavepaths.exact.halfplane import Polarization, _sign_for, check_angles

__all__ = ["utd_wedge_total_field", "wedge_geometrical_optics", "wedge_plane_wave"]

WedgeFieldModel = Literal["utd", "gtd", "sionna"]

# Terms of the series are dropped once their Bessel factor is below this (relative to the
# unit incident field) and the order is past the turning point, where J_nu decays
# super-exponentially.
_SERIES_TAIL = 1e-17
_CHUNK = 2048
_BESSEL_BUDGET = 1 << 23  # (distinct k rho) x (terms) Bessel values held at once


def _terms(xmax: float, n: float) -> int:
    # M = n (k rho + 20 (k rho)^{1/3} + 30): 20 (k rho)^{1/3} past the turning point J_nu has
    # fallen below 1e-30 at every k rho (with 10 (k rho)^{1/3} it was still 1.6e-17 at 6e4, and
    # the series refused k rho above about 4e4)
    return int(np.ceil(n * (xmax + 20.0 * xmax ** (1.0 / 3.0) + 30.0))) + 1


def _series_chunk(
    x: NDArray[np.float64], p: NDArray[np.float64], pp: NDArray[np.float64], n: float, sign: float
) -> NDArray[np.complex128]:
    xmax = float(np.max(x)) if x.size else 0.0
    m_count = first = _terms(xmax, n)
    while True:
        m = np.arange(m_count, dtype=float)
        nu = m / n
        # J_nu depends on k rho only: evaluate once per distinct k rho (usually few).
        xu, inverse = np.unique(x, return_inverse=True)
        with np.errstate(all="ignore"):
            bessel_u = jv(nu[None, :], xu[:, None])
        bad = ~np.isfinite(bessel_u)
        if np.any(bad & (nu[None, :] <= xu[:, None] + 1.0)):
            raise WavepathsError("Bessel function not finite before its turning point")
        bessel_u = np.where(bad, 0.0, bessel_u)  # far past the turning point: negligible
        bessel = bessel_u[inverse.ravel()]
        tail = np.abs(bessel_u[:, -5:])
        if np.all(tail < _SERIES_TAIL):
            break
        if m_count > 8 * first:
            raise WavepathsError(f"wedge series did not converge within {m_count} terms")
        m_count *= 2
    eps_m = np.where(m == 0, 1.0, 2.0)
    coef = eps_m * np.exp(0.5j * np.pi * nu) * bessel
    ang = np.cos(nu[None, :] * (p - pp)[:, None]) + sign * np.cos(nu[None, :] * (p + pp)[:, None])
    return np.sum(coef * ang, axis=-1) / n


def wedge_plane_wave(
    k_rho: ArrayLike, phi: ArrayLike, phi_prime: ArrayLike, n: float, polarization: Polarization
) -> NDArray[np.complex128]:
    """Exact total field of a unit plane wave on a PEC wedge (Macdonald's series).

    ::

        u = (1/n) sum_{m>=0} eps_m e^{j pi nu_m / 2} J_{nu_m}(k rho)
                     [cos nu_m (phi - phi') -+ cos nu_m (phi + phi')],   nu_m = m/n

    (``eps_0 = 1``, ``eps_m = 2``; ``-`` soft, ``+`` hard). For ``n = 1`` it is the
    Jacobi-Anger expansion of incident + image, for ``n = 2`` Sommerfeld's half-plane.
    Truncated adaptively: from ``M = n (k rho + 20 (k rho)^{1/3} + 30)`` terms, doubled
    until the last terms' Bessel factors are below 1e-17; non-finite Bessel values past the
    turning point (``nu > k rho``) are dropped as negligible. The points go through in chunks
    small enough that their (distinct ``k rho``) x (terms) Bessel values stay near 8 M.

    Parameters
    ----------
    k_rho : array_like
        Wavenumber times distance from the edge, >= 0.
    phi, phi_prime : array_like [rad]
        Observer and source directions, in ``[0, n pi]``.
    n : float
        Exterior angle / pi, in ``[1, 2]``.
    polarization : {"soft", "hard"}

    Returns
    -------
    complex128 array, broadcast shape
    """
    sign = _sign_for(polarization)
    n = float(n)
    if not 1.0 <= n <= 2.0:
        raise WavepathsError(f"`n` must lie in [1, 2], got {n!r}")
    kr, p, pp = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (k_rho, phi, phi_prime)))
    if not (np.all(np.isfinite(kr)) and np.all(np.isfinite(p)) and np.all(np.isfinite(pp))):
        raise WavepathsError("`k_rho`, `phi` and `phi_prime` must be finite")
    if np.any(kr < 0):
        raise WavepathsError("`k_rho` must be >= 0")
    check_angles(p, pp, n)
    flat = [a.ravel() for a in (kr, p, pp)]
    out = np.empty(flat[0].shape, dtype=np.complex128)
    chunk = max(1, min(_CHUNK, _BESSEL_BUDGET // _terms(float(kr.max(initial=0.0)), n)))
    for start in range(0, out.size, chunk):
        sl = slice(start, start + chunk)
        out[sl] = _series_chunk(flat[0][sl], flat[1][sl], flat[2][sl], n, sign)
    return out.reshape(kr.shape)


def _go_weight(offset: NDArray[np.float64]) -> NDArray[np.float64]:
    """1 on the lit side, 0 in shadow, 1/2 exactly on the boundary."""
    return np.where(offset > 0, 1.0, np.where(offset < 0, 0.0, 0.5))


def wedge_geometrical_optics(
    k_rho: ArrayLike, phi: ArrayLike, phi_prime: ArrayLike, n: float, polarization: Polarization
) -> NDArray[np.complex128]:
    """Geometrical-optics field of a unit plane wave on a PEC wedge: incident + one reflection per face.

    ::

        u_GO = w_i e^{jk rho cos(phi - phi')} + R w_0 e^{jk rho cos(phi + phi')}
               + R w_n e^{jk rho cos(phi + phi' - 2 n pi)},   R = -1 soft, +1 hard

    each term weighted by :func:`_go_weight` of its boundary offset (1 lit, 0 in shadow, 1/2
    exactly on the boundary): ``pi - |phi - phi'|``, ``pi - (phi + phi')`` and
    ``phi + phi' - (2n - 1) pi``. For ``1 <= n <= 2`` no ray reflects twice, so the exact
    field minus this is the edge-diffracted field (Keller; KP Table I), the part of a total
    the boundary lines measure against each engine's diffracted paths alone.

    Parameters
    ----------
    k_rho : array_like
        Wavenumber in the plane normal to the edge times distance from the edge.
    phi, phi_prime : array_like [rad]
        Observer and source directions, in ``[0, n pi]``.
    n : float
        Exterior angle / pi.
    polarization : {"soft", "hard"}

    Returns
    -------
    complex128 array, broadcast shape
    """
    sign = _sign_for(polarization)
    kr, p, pp = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (k_rho, phi, phi_prime)))
    check_angles(p, pp, float(n))
    # the boundary tests on the same floating-point offsets as the coefficients
    bm, bp = p - pp, p + pp
    w_inc = _go_weight(np.pi - np.abs(bm))
    w_0 = _go_weight(np.pi - bp)
    w_n = _go_weight((np.pi + bp) - 2.0 * np.pi * n)
    return (w_inc * np.exp(1j * kr * np.cos(bm)) + sign * w_0 * np.exp(1j * kr * np.cos(bp))
            + sign * w_n * np.exp(1j * kr * np.cos(bp - 2.0 * np.pi * n)))


def utd_wedge_total_field(
    k_rho: ArrayLike, phi: ArrayLike, phi_prime: ArrayLike, n: float, polarization: Polarization,
    model: WedgeFieldModel = "utd", *, beta_0: float = np.pi / 2,
) -> NDArray[np.complex128]:
    """GO + edge diffraction total field of a unit plane wave on a PEC wedge.

    GO: the incident wave where ``|phi - phi'| < pi``; the 0-face reflection
    ``R exp(jk_t rho cos(phi + phi'))`` where ``phi + phi' < pi``; the n-face reflection
    ``R exp(jk_t rho cos(phi + phi' - 2 n pi))`` where ``phi + phi' > (2n - 1) pi``
    (``R = -1`` soft, ``+1`` hard). Each GO term has weight 1/2 exactly on its boundary,
    decided on the same floating-point offsets as the coefficients
    (:func:`wavepaths.em.utd.boundary_offsets`), so the total is continuous there.

    Diffraction (KP Table I, plane wave): ``u_d = D(beta_0; k, L) exp(-jk s sin^2 beta_0) / sqrt(s)``
    with ``s = rho / sin beta_0`` and ``L = s sin^2 beta_0`` -- the field at ``z = 0`` of a
    3-D plane wave travelling at ``beta_0`` to the edge, whose exact counterpart is the 2-D
    solution at ``k_t rho = k rho sin beta_0``. Lengths are in units of ``1/k``.

    Parameters
    ----------
    k_rho : array_like
        ``k rho`` with the free-space ``k`` [rad], > 0.
    phi, phi_prime : array_like [rad]
        Observer and source directions, in ``[0, n pi]``.
    n : float
        Exterior angle / pi, in ``(1, 2]``.
    polarization : {"soft", "hard"}
    model : {"utd", "gtd", "sionna"}
        KP, Keller, or the Sionna RT 2.2 compat matrix (PEC; scalar coefficient
        ``-J[0, 0]`` soft, ``-J[1, 1]`` hard).
    beta_0 : float [rad]
        Angle between the incident direction and the edge (default broadside).

    Returns
    -------
    complex128 array, broadcast shape
    """
    kr, p, pp = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (k_rho, phi, phi_prime)))
    if np.any(kr <= 0):
        raise WavepathsError("`k_rho` must be > 0")
    sb = float(np.sin(beta_0))
    if not sb > 0:
        raise WavepathsError("`beta_0` must lie in (0, pi)")
    go = wedge_geometrical_optics(kr * sb, p, pp, n, polarization)
    s = kr / sb  # k = 1
    L = s * sb**2
    if model == "utd":
        d_s, d_h = kp_coefficients(p, pp, beta_0, n, 1.0, L)
        d = d_s if polarization == "soft" else d_h
    elif model == "gtd":
        d_s, d_h = keller_coefficients(p, pp, beta_0, n, 1.0)
        d = d_s if polarization == "soft" else d_h
    elif model == "sionna":
        j = sionna_compat_coefficients(p, pp, beta_0, n, 1.0, L)
        d = -j[..., 0, 0] if polarization == "soft" else -j[..., 1, 1]
    else:
        raise WavepathsError(f"`model` must be one of ('utd', 'gtd', 'sionna'), got {model!r}")
    return go + d * np.exp(-1j * s * sb**2) / np.sqrt(s)

