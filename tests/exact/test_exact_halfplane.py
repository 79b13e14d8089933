"""Sommerfeld half-plane: the exact solution, and KP-UTD reproducing it to machine precision."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import fresnel

from wavepaths.em.utd import boundary_offsets, kp_coefficients
from wavepaths.exact import halfplane_plane_wave, utd_wedge_total_field
from wavepaths.errors import WavepathsError

pytestmark = pytest.mark.exact

# Reference table (diffraction-physics.md §1): unit plane wave, phi' = 60°, 6 decimals.
TABLE = [
    (10, 30, -1.729123 + 0.714559j, 0.316278 + 0.543087j),
    (10, 90, -0.077930 + 1.514618j, -1.334915 - 0.256972j),
    (10, 120, 0.720682 - 1.301441j, -0.118389 - 0.757420j),
    (10, 180, 0.357178 + 0.722768j, 0.283662 + 0.958924j),
    (10, 240, -0.402051 + 0.201504j, -0.437020 + 0.342517j),
    (10, 270, -0.077930 + 0.130231j, -0.108509 + 0.256972j),
    (10, 330, -0.007411 + 0.022365j, -0.037989 + 0.149107j),
    (50, 30, -0.213684 - 0.634687j, 1.716695 - 0.595751j),
    (50, 120, 0.480346 - 0.247547j, 1.445313 + 0.014828j),
    (50, 180, 0.892276 + 0.186397j, 0.991203 + 0.132352j),
    (50, 240, 0.454110 + 0.147180j, 0.510856 + 0.115195j),
    (50, 330, 0.009389 - 0.005096j, 0.060231 - 0.033840j),
    (200, 30, -1.908978 - 0.403974j, 0.052671 - 0.414962j),
    (200, 120, 0.603065 - 0.947487j, 1.090252 - 0.074190j),
    (200, 180, 0.808124 + 0.490692j, 0.862319 + 0.506366j),
    (200, 240, 0.227933 + 0.432176j, 0.259254 + 0.441121j),
    (200, 330, 0.005133 + 0.001488j, 0.033217 + 0.009499j),
]


@pytest.mark.parametrize(("k_rho", "phi_deg", "soft", "hard"), TABLE)
def test_reference_table(k_rho: float, phi_deg: float, soft: complex, hard: complex) -> None:
    phi, pp = np.radians(phi_deg), np.radians(60)
    assert abs(halfplane_plane_wave(k_rho, phi, pp, "soft") - soft) < 1e-6
    assert abs(halfplane_plane_wave(k_rho, phi, pp, "hard") - hard) < 1e-6


def _fresnel_form(k_rho: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """U = e^{jk rho cos psi} (1+j)/2 [(1-j)/2 + C(X) - j S(X)], X = 2 sqrt(k rho/pi) cos(psi/2)."""
    s, c = fresnel(2 * np.sqrt(k_rho / np.pi) * np.cos(psi / 2))
    return np.exp(1j * k_rho * np.cos(psi)) * (1 + 1j) / 2 * ((1 - 1j) / 2 + c - 1j * s)


def test_against_fresnel_integral_form() -> None:
    k_rho = np.array([0.5, 10.0, 50.0, 200.0])[:, None]
    phi = np.linspace(0, 2 * np.pi, 181)[None, :]
    for pp in np.radians([10, 60, 135, 250]):
        for pol, sign in (("soft", -1), ("hard", 1)):
            ref = _fresnel_form(k_rho, phi - pp) + sign * _fresnel_form(k_rho, phi + pp)
            assert np.max(np.abs(halfplane_plane_wave(k_rho, phi, pp, pol) - ref)) < 1e-11


def test_boundary_conditions_and_edge_value() -> None:
    pp = np.radians(70)
    k_rho = np.array([1.0, 20.0, 300.0])
    for face in (0.0, 2 * np.pi):
        assert np.all(np.abs(halfplane_plane_wave(k_rho, face, pp, "soft")) < 1e-13)
    h = 1e-6
    for face, step in ((0.0, h), (2 * np.pi, -h)):
        d = (halfplane_plane_wave(k_rho, face + step, pp, "hard") - halfplane_plane_wave(k_rho, face, pp, "hard")) / step
        assert np.all(np.abs(d) < 2 * h * (1 + k_rho) ** 2)  # one-sided difference: O(h (k rho)^2)
    # At the edge the hard field is 1 (continuous, as U(0, psi) = 1/2), the soft field 0.
    assert abs(halfplane_plane_wave(0.0, 1.0, pp, "hard") - 1) < 1e-15
    assert abs(halfplane_plane_wave(0.0, 1.0, pp, "soft")) < 1e-15


def _grid_with_boundaries(pp: float, n: float) -> np.ndarray:
    phi = np.linspace(0, n * np.pi, 2001)
    b = np.array([np.pi + pp, pp - np.pi, np.pi - pp, (2 * n - 1) * np.pi - pp])
    b = b[(b > 0) & (b < n * np.pi)]
    return np.concatenate([phi, b, b + 1e-6, b - 1e-6, b + 1e-12, b - 1e-12])


@pytest.mark.parametrize("k_rho", [10.0, 50.0, 200.0])
@pytest.mark.parametrize("phi_prime_deg", [5.0, 60.0, 90.0, 150.0, 200.0, 300.0])
@pytest.mark.parametrize("polarization", ["soft", "hard"])
def test_kp_utd_equals_sommerfeld(k_rho: float, phi_prime_deg: float, polarization: str) -> None:
    pp = np.radians(phi_prime_deg)
    phi = _grid_with_boundaries(pp, 2.0)
    exact = halfplane_plane_wave(k_rho, phi, pp, polarization)
    utd = utd_wedge_total_field(k_rho, phi, pp, 2.0, polarization)
    assert np.max(np.abs(utd - exact)) < 1e-9


@pytest.mark.parametrize("beta_0_deg", [45.0, 20.0])
@pytest.mark.parametrize("polarization", ["soft", "hard"])
def test_oblique_incidence_3d(beta_0_deg: float, polarization: str) -> None:
    # 3-D plane wave along s' = (-sin b0 cos phi', -sin b0 sin phi', cos b0); observer (rho, phi, z).
    # Exact: 2-D solution at k_t = k sin b0 times exp(-jkz cos b0).
    # UTD: GO + u_i(Q) D(b0; k, L = s sin^2 b0) e^{-jks}/sqrt(s), s = rho/sin b0, z_Q = z - s cos b0.
    k, b0, pp = 2 * np.pi, np.radians(beta_0_deg), np.radians(75)
    sb, cb = np.sin(b0), np.cos(b0)
    rho, z = 3.0, 1.7
    phi = _grid_with_boundaries(pp, 2.0)
    exact = halfplane_plane_wave(k * sb * rho, phi, pp, polarization) * np.exp(-1j * k * z * cb)
    sign = -1.0 if polarization == "soft" else 1.0
    # GO lit tests on the same floating-point offsets as the coefficients (boundary_offsets
    # with N = 0, or N = 1 for the n-face), weight 1/2 exactly on a boundary.
    step = lambda x: np.where(x > 0, 1.0, np.where(x < 0, 0.0, 0.5))  # noqa: E731
    w_inc = step(np.pi - np.abs(phi - pp))
    w_0 = step(np.pi - (phi + pp))
    w_n = step((np.pi + (phi + pp)) - 4 * np.pi)
    eps = boundary_offsets(phi, pp, 2.0)
    near = np.abs(eps.eps_2) < 1e-3
    assert np.array_equal(w_inc[near], step(eps.eps_2)[near])
    plane = lambda a: np.exp(1j * k * sb * rho * np.cos(a)) * np.exp(-1j * k * z * cb)  # noqa: E731
    go = w_inc * plane(phi - pp) + sign * (w_0 * plane(phi + pp) + w_n * plane(phi + pp - 4 * np.pi))
    s = rho / sb
    d = kp_coefficients(phi, pp, b0, 2.0, k, s * sb**2)
    dd = d.d_s if polarization == "soft" else d.d_h
    u_q = np.exp(-1j * k * (z - s * cb) * cb)
    utd = go + u_q * dd * np.exp(-1j * k * s) / np.sqrt(s)
    assert np.max(np.abs(utd - exact)) < 1e-9
    # The helper's beta_0 option is the same construction at z = 0.
    helper = utd_wedge_total_field(k * rho, phi, pp, 2.0, polarization, beta_0=b0)
    assert np.max(np.abs(helper - halfplane_plane_wave(k * sb * rho, phi, pp, polarization))) < 1e-9


@pytest.mark.parametrize("polarization", ["soft", "hard"])
def test_total_field_continuous_across_boundaries(polarization: str) -> None:
    pp, k_rho = np.radians(60), 50.0
    for b in (np.pi + pp, np.pi - pp):
        jumps = []
        for e in (1e-3, 1e-5, 1e-7):
            u = utd_wedge_total_field(k_rho, np.array([b - e, b + e]), pp, 2.0, polarization)
            jumps.append(abs(u[1] - u[0]))
        assert jumps[0] > jumps[1] > jumps[2] and jumps[2] < 1e-5 * k_rho**0.5


def test_input_checks() -> None:
    with pytest.raises(WavepathsError, match="polarization"):
        halfplane_plane_wave(1.0, 1.0, 1.0, "TE")  # type: ignore[arg-type]
    with pytest.raises(WavepathsError, match="k_rho"):
        halfplane_plane_wave(-1.0, 1.0, 1.0, "soft")


def test_angles_outside_the_free_space_are_refused():
    """The Fresnel form and the series extend into the wedge with values that are no field (a
    review got 1.56 from a soft wedge at phi = -0.5): refused, rounding (1e-9 rad) let through."""
    import numpy as np
    import pytest

    from wavepaths.errors import WavepathsError
    from wavepaths.exact.halfplane import halfplane_plane_wave
    from wavepaths.exact.wedge import wedge_plane_wave

    with pytest.raises(WavepathsError, match="phi"):
        wedge_plane_wave(10.0, -0.5, 1.0, 1.5, "soft")
    with pytest.raises(WavepathsError, match="phi_prime"):
        wedge_plane_wave(10.0, 1.0, 1.5 * np.pi + 1e-6, 1.5, "hard")
    with pytest.raises(WavepathsError, match="phi"):
        halfplane_plane_wave(10.0, 2 * np.pi + 1e-3, 1.0, "soft")
    assert abs(wedge_plane_wave(10.0, 1.5 * np.pi + 1e-12, 1.0, 1.5, "soft")) < 1e-9  # the face, to rounding
    assert np.isfinite(halfplane_plane_wave(10.0, np.array([0.0, 2 * np.pi]), 1.0, "hard")).all()
