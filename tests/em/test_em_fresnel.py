"""Fresnel half-space and single-layer slab coefficients (ITU-R P.2040-3 eqs. 37, 43-44)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.constants import speed_of_light

from wavepaths.em.fresnel import fresnel_half_space, reflection_coefficients, slab_coefficients
from wavepaths.em.materials import ABSORBER, PEC, Material, itu_material
from wavepaths.errors import WavepathsError

F35 = 3.5e9
LAMBDA35 = speed_of_light / F35
ETA_CONCRETE_35 = 5.24 - 0.6321430346327808j  # P.2040 Table 3 at 3.5 GHz

# Reference table (diffraction-physics.md §8): concrete, 3.5 GHz, slab d = 0.2 m, 5 decimals.
SLAB_TABLE = [
    # θ°, r_TE, r_TM, R_TE, R_TM, T_TE, T_TM
    (0, -0.39376 + 0.02537j, 0.39376 - 0.02537j, -0.39502 + 0.03108j, 0.39502 - 0.03108j, -0.06604 - 0.09038j, -0.06604 - 0.09038j),
    (45, -0.51172 + 0.02448j, 0.26126 - 0.02506j, -0.50981 + 0.01943j, 0.26024 - 0.02172j, 0.07461 - 0.04733j, 0.09300 - 0.06126j),
    (80, -0.84606 + 0.01046j, -0.38798 - 0.01979j, -0.84742 + 0.01283j, -0.38977 - 0.01649j, 0.01410 + 0.02680j, 0.04892 + 0.07625j),
    (89, -0.98333 + 0.00123j, -0.91489 - 0.00376j, -0.98358 + 0.00149j, -0.91589 - 0.00243j, 0.00125 + 0.00325j, 0.00798 + 0.01520j),
]


@pytest.mark.parametrize("row", SLAB_TABLE, ids=lambda r: f"theta={r[0]}")
def test_concrete_slab_table(row: tuple) -> None:
    theta, r_te, r_tm, s_rte, s_rtm, s_tte, s_ttm = row
    c = np.cos(np.radians(theta))
    hs = fresnel_half_space(ETA_CONCRETE_35, c)
    sl = slab_coefficients(ETA_CONCRETE_35, c, 0.2, LAMBDA35)
    got = [hs.r_te, hs.r_tm, sl.r_te, sl.r_tm, sl.t_te, sl.t_tm]
    for g, e in zip(got, [r_te, r_tm, s_rte, s_rtm, s_tte, s_ttm]):
        assert abs(g - e) < 1e-5  # table rounded to 5 decimals


def test_material_api_matches_table() -> None:
    m = itu_material("concrete", 0.2)
    c = np.cos(np.radians([[0.0, 45.0], [80.0, 89.0]]))
    slab = reflection_coefficients(m, F35, c)
    hs = reflection_coefficients(m, F35, c, "half_space")
    assert slab.r_te.shape == (2, 2)
    assert abs(slab.r_tm[0, 1] - SLAB_TABLE[1][4]) < 1e-5
    assert abs(hs.r_te[1, 0] - SLAB_TABLE[2][1]) < 1e-5


def test_pec_and_absorber_exact() -> None:
    c = np.linspace(0.0, 1.0, 7).reshape(7, 1)
    r = reflection_coefficients(PEC, F35, c)
    assert r.r_te.shape == (7, 1)
    assert np.all(r.r_te == -1.0) and np.all(r.r_tm == 1.0)
    a = reflection_coefficients(ABSORBER, F35, c, "half_space")
    assert np.all(a.r_te == 0.0) and np.all(a.r_tm == 0.0)


def test_normal_incidence_tm_is_minus_te() -> None:
    for eta in (ETA_CONCRETE_35, 2.0, 80 - 30j, 1 - 1e9j):
        hs = fresnel_half_space(eta, 1.0)
        sl = slab_coefficients(eta, 1.0, 0.13, 0.05)
        assert abs(hs.r_tm + hs.r_te) < 1e-14
        assert abs(sl.r_tm + sl.r_te) < 1e-13
        assert abs(sl.t_tm - sl.t_te) < 1e-13


def test_pec_limit_of_eta_and_grazing() -> None:
    # r_te → −1 + 2cosθ/√η and r_tm → +1 − 2/(√η cosθ): non-uniform at grazing.
    eta = 1 - 1e12j
    c = np.array([1.0, 0.5, 0.1, 0.01])
    r = fresnel_half_space(eta, c)
    assert np.all(np.abs(r.r_te + 1) <= 2.01 * c / abs(np.sqrt(eta)))
    assert np.all(np.abs(r.r_tm - 1) <= 2.01 / (abs(np.sqrt(eta)) * c))
    g = fresnel_half_space(eta, 0.0)  # exactly grazing: −1 for any finite η
    assert abs(g.r_te + 1) < 1e-15 and abs(g.r_tm + 1) < 1e-15


def test_thin_slab_is_transparent() -> None:
    # First order in q = 2π d √(η − sin²θ)/λ: R = 2jq R'/(1 − R'²), |T − 1| = O(q/(1 − R'²)).
    c = np.linspace(0.1, 1.0, 10)
    d = 1e-9
    s = slab_coefficients(ETA_CONCRETE_35, c, d, LAMBDA35)
    h = fresnel_half_space(ETA_CONCRETE_35, c)
    q = 2 * np.pi * d / LAMBDA35 * np.sqrt(ETA_CONCRETE_35 - (1 - c**2))
    for r, rp, t in ((s.r_te, h.r_te, s.t_te), (s.r_tm, h.r_tm, s.t_tm)):
        first = 2j * q * rp / (1 - rp**2)
        assert np.all(np.abs(r - first) <= 1e-5 * np.abs(first))
        assert np.all(np.abs(t - 1) <= 10 * np.abs(q / (1 - rp**2)))
    z = slab_coefficients(ETA_CONCRETE_35, np.linspace(0.0, 1.0, 11), 0.0, LAMBDA35)
    assert np.all(z.r_te[1:] == 0) and np.allclose(z.t_tm[1:], 1, rtol=0, atol=1e-15)


def test_thick_lossy_slab_is_half_space() -> None:
    c = np.linspace(0.05, 1.0, 9)
    s = slab_coefficients(ETA_CONCRETE_35, c, 5.0, LAMBDA35)  # −Im q ≈ 10
    h = fresnel_half_space(ETA_CONCRETE_35, c)
    assert np.allclose(s.r_te, h.r_te, atol=1e-7) and np.allclose(s.r_tm, h.r_tm, atol=1e-7)
    assert np.all(np.abs(s.t_te) < 1e-7)


def test_vacuum_slab_does_nothing() -> None:
    c = np.linspace(0.01, 1.0, 9)
    s = slab_coefficients(1.0, c, 0.3, 0.1)
    assert np.allclose(s.r_te, 0, atol=1e-15) and np.allclose(s.r_tm, 0, atol=1e-15)
    # T = e^{−jq} with q = 2π d cosθ/λ: the phase of the path through the slab.
    assert np.allclose(s.t_te, np.exp(-2j * np.pi * 0.3 * c / 0.1), atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(
    eps=st.floats(1.0, 100.0),
    cos_theta=st.floats(0.0, 1.0),
    d=st.floats(0.0, 2.0),
    lam=st.floats(1e-3, 10.0),
)
def test_energy_conservation_lossless(eps: float, cos_theta: float, d: float, lam: float) -> None:
    s = slab_coefficients(eps, cos_theta, d, lam)
    for r, t in ((s.r_te, s.t_te), (s.r_tm, s.t_tm)):
        assert abs(abs(r) ** 2 + abs(t) ** 2 - 1) < 1e-12


@settings(max_examples=200, deadline=None)
@given(
    eps=st.floats(1.0, 1e3),
    loss=st.floats(0.0, 1e12),
    cos_theta=st.floats(0.0, 1.0),
    d=st.floats(0.0, 10.0),
    lam=st.floats(1e-4, 100.0),
)
def test_lossy_is_passive_and_finite(eps: float, loss: float, cos_theta: float, d: float, lam: float) -> None:
    eta = complex(eps, -loss)
    s = slab_coefficients(eta, cos_theta, d, lam)
    h = fresnel_half_space(eta, cos_theta)
    for v in (*s, *h):
        assert np.isfinite(v)
    for r, t in ((s.r_te, s.t_te), (s.r_tm, s.t_tm)):
        assert abs(r) ** 2 + abs(t) ** 2 <= 1 + 1e-9


def test_input_checks() -> None:
    with pytest.raises(WavepathsError, match="cos_theta"):
        fresnel_half_space(2.0, 1.5)
    with pytest.raises(WavepathsError, match="model"):
        reflection_coefficients(PEC, F35, 0.5, "thin")  # type: ignore[arg-type]
    with pytest.raises(WavepathsError, match="Im"):
        slab_coefficients(2 + 1j, 0.5, 0.1, 0.1)
    with pytest.raises(WavepathsError, match="thickness"):
        slab_coefficients(2.0, 0.5, -0.1, 0.1)
    with pytest.raises(WavepathsError, match="outside"):
        reflection_coefficients(Material("x", "itu", 2.0, 0, 0, 0, 1e9, 2e9), 3e9, 0.5)


def _compiled_fresnel(eta, c, thickness_over_lambda, slab):
    from wavepaths.fields import compiled

    if not compiled.available():
        pytest.skip("numba is not installed (the `fast` extra)")
    from wavepaths.fields import _numba

    return _numba.fresnel(_numba.KIND_DIELECTRIC, complex(eta), float(thickness_over_lambda), slab, float(c))


@pytest.mark.parametrize("c", [0.0, 0.1, 0.5])
def test_a_lossless_medium_below_sin2_takes_the_decaying_root(c):
    """eta = 0.5 (lossless, below sin^2 theta for cos theta <= 0.5: total reflection): the
    coefficients are the limit of a vanishing loss, and a thick slab tends to the half-space
    with no transmission. The principal root of the negative real (eta - 1) + c^2 with a +0
    imaginary part is +j sqrt(.): the conjugate coefficient, and a slab's e^{-jq} grew as
    e^{220} at 50 wavelengths (found by a review)."""
    lossless = fresnel_half_space(0.5 + 0j, c)
    lossy = fresnel_half_space(0.5 - 1e-13j, c)
    assert abs(lossless.r_te - lossy.r_te) < 1e-11 and abs(lossless.r_tm - lossy.r_tm) < 1e-11
    assert abs(lossless.r_te) == pytest.approx(1.0, abs=1e-12)
    thick = slab_coefficients(0.5 + 0j, c, 50.0, 1.0)
    assert abs(thick.r_te - lossless.r_te) < 1e-12 and abs(thick.t_te) < 1e-12
    for slab, d in ((False, 0.0), (True, 50.0)):
        r_te, r_tm = _compiled_fresnel(0.5 + 0j, c, d, slab)
        assert abs(r_te - lossless.r_te) < 1e-12 and abs(r_tm - lossless.r_tm) < 1e-12


@pytest.mark.parametrize("c", [0.0, 1e-12, 0.5, 1.0])
def test_a_slab_of_thickness_zero_reflects_nothing_at_every_angle(c):
    """d = 0 is no slab: R = 0, T = 1, at exact grazing too (it gave R = -1, T = 0 there:
    the limits d -> 0 and cos theta -> 0 disagree; found by a review)."""
    s = slab_coefficients(5.0 - 0.5j, c, 0.0, 0.1)
    assert s.r_te == 0 and s.r_tm == 0 and s.t_te == 1 and s.t_tm == 1
    r = reflection_coefficients(Material("thin", "custom", a=5.0, c=0.05, thickness_m=0.0), 3e9, c, "slab")
    assert r.r_te == 0 and r.r_tm == 0
    assert _compiled_fresnel(5.0 - 0.5j, c, 0.0, True) == (0j, 0j)


@pytest.mark.parametrize("log_eta", [99.0, 101.0, 155.0, 165.0, 307.0])
def test_a_huge_permittivity_gives_a_perfect_conductor_not_nan(log_eta):
    """|eta| past ~1e154 overflowed the squares of the rationalised eq. (37) (r_tm was NaN).
    To first order r_te = -1 + 2c/sqrt(eta) and r_tm = 1 - 2/(c sqrt(eta)): within 2e-16 of
    (-1, +1) at |eta| >= 1e98 for cos(theta) >= 1e-33, on both sides of the 1e100 switch, for
    a lossy and a lossless eta, half-space and slab (whose transmission then vanishes or is
    below rounding)."""
    c = np.array([1.0, 0.5, 1e-3, 1e-20])
    for eta in (10.0**log_eta * (1 - 1j) / np.sqrt(2), 10.0**log_eta + 0j):
        tol = 2.0 / (c * np.sqrt(abs(eta))) + 1e-15
        for co in (fresnel_half_space(eta, c), slab_coefficients(eta, c, 0.2, LAMBDA35)):
            assert np.all(np.isfinite(co.r_te)) and np.all(np.isfinite(co.r_tm))
            assert np.all(np.abs(co.r_te + 1) <= tol) and np.all(np.abs(co.r_tm - 1) <= tol)
