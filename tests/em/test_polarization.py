"""Invariants of the spherical bases, Jones basis changes and coherence matrices."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wavepaths.em.polarization import (
    as_unit_directions,
    coherence_from_jones,
    degree_of_polarization,
    field_components,
    field_vector,
    jones_basis_change,
    partially_polarized_coherence,
    propagate_coherence,
    radiance,
    seed_diffracted_coherence,
    spherical_unit_vectors,
    theta_phi_from_direction,
    unpolarized_coherence,
)
from wavepaths.errors import WavepathsError

POLES = [(0.0, 0.0, 1.0), (0.0, 0.0, -1.0), (1e-300, 0.0, 1.0), (0.0, -1e-17, -1.0),
         (3e-10, 2e-10, 1.0), (0.0, 0.0, 1e-200)]


def random_directions(rng: np.random.Generator, n: int) -> np.ndarray:
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def random_complex(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    return rng.normal(size=shape) + 1j * rng.normal(size=shape)


directions_strategy = st.one_of(
    st.sampled_from(POLES),
    st.tuples(*[st.floats(-1.0, 1.0, allow_subnormal=True)] * 3).filter(
        lambda v: any(c != 0.0 for c in v)
    ),
)


# --- spherical unit vectors and angles ------------------------------------------------


def test_spherical_vectors_match_closed_form_away_from_poles() -> None:
    rng = np.random.default_rng(1)
    d = random_directions(rng, 500)
    theta, phi = theta_phi_from_direction(d)
    th, ph = spherical_unit_vectors(d)
    ct, st_, cp, sp = np.cos(theta), np.sin(theta), np.cos(phi), np.sin(phi)
    np.testing.assert_allclose(np.stack([st_ * cp, st_ * sp, ct], -1), d, atol=1e-14)
    np.testing.assert_allclose(th, np.stack([ct * cp, ct * sp, -st_], -1), atol=1e-14)
    np.testing.assert_allclose(ph, np.stack([-sp, cp, 0 * sp], -1), atol=1e-14)
    assert np.all((theta >= 0) & (theta <= np.pi) & (phi > -np.pi) & (phi <= np.pi))


def test_poles_follow_sionna_choice_phi_zero() -> None:
    theta, phi = theta_phi_from_direction([[0, 0, 2.0], [0, 0, -1.0]])
    np.testing.assert_array_equal(theta, [0.0, np.pi])
    np.testing.assert_array_equal(phi, [0.0, 0.0])
    th, ph = spherical_unit_vectors([[0, 0, 1.0], [0, 0, -1.0]])
    np.testing.assert_allclose(th, [[1, 0, 0], [-1, 0, 0]], atol=0)
    np.testing.assert_allclose(ph, [[0, 1, 0], [0, 1, 0]], atol=0)


def test_theta_is_accurate_near_the_pole() -> None:
    theta, _ = theta_phi_from_direction([[1e-8, 0.0, 1.0]])
    assert theta[0] == pytest.approx(1e-8, rel=1e-12)  # arccos(z) would give 0


@settings(max_examples=200, deadline=None)
@given(directions_strategy)
def test_triad_orthonormal_right_handed_and_finite(v: tuple[float, float, float]) -> None:
    r = as_unit_directions(v)
    th, ph = spherical_unit_vectors(v)
    theta, phi = theta_phi_from_direction(v)
    assert np.all(np.isfinite(th)) and np.all(np.isfinite(ph))
    assert np.isfinite(theta) and np.isfinite(phi)
    frame = np.stack([r, th, ph])
    np.testing.assert_allclose(frame @ frame.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(np.cross(r, th), ph, atol=1e-12)
    assert np.linalg.det(frame) == pytest.approx(1.0, abs=1e-12)


def test_field_vector_round_trip() -> None:
    rng = np.random.default_rng(2)
    d = np.concatenate([random_directions(rng, 200), np.asarray(POLES)])
    e = random_complex(rng, (len(d), 2))
    v = field_vector(e, d)
    np.testing.assert_allclose(np.sum(v * as_unit_directions(d), -1), 0, atol=1e-14)
    np.testing.assert_allclose(field_components(v, d), e, atol=1e-13)


# --- basis changes --------------------------------------------------------------------


def _random_transverse_basis(rng: np.random.Generator, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = rng.normal(size=k.shape)
    u = a - np.sum(a * k, -1, keepdims=True) * k
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    return u, np.cross(k, u)


def test_basis_change_is_orthogonal_and_preserves_the_field() -> None:
    rng = np.random.default_rng(3)
    k = random_directions(rng, 300)
    fu, fv = _random_transverse_basis(rng, k)
    tu, tv = _random_transverse_basis(rng, k)
    b = jones_basis_change(fu, fv, tu, tv)
    np.testing.assert_allclose(b @ np.swapaxes(b, -1, -2), np.broadcast_to(np.eye(2), b.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(b), 1.0, atol=1e-12)
    e = random_complex(rng, (300, 2))
    e_new = np.einsum("...ij,...j->...i", b, e)
    field_old = e[:, :1] * fu + e[:, 1:] * fv
    field_new = e_new[:, :1] * tu + e_new[:, 1:] * tv
    np.testing.assert_allclose(field_new, field_old, atol=1e-12)
    # Round trip, and to the spherical basis of k.
    back = jones_basis_change(tu, tv, fu, fv)
    np.testing.assert_allclose(back @ b, np.broadcast_to(np.eye(2), b.shape), atol=1e-12)
    th, ph = spherical_unit_vectors(k)
    s = jones_basis_change(fu, fv, th, ph)
    np.testing.assert_allclose(field_vector(np.einsum("...ij,...j->...i", s, e), k), field_old, atol=1e-12)


def test_basis_change_for_reversed_direction_is_a_reflection() -> None:
    rng = np.random.default_rng(4)
    k = random_directions(rng, 50)
    th, ph = spherical_unit_vectors(k)
    th_r, ph_r = spherical_unit_vectors(-k)
    b = jones_basis_change(th_r, ph_r, th, ph)
    # theta_hat(-k) = theta_hat(k) and phi_hat(-k) = -phi_hat(k) away from the poles.
    np.testing.assert_allclose(b, np.broadcast_to(np.diag([1.0, -1.0]), b.shape), atol=1e-12)


def test_basis_change_rejects_bases_of_different_directions() -> None:
    with pytest.raises(WavepathsError, match="same transverse plane"):
        jones_basis_change([1, 0, 0], [0, 1, 0], [1, 0, 0], [0, 0, 1])
    with pytest.raises(WavepathsError, match="unit"):
        jones_basis_change([2, 0, 0], [0, 1, 0], [1, 0, 0], [0, 1, 0])
    with pytest.raises(WavepathsError, match=r"\(\.\.\., 3\)"):
        jones_basis_change([1, 0], [0, 1, 0], [1, 0, 0], [0, 1, 0])


# --- coherence matrices ---------------------------------------------------------------


def test_coherence_form_equals_jones_form() -> None:
    rng = np.random.default_rng(5)
    e = random_complex(rng, (1000, 2))
    m = random_complex(rng, (1000, 2, 2))
    me = np.einsum("...ij,...j->...i", m, e)
    np.testing.assert_allclose(
        propagate_coherence(m, coherence_from_jones(e)), coherence_from_jones(me), rtol=0, atol=1e-12
    )
    np.testing.assert_allclose(radiance(coherence_from_jones(e)), np.sum(np.abs(e) ** 2, -1), rtol=1e-14)


def test_seed_formula_is_diagonal_special_case() -> None:
    rng = np.random.default_rng(6)
    e = random_complex(rng, (500, 2))
    j = partially_polarized_coherence(e, rng.uniform(0, 1, 500))
    dp, ds = rng.normal(size=500), rng.normal(size=500)
    m = np.zeros((500, 2, 2))
    m[:, 0, 0], m[:, 1, 1] = dp, ds
    np.testing.assert_allclose(seed_diffracted_coherence(j, dp, ds), propagate_coherence(m, j), atol=1e-13)


def test_seed_formula_refuses_complex_coefficients() -> None:
    j = unpolarized_coherence()
    with pytest.raises(WavepathsError, match="propagate_coherence"):
        seed_diffracted_coherence(j, 0.5 + 0.1j, 0.3)
    seed_diffracted_coherence(j, np.complex128(0.5), 0.3)  # zero imaginary part is fine


def test_unpolarized_source_diffracted_radiance() -> None:
    rng = np.random.default_rng(7)
    power = rng.uniform(0.1, 10, 200)
    dp, ds = rng.normal(size=200), rng.normal(size=200)
    j = unpolarized_coherence(power)
    expected = 0.5 * (dp**2 + ds**2) * power
    np.testing.assert_allclose(radiance(seed_diffracted_coherence(j, dp, ds)), expected, rtol=1e-13)
    # Complex UTD coefficients through M J M^H: (|D_par|^2 + |D_perp|^2) / 2.
    dpc, dsc = random_complex(rng, (200,)), random_complex(rng, (200,))
    m = np.zeros((200, 2, 2), complex)
    m[:, 0, 0], m[:, 1, 1] = dpc, dsc
    np.testing.assert_allclose(
        radiance(propagate_coherence(m, j)), 0.5 * (abs(dpc) ** 2 + abs(dsc) ** 2) * power, rtol=1e-13
    )


def test_unpolarized_is_basis_independent_and_degree_zero() -> None:
    rng = np.random.default_rng(8)
    k = random_directions(rng, 20)
    fu, fv = _random_transverse_basis(rng, k)
    th, ph = spherical_unit_vectors(k)
    b = jones_basis_change(fu, fv, th, ph)
    j = unpolarized_coherence(np.full(20, 3.0))
    np.testing.assert_allclose(propagate_coherence(b, j), j, atol=1e-14)
    np.testing.assert_allclose(degree_of_polarization(j), 0.0, atol=1e-7)


def test_partial_polarization_radiance_and_degree() -> None:
    rng = np.random.default_rng(9)
    e = random_complex(rng, (300, 2))
    g = rng.uniform(0, 1, 300)
    j = partially_polarized_coherence(e, g)
    np.testing.assert_allclose(radiance(j), np.sum(np.abs(e) ** 2, -1), rtol=1e-13)
    np.testing.assert_allclose(degree_of_polarization(j), g, atol=1e-7)
    np.testing.assert_allclose(j, np.conj(np.swapaxes(j, -1, -2)), atol=0)
    assert np.all(np.linalg.eigvalsh(j) > -1e-12)
    np.testing.assert_allclose(degree_of_polarization(coherence_from_jones(e)), 1.0, atol=1e-7)
    assert degree_of_polarization(np.zeros((2, 2)))[()] == 0.0


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: coherence_from_jones([1, 2, 3]), r"\(\.\.\., 2\)"),
        (lambda: radiance(np.eye(3)), r"\(\.\.\., 2, 2\)"),
        (lambda: partially_polarized_coherence([1, 0], 1.5), r"\[0, 1\]"),
        (lambda: unpolarized_coherence(-1.0), "non-negative"),
        (lambda: spherical_unit_vectors([0, 0, 0]), "non-zero"),
        (lambda: spherical_unit_vectors([np.nan, 0, 1]), "finite"),
        (lambda: theta_phi_from_direction([0, 0, 1], pole_tolerance=-1), "pole_tolerance"),
    ],
)
def test_bad_input_raises_named_errors(call, match: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(WavepathsError, match=match):
        call()
