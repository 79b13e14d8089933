"""UTD transition function and wedge diffraction coefficients (KP, Luebbers, Keller, seed)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.constants import speed_of_light
from scipy.special import fresnel

from wavepaths.em.fresnel import fresnel_half_space
from wavepaths.em.materials import PEC, itu_material
from wavepaths.em.utd import (
    boundary_offsets,
    diffraction_jones,
    keller_coefficients,
    kp_coefficients,
    luebbers_coefficients,
    luebbers_face_coefficients,
    seed_keller_coefficient,
    seed_scalar_radiance,
    transition_function,
)
from wavepaths.errors import WavepathsError

# ------------------------------------------------------------------ F(x)
# Reference table (diffraction-physics.md §5.1; 0.3 and 1.0 also in jmm/utd's tests), 6 decimals.
F_TABLE = [
    (1e-3, 0.039595 + 0.037673j),
    (1e-2, 0.124205 + 0.106579j),
    (0.1, 0.368104 + 0.234453j),
    (0.3, 0.571713 + 0.272992j),
    (1.0, 0.809525 + 0.232199j),
    (3.0, 0.947242 + 0.132578j),
    (10.0, 0.993041 + 0.048351j),
    (100.0, 0.999925 + 0.004998j),
]


@pytest.mark.parametrize(("x", "expected"), F_TABLE)
def test_transition_function_table(x: float, expected: complex) -> None:
    assert abs(transition_function(x) - expected) <= 1e-6


def test_transition_function_against_fresnel_integral_form() -> None:
    # Independent form (KP eq. 25 via standard Fresnel integrals, as Sionna writes it):
    # F = sqrt(pi x/2) e^{jx} [1 + j - 2j (C(X) - j S(X))], X = sqrt(2x/pi). Accurate for x <~ 1e3.
    x = np.logspace(-8, 3, 300)
    s, c = fresnel(np.sqrt(2 * x / np.pi))
    ref = np.sqrt(np.pi * x / 2) * np.exp(1j * x) * (1 + 1j - 2j * (c - 1j * s))
    assert np.max(np.abs(transition_function(x) - ref)) < 1e-12


def test_transition_function_series_against_the_faddeeva_form_and_the_fresnel_integrals() -> None:
    # from x = 100 on F comes from its asymptotic series: it must agree with the Faddeeva form
    # (scipy's erfcx, relative accuracy ~5e-15 there) and with the Fresnel-integral form
    # (accurate to ~1e-12 up to x ~ 1e3) on both sides of the switch
    from scipy.special import erfcx

    x = np.concatenate([np.linspace(99.0, 101.0, 201), np.geomspace(100.0, 1e6, 300)])
    faddeeva = np.exp(0.25j * np.pi) * np.sqrt(np.pi * x) * erfcx(np.exp(0.25j * np.pi) * np.sqrt(x))
    assert np.max(np.abs(transition_function(x) / faddeeva - 1)) < 2e-14
    low = x[x <= 1e3]
    s, c = fresnel(np.sqrt(2 * low / np.pi))
    ref = np.sqrt(np.pi * low / 2) * np.exp(1j * low) * (1 + 1j - 2j * (c - 1j * s))
    assert np.max(np.abs(transition_function(low) - ref)) < 1e-12


def test_transition_function_limits() -> None:
    assert transition_function(0.0) == 0
    assert transition_function(np.inf) == 1
    small = np.array([1e-12, 1e-8, 1e-4])
    lead = np.sqrt(np.pi * small) * np.exp(0.25j * np.pi)  # F ~ sqrt(pi x) e^{j pi/4}
    assert np.all(np.abs(transition_function(small) / lead - 1) < 3 * np.sqrt(small))
    big = np.array([10.0, 1e2, 1e4, 1e7, 1e8, 2e8, 1e12, 1e300])
    assert np.all(np.abs(transition_function(big) - (1 + 0.5j / big)) <= (1 / big) ** 2 + 4e-16)  # next term 3/(4x^2)
    assert transition_function(np.zeros((2, 3))).shape == (2, 3)
    with pytest.raises(WavepathsError):
        transition_function(-1.0)


@settings(max_examples=300, deadline=None)
@given(x=st.floats(0.0, 1e300))
def test_transition_function_finite_and_bounded(x: float) -> None:
    f = transition_function(x)
    assert np.isfinite(f) and abs(f) <= 1.0 + 1e-12  # |F| rises monotonically from 0 to 1


# ------------------------------------------------------------------ KP / Keller tables
K_REF = 2 * np.pi  # wavelength 1 m


def test_keller_and_utd_reference_values() -> None:
    # diffraction-physics.md §5.2: n = 1.5, phi' = 45°, L = 10 lambda (lambda = 1 m), soft; 4-5 digits.
    phi = np.radians([100, 134, 136, 224, 226, 260])
    keller = [0.11935 - 0.11935j, 6.362 - 6.362j, -6.536 + 6.536j, -6.557 + 6.557j, 6.340 - 6.340j, 0.05970 - 0.05970j]
    utd_s = [0.12584 - 0.11088j, 1.37214 - 0.02397j, -1.54660 + 0.19602j, -1.56793 + 0.21669j, 1.34947 - 0.00202j, 0.06444 - 0.05321j]
    utd_h = [-0.22613 + 0.21017j, -1.50178 + 0.15159j, 1.41429 - 0.06583j, -1.30598 - 0.04113j, 1.61142 - 0.25983j, 0.37955 - 0.35906j]
    g = keller_coefficients(phi, np.radians(45), np.pi / 2, 1.5, K_REF)
    d = kp_coefficients(phi, np.radians(45), np.pi / 2, 1.5, K_REF, 10.0)
    assert np.allclose(g.d_s, keller, rtol=1e-3, atol=1e-5)
    assert np.allclose(d.d_s, utd_s, rtol=0, atol=1e-5)
    assert np.allclose(d.d_h, utd_h, rtol=0, atol=1e-5)


def test_kp_boundary_limit_is_analytic() -> None:
    # cot((pi+-b)/2n) F(kLa) -> n [sqrt(2 pi kL) sgn(eps) - 2 kL eps e^{j pi/4}] e^{j pi/4} (KP eq. 29).
    n, k, L, pp = 1.5, K_REF, 3.0, np.radians(30)
    kl = k * L
    pref = -np.exp(-0.25j * np.pi) / (2 * n * np.sqrt(2 * np.pi * k))
    for eps in (1e-9, -1e-9, 1e-7, -1e-7):
        phi = np.pi + pp - eps  # incident shadow boundary: eps_2 = pi - (phi - phi') = eps
        assert boundary_offsets(phi, pp, n).eps_2 == pytest.approx(eps, abs=1e-15)
        lim = n * (np.sqrt(2 * np.pi * kl) * np.sign(eps) - 2 * kl * eps * np.exp(0.25j * np.pi)) * np.exp(0.25j * np.pi)
        d = kp_coefficients(phi, pp, np.pi / 2, n, k, L)
        # The other three terms are smooth here, so D(eps) - D(-eps) = 2 pref * limit(eps) + O(eps).
        d_m = kp_coefficients(np.pi + pp + eps, pp, np.pi / 2, n, k, L)
        assert abs((d.d_s - d_m.d_s) - 2 * pref * lim) < 1e-6 * abs(pref * lim)
    on = kp_coefficients(np.pi + pp, pp, np.pi / 2, n, k, L)
    plus = kp_coefficients(np.pi + pp - 1e-12, pp, np.pi / 2, n, k, L)
    minus = kp_coefficients(np.pi + pp + 1e-12, pp, np.pi / 2, n, k, L)
    assert abs(on.d_s - 0.5 * (plus.d_s + minus.d_s)) < 1e-9  # exactly on it: the mean


@pytest.mark.parametrize("n", [1.1, 1.5, 1.9, 2.0])
@pytest.mark.parametrize("beta_0", np.radians([90, 45, 20]))
def test_kp_reciprocity_and_sin_beta_scaling(n: float, beta_0: float) -> None:
    phi = np.linspace(0, n * np.pi, 97)[:, None]
    pp = np.linspace(0, n * np.pi, 13)[None, :]
    a = kp_coefficients(phi, pp, beta_0, n, K_REF, 7.0)
    b = kp_coefficients(pp, phi, beta_0, n, K_REF, 7.0)
    assert np.allclose(a.d_s, b.d_s, rtol=1e-12, atol=1e-14) and np.allclose(a.d_h, b.d_h, rtol=1e-12, atol=1e-14)
    # 1/sin(beta_0) prefactor at fixed kL.
    c = kp_coefficients(phi, pp, np.pi / 2, n, K_REF, 7.0)
    assert np.allclose(a.d_h * np.sin(beta_0), c.d_h, rtol=1e-12, atol=1e-14)
    # Soft coefficient vanishes on both faces (Dirichlet).
    assert np.allclose(kp_coefficients(0.0, pp, beta_0, n, K_REF, 7.0).d_s, 0, atol=1e-12)
    assert np.allclose(kp_coefficients(n * np.pi, pp, beta_0, n, K_REF, 7.0).d_s, 0, atol=1e-12)


def test_kp_vanishes_for_flat_plane() -> None:
    # n -> 1: a flat PEC plane does not diffract; D = O(n - 1).
    phi = np.linspace(0.0, np.pi, 51)
    for dn in (1e-3, 1e-6, 1e-12):
        d = kp_coefficients(phi, 0.7, np.pi / 2, 1 + dn, K_REF, 5.0)
        assert np.max(np.abs(d.d_s)) < 100 * dn and np.max(np.abs(d.d_h)) < 100 * dn


# ------------------------------------------------------------------ GTD
def _term_scale(phi: np.ndarray, pp: np.ndarray, n: float, k: float) -> np.ndarray:
    """Sum of |prefactor * cot(eps_i/2n)| over the four Keller terms."""
    eps = np.array(boundary_offsets(phi, pp, n))
    with np.errstate(divide="ignore"):
        cot = 1 / np.tan(eps / (2 * n))
    return np.sum(np.abs(cot), axis=0) / (2 * n * np.sqrt(2 * np.pi * k))


@pytest.mark.parametrize("n", [1.25, 1.5, 1.75, 2.0])
def test_gtd_matches_utd_far_from_boundaries(n: float) -> None:
    phi = np.linspace(0, n * np.pi, 1201)[:, None]
    pp = np.linspace(0.1, n * np.pi - 0.1, 13)[None, :]
    L = 100.0
    eps = np.array(boundary_offsets(phi, pp, n))
    far = np.all(K_REF * L * 2 * np.sin(eps / 2) ** 2 > 200, axis=0)  # kLa > 200 for all terms
    assert far.sum() > 1000
    u = kp_coefficients(phi, pp, np.pi / 2, n, K_REF, L)
    g = keller_coefficients(phi, pp, np.pi / 2, n, K_REF)
    scale = _term_scale(phi, pp, n, K_REF)
    for a, b in ((u.d_s, g.d_s), (u.d_h, g.d_h)):
        assert np.all(np.abs(a - b)[far] <= 0.01 * scale[far])  # |F - 1| <= 1/(2kLa) < 0.25 % per term
        big = far & (np.abs(a) > 0.3 * scale)
        assert np.all(np.abs(a - b)[big] <= 0.01 * np.abs(a)[big])
    # The F -> 1 form of diffraction_jones equals Keller's closed form.
    j = diffraction_jones(phi, pp, np.pi / 2, n, K_REF, L, "gtd")
    assert np.allclose(-j[..., 0, 0][far], g.d_s[far], rtol=1e-10) and np.allclose(-j[..., 1, 1][far], g.d_h[far], rtol=1e-10)


def test_gtd_blows_up_at_boundaries() -> None:
    n, pp = 1.5, np.radians(45)
    for b in (np.pi + pp, np.pi - pp):
        for e in (1e-6, -1e-6, 0.0):
            g = keller_coefficients(b + e, pp, np.pi / 2, n, K_REF)
            u = kp_coefficients(b + e, pp, np.pi / 2, n, K_REF, 10.0)
            assert np.isfinite(g.d_s) and abs(g.d_s) > 1e4 * abs(u.d_s)


# ------------------------------------------------------------------ Luebbers
F35 = 3.5e9
K35 = 2 * np.pi * F35 / speed_of_light


def test_luebbers_reference_table() -> None:
    # diffraction-physics.md §5.3: concrete (eta = 5.24 - 0.6321j), n = 1.5, phi' = 45°, L = 5 m,
    # half-space Fresnel coefficients at Luebbers' angles.
    phi = np.radians([100, 200, 260])
    conc = itu_material("concrete")
    r = luebbers_face_coefficients(conc, conc, F35, phi, np.radians(45), 1.5, "half_space")
    d = luebbers_coefficients(phi, np.radians(45), np.pi / 2, 1.5, K35, 5.0, *r)
    p = kp_coefficients(phi, np.radians(45), np.pi / 2, 1.5, K35, 5.0)
    assert np.allclose(d.d_s, [0.008459 - 0.010606j, -0.090545 + 0.090358j, 0.029548 - 0.027625j], atol=1e-6)
    assert np.allclose(d.d_h, [-0.028773 + 0.031056j, -0.060263 + 0.056052j, 0.052708 - 0.053899j], atol=1e-6)
    assert np.allclose(p.d_s, [0.035305 - 0.034535j, -0.113227 + 0.110901j, 0.017755 - 0.017173j], atol=1e-6)
    assert np.allclose(p.d_h, [-0.064538 + 0.063717j, -0.030029 + 0.028018j, 0.108925 - 0.107876j], atol=1e-6)


def test_luebbers_pec_material_is_kp_exactly() -> None:
    phi = np.linspace(0, 1.7 * np.pi, 101)[:, None]
    pp = np.linspace(0, 1.7 * np.pi, 11)[None, :]
    r = luebbers_face_coefficients(PEC, PEC, F35, phi, pp, 1.7, "slab")
    a = luebbers_coefficients(phi, pp, np.pi / 2, 1.7, K35, 2.0, *r)
    b = kp_coefficients(phi, pp, np.pi / 2, 1.7, K35, 2.0)
    assert np.array_equal(a.d_s, b.d_s) and np.array_equal(a.d_h, b.d_h)


@pytest.mark.parametrize("n", [1.25, 1.5, 2.0])
def test_luebbers_reduces_to_kp_as_eta_to_infinity(n: float) -> None:
    # |r_te + 1| ~ 2 cos/|sqrt(eta)| and |r_tm - 1| ~ 2/(|sqrt(eta)| cos): the TM limit is
    # non-uniform at grazing (r_tm = -1 at cos = 0 for every finite eta), so D_h is checked
    # where both face cosines are >= 0.1.
    phi = np.linspace(0.01, n * np.pi - 0.01, 400)[:, None]
    pp = np.linspace(0.05, n * np.pi - 0.05, 9)[None, :]
    c0 = np.abs(np.sin(pp)) + 0 * phi
    cn = np.abs(np.sin(n * np.pi - phi)) + 0 * pp
    k = K_REF
    ref = kp_coefficients(phi, pp, np.pi / 2, n, k, 3.0)
    ok = (c0 >= 0.1) & (cn >= 0.1)
    for eta, tol_s, tol_h in ((1 - 1e12j, 2e-6, 2e-5), (1 - 1e16j, 2e-8, 2e-7)):
        r0, rn = fresnel_half_space(eta, c0), fresnel_half_space(eta, cn)
        d = luebbers_coefficients(phi, pp, np.pi / 2, n, k, 3.0, r0.r_te, r0.r_tm, rn.r_te, rn.r_tm)
        assert np.max(np.abs(d.d_s - ref.d_s)) <= tol_s * np.max(np.abs(ref.d_s))
        assert np.max(np.abs(d.d_h - ref.d_h)[ok]) <= tol_h * np.max(np.abs(ref.d_h)[ok])


def test_luebbers_with_fixed_face_labels_is_not_reciprocal() -> None:
    # R0 at phi' and Rn at n pi - phi are not symmetric in phi <-> phi' for fixed face labels,
    # so neither is D: the field chain labels the faces so that phi' <= phi, which makes it
    # reciprocal (fields.chain._reciprocal_face_order; tests/fields/test_fields_chain.py).
    conc = itu_material("concrete")
    a, b = np.radians(100), np.radians(45)
    ra = luebbers_face_coefficients(conc, conc, F35, a, b, 1.5)
    rb = luebbers_face_coefficients(conc, conc, F35, b, a, 1.5)
    da = luebbers_coefficients(a, b, np.pi / 2, 1.5, K35, 5.0, *ra)
    db = luebbers_coefficients(b, a, np.pi / 2, 1.5, K35, 5.0, *rb)
    assert abs(da.d_s - db.d_s) > 0.3 * abs(da.d_s)


# ------------------------------------------------------------------ Jones matrix
def test_diffraction_jones_utd_is_minus_diag() -> None:
    phi = np.linspace(0.1, 1.4 * np.pi, 5)
    j = diffraction_jones(phi, 0.8, np.radians(60), 1.5, K_REF, 2.0, "utd")
    d = kp_coefficients(phi, 0.8, np.radians(60), 1.5, K_REF, 2.0)
    assert j.shape == (5, 2, 2)
    assert np.array_equal(j[:, 0, 0], -d.d_s) and np.array_equal(j[:, 1, 1], -d.d_h)
    assert np.all(j[:, 0, 1] == 0) and np.all(j[:, 1, 0] == 0)
    with pytest.raises(WavepathsError, match="model"):
        diffraction_jones(phi, 0.8, 1.0, 1.5, K_REF, 2.0, "ptd")  # type: ignore[arg-type]


# ------------------------------------------------------------------ seed paper
def test_seed_coefficient_is_real_part_of_keller() -> None:
    # delta, alpha are measured from the incident face's normal: delta = phi - pi/2, alpha = phi' - pi/2.
    lam = 0.5
    k = 2 * np.pi / lam
    n = np.array([1.2, 1.5, 1.8, 2.0])[:, None]
    phi = np.radians(np.array([20.0, 95.0, 170.0, 250.0]))[None, :]
    pp = np.radians(35.0)
    beta = np.radians(70.0)
    inside = phi < n * np.pi
    g = keller_coefficients(np.minimum(phi, n * np.pi), pp, beta, n, k)
    for c, d_keller in ((-1, g.d_s), (+1, g.d_h)):
        seed = seed_keller_coefficient(lam, n, beta, phi - np.pi / 2, pp - np.pi / 2, c)
        rotated = d_keller * np.exp(0.25j * np.pi)  # Keller without its e^{-j pi/4}: real
        assert np.allclose(rotated.imag[inside], 0, atol=1e-12)
        assert np.allclose(seed[inside], rotated.real[inside] / np.sqrt(2), rtol=1e-12)
        assert np.allclose(np.abs(seed[inside]), np.abs(d_keller[inside]) / np.sqrt(2), rtol=1e-12)


def test_seed_radiance_drops_the_reflection_term() -> None:
    lam, n, beta, pp = 0.3, 1.5, np.radians(80), np.radians(40)
    phi = np.radians(np.array([150.0, 200.0, 250.0]))
    lr = seed_scalar_radiance(2.0, lam, n, beta, phi - np.pi / 2, pp - np.pi / 2)
    g = keller_coefficients(phi, pp, beta, n, 2 * np.pi / lam)
    first = 0.5 * (g.d_s + g.d_h)  # Keller's incident-boundary term A; (D_s - D_h)/2 = -B
    assert np.allclose(lr, 2.0 * 2 * np.abs(first) ** 2, rtol=1e-12)  # 2 L_inc |A|^2
    unpolarised = 0.5 * (np.abs(g.d_s) ** 2 + np.abs(g.d_h) ** 2)  # = |A|^2 + |B|^2
    assert np.all(np.abs(lr / 2.0 - unpolarised) > 0.01 * unpolarised)


# ------------------------------------------------------------------ robustness
@settings(max_examples=300, deadline=None)
@given(
    u=st.floats(0, 1), v=st.floats(0, 1),
    beta_0=st.floats(0, np.pi),
    n=st.floats(1.0, 2.0, exclude_min=True),
    k=st.floats(1e-3, 1e4),
    L=st.floats(0, 1e6),
    r=st.complex_numbers(max_magnitude=1.0, allow_nan=False, allow_infinity=False),
)
def test_no_nan_for_finite_inputs(u, v, beta_0, n, k, L, r) -> None:
    phi, pp = u * n * np.pi, v * n * np.pi
    outs = [
        *kp_coefficients(phi, pp, beta_0, n, k, L),
        *luebbers_coefficients(phi, pp, beta_0, n, k, L, r, -r, r, r),
        *keller_coefficients(phi, pp, beta_0, n, k),
    ]
    for model in ("utd", "gtd", "sionna"):
        outs.extend(diffraction_jones(phi, pp, beta_0, n, k, L, model, r, 1, -1, r).ravel())
    assert all(np.isfinite(o) for o in outs)


def test_grazing_beta_and_n_near_one() -> None:
    phi = np.linspace(0, 1.5 * np.pi, 31)
    for b in (0.0, 1e-300, 1e-12, np.pi - 1e-12, np.pi):
        d = kp_coefficients(phi, 0.4, b, 1.5, K_REF, 5.0)
        ref = kp_coefficients(phi, 0.4, np.pi / 2, 1.5, K_REF, 5.0)
        assert np.all(np.isfinite(d.d_s)) and np.all(np.isfinite(d.d_h))
        assert np.all(np.abs(d.d_h) <= 1e6 * np.abs(ref.d_h) * (1 + 1e-9))  # sin(beta_0) floored at 1e-6
        j = diffraction_jones(phi, 0.4, b, 1.5, K_REF, 5.0, "sionna")
        assert np.all(np.isfinite(j))
    for n in (1 + 1e-15, 1 + 1e-9):
        assert np.all(np.isfinite(diffraction_jones(phi * n / 1.5, 0.4, 1.0, n, K_REF, 5.0, "gtd")))


def test_input_validation() -> None:
    with pytest.raises(WavepathsError, match="n"):
        kp_coefficients(0.1, 0.2, 1.0, 2.5, K_REF, 1.0)
    with pytest.raises(WavepathsError, match="k"):
        kp_coefficients(0.1, 0.2, 1.0, 1.5, 0.0, 1.0)
    with pytest.raises(WavepathsError, match="L"):
        kp_coefficients(0.1, 0.2, 1.0, 1.5, 1.0, -1.0)
    with pytest.raises(WavepathsError, match="finite"):
        kp_coefficients(np.nan, 0.2, 1.0, 1.5, 1.0, 1.0)
    with pytest.raises(WavepathsError, match="finite"):
        luebbers_coefficients(0.1, 0.2, 1.0, 1.5, 1.0, 1.0, np.nan, 1, -1, 1)


def test_transition_function_magnitude_is_at_most_one_and_sqrt_pi_x():
    """The two facts utd_magnitude_bound rests on: |F(x)| <= 1 and |F(x)| <= sqrt(pi x),
    on a dense grid from 1e-12 to 1e9 (within rounding)."""
    from wavepaths.em.utd import transition_function

    x = np.logspace(-12, 9, 200_001)
    f = np.abs(transition_function(x))
    assert f.max() <= 1.0 + 1e-15
    assert (f <= np.sqrt(np.pi * x) * (1 + 1e-15)).all()


def test_utd_magnitude_bound_holds_for_passive_faces_near_boundaries_and_at_grazing(rng):
    """max(|D_s|, |D_h|) <= the bound for random wedges, angles (a quarter within 1e-3 to
    1e-13 rad of the incident shadow boundary, a quarter of a reflection boundary),
    grazing and broadside incidence, 0.1-100 GHz, L from 1 cm to 1 km, and random passive
    face coefficients; tight for KP (the median ratio is above 0.9), and it does not grow
    with frequency."""
    from wavepaths.em.utd import kp_coefficients, luebbers_coefficients, utd_magnitude_bound

    N = 100_000
    n = rng.uniform(1.0 + 1e-4, 2.0, N)
    pp = rng.uniform(0, 1, N) * n * np.pi
    p = rng.uniform(0, 1, N) * n * np.pi
    q = N // 4
    offs = rng.normal(0, 1e-3, N) * rng.choice([1.0, 1e-6, 1e-10], N)
    p[:q] = np.clip(pp[:q] + np.pi + offs[:q], 0, n[:q] * np.pi)
    p[q:2 * q] = np.clip(np.pi - pp[q:2 * q] + offs[q:2 * q], 0, n[q:2 * q] * np.pi)
    b0 = np.concatenate([rng.uniform(1e-7, 1e-3, N // 10), rng.uniform(0.01, np.pi - 0.01, N - N // 10)])
    k = 2 * np.pi * 10 ** rng.uniform(8, 11, N) / 299_792_458.0
    L = 10 ** rng.uniform(-2, 3, N)
    bound = utd_magnitude_bound(p, pp, np.abs(np.sin(b0)), n, k, L)

    def passive():
        return np.sqrt(rng.uniform(0, 1, N)) * np.exp(2j * np.pi * rng.uniform(size=N))

    ds, dh = luebbers_coefficients(p, pp, b0, n, k, L, passive(), passive(), passive(), passive())
    assert (np.maximum(abs(ds), abs(dh)) <= bound * (1 + 1e-12)).all()
    ds, dh = kp_coefficients(p, pp, b0, n, k, L)
    ratio = np.maximum(abs(ds), abs(dh)) / bound
    assert ratio.max() <= 1 + 1e-12 and np.median(ratio) > 0.9
    assert (utd_magnitude_bound(p, pp, np.abs(np.sin(b0)), n, 3 * k, L) <= bound * (1 + 1e-12)).all()


def test_utd_magnitude_bound_holds_for_the_sionna_compat_matrix(rng):
    """Sionna's J = R0 (d1 - d4) + Rn (d2 - d3) with passive face matrices: its spectral norm
    is at most |d1| + |d2| + |d3| + |d4|, hence within the same bound (the tradeoff
    benchmark prunes with Sionna's coefficient model)."""
    from wavepaths.em.sionna_compat import sionna_compat_coefficients
    from wavepaths.em.utd import utd_magnitude_bound

    N = 20_000
    n = rng.uniform(1.0 + 1e-4, 2.0, N)
    pp = rng.uniform(0, 1, N) * n * np.pi
    p = rng.uniform(0, 1, N) * n * np.pi
    p[: N // 4] = np.clip(pp[: N // 4] + np.pi + rng.normal(0, 1e-6, N // 4), 0, n[: N // 4] * np.pi)
    b0 = rng.uniform(0.01, np.pi - 0.01, N)
    k = 2 * np.pi * 10 ** rng.uniform(8, 11, N) / 299_792_458.0
    L = 10 ** rng.uniform(-2, 3, N)

    def passive():
        return np.sqrt(rng.uniform(0, 1, N)) * np.exp(2j * np.pi * rng.uniform(size=N))

    J = sionna_compat_coefficients(p, pp, b0, n, k, L, passive(), passive(), passive(), passive())
    norm = np.linalg.norm(J, ord=2, axis=(-2, -1))
    assert (norm <= utd_magnitude_bound(p, pp, np.abs(np.sin(b0)), n, k, L) * (1 + 1e-12)).all()
