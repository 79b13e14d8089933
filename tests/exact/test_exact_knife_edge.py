"""ITU-R P.526 single knife edge, and the PEC half-plane (KP-UTD) against it."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import erfc

from wavepaths.em.utd import boundary_offsets, kp_coefficients
from wavepaths.exact import fresnel_nu, knife_edge_field, knife_edge_loss_db
from wavepaths.errors import WavepathsError

pytestmark = pytest.mark.exact

# diffraction-physics.md §4, 4 decimals.
J_TABLE = [(-1.0, -1.0010), (-0.78, -0.0111), (-0.5, 1.8586), (0.0, 6.0206), (0.5, 10.2338),
           (1.0, 13.8641), (2.0, 19.0910), (3.0, 22.5218)]


@pytest.mark.parametrize(("nu", "j_db"), J_TABLE)
def test_j_table(nu: float, j_db: float) -> None:
    assert abs(knife_edge_loss_db(nu) - j_db) < 1e-3


def test_nu_zero_is_6_02_db() -> None:
    assert abs(knife_edge_loss_db(0.0) - 20 * np.log10(2)) < 1e-12
    assert abs(knife_edge_field(0.0) - 0.5) < 1e-15


def test_complex_field_is_half_erfc() -> None:
    # Independent form: (1+j)/2 int_nu^inf e^{-j pi t^2/2} dt = 1/2 erfc(e^{j pi/4} sqrt(pi/2) nu).
    nu = np.linspace(-5, 10, 301)
    ref = 0.5 * erfc(np.exp(0.25j * np.pi) * np.sqrt(np.pi / 2) * nu)
    e = knife_edge_field(nu)
    assert np.max(np.abs(e - ref)) < 1e-12
    assert np.allclose(-20 * np.log10(np.abs(e)), knife_edge_loss_db(nu), atol=1e-10)
    assert abs(knife_edge_field(-1e4) - 1) < 1e-4  # no obstruction: free space


def test_p526_approximation_and_asymptote() -> None:
    nu = np.linspace(-0.78, 3.0, 400)
    approx = 6.9 + 20 * np.log10(np.sqrt((nu - 0.1) ** 2 + 1) + nu - 0.1)
    diff = approx - knife_edge_loss_db(nu)
    assert -0.11 < diff.min() and diff.max() < 0.11  # the doc: -0.106 ... +0.103 dB
    assert abs(knife_edge_loss_db(10.0) - (13 + 20)) < 0.1  # J ~ 13 + 20 log10(nu)


def test_nu_forms_agree_for_small_angles() -> None:
    lam, d1, d2 = 0.1, 800.0, 1300.0
    for h in (-3.0, 0.5, 4.0):
        nu = fresnel_nu(h, d1, d2, lam)
        theta = np.arctan(h / d1) + np.arctan(h / d2)  # diffraction angle
        assert nu == pytest.approx(theta * np.sqrt(2 / (lam * (1 / d1 + 1 / d2))), rel=1e-4)
        assert nu == pytest.approx(np.sign(h) * np.sqrt(2 * h * theta / lam), rel=1e-4)
    with pytest.raises(WavepathsError):
        fresnel_nu(1.0, 0.0, 1.0, 1.0)


def _pec_screen_loss_db(h: float, d1: float, d2: float, k: float, polarization: str) -> float:
    """KP-UTD loss of a PEC half-plane screen below the edge; point source, Tx (-d1, -h), Rx (d2, -h)."""
    tx, rx = np.array([-d1, -h]), np.array([d2, -h])
    sp, s = np.hypot(*tx), np.hypot(*rx)
    to_phi = lambda p: np.mod(np.arctan2(p[1], p[0]) + np.pi / 2, 2 * np.pi)  # noqa: E731 (0-face along -y)
    pp, ph = to_phi(tx), to_phi(rx)
    d = kp_coefficients(ph, pp, np.pi / 2, 2.0, k, s * sp / (s + sp))
    dd = d.d_s if polarization == "soft" else d.d_h
    u_d = np.exp(-1j * k * sp) / sp * dd * np.sqrt(sp / (s * (s + sp))) * np.exp(-1j * k * s)
    e = boundary_offsets(ph, pp, 2.0).eps_1  # shadow boundary phi = phi' - pi
    w = 1.0 if e > 0 else (0.0 if e < 0 else 0.5)
    dist = np.hypot(*(rx - tx))
    u = u_d + w * np.exp(-1j * k * dist) / dist
    return float(-20 * np.log10(abs(u) * dist))


def test_pec_half_plane_brackets_knife_edge() -> None:
    # diffraction-physics.md §4: d1 = d2 = 1000 lambda; soft and hard bracket J, mean within 0.05 dB,
    # |L - J| <= 0.5 dB for nu <= 2.5, and the doc's values to 0.002 dB.
    lam, d1 = 1.0, 1000.0
    k = 2 * np.pi / lam
    doc = {-10: (0.904, 0.911), -5: (3.335, 3.299), 0: (6.064, 5.977), 5: (8.806, 8.659),
           10: (11.372, 11.160), 20: (15.677, 15.313), 40: (21.424, 20.727)}
    for h, (doc_s, doc_h) in doc.items():
        nu = float(fresnel_nu(h, d1, d1, lam))
        j = float(knife_edge_loss_db(nu))
        ls, lh = (_pec_screen_loss_db(h, d1, d1, k, p) for p in ("soft", "hard"))
        assert abs(ls - doc_s) < 2e-3 and abs(lh - doc_h) < 2e-3
        assert min(ls, lh) - 1e-3 <= j <= max(ls, lh) + 1e-3
        assert abs(0.5 * (ls + lh) - j) < 0.05
        if nu <= 2.5:
            assert abs(ls - j) <= 0.5 and abs(lh - j) <= 0.5


@settings(max_examples=200, deadline=None)
@given(nu=st.floats(-1e6, 1e6))
def test_knife_edge_finite(nu: float) -> None:
    e = knife_edge_field(nu)
    j = knife_edge_loss_db(nu)
    assert np.isfinite(e) and np.isfinite(j) and abs(e) < 1.2  # max |E/E0| = 1.17 at nu ~ -1.2
