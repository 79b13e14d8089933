"""Invariants of the antenna patterns, polarisation slants and orientation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import sici

from wavepaths.em.antennas import (
    Antenna,
    antenna_field,
    antenna_field_vectors,
    antenna_gain,
    antenna_gain_dbi,
    polarization_slant_angles,
    rotation_matrix,
)
from wavepaths.em.polarization import field_vector, spherical_unit_vectors
from wavepaths.errors import WavepathsError

PATTERNS = ["iso", "dipole", "hw_dipole", "tr38901"]
POLARIZATIONS = ["V", "H", "VH", "cross"]
MODELS = ["tr38901_1", "tr38901_2"]
POLES = [(0.0, 0.0, 1.0), (0.0, 0.0, -1.0), (1e-300, 0.0, 1.0), (0.0, -1e-17, -1.0), (3e-10, 2e-10, -1.0)]


def random_directions(rng: np.random.Generator, n: int) -> np.ndarray:
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def sphere_grid(n_theta: int = 200, n_phi: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """Directions and weights of Gauss-Legendre (cos theta) x uniform (phi) quadrature."""
    x, w = np.polynomial.legendre.leggauss(n_theta)
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi - np.pi
    ct, ph = np.meshgrid(x, phi, indexing="ij")
    st_ = np.sqrt(1 - ct**2)
    d = np.stack([st_ * np.cos(ph), st_ * np.sin(ph), ct], -1)
    return d, np.broadcast_to(w[:, None] * 2 * np.pi / n_phi, ct.shape)


# Mean gain over the sphere, (1/4pi) * integral of G dOmega, as Sionna normalises:
# iso and short dipole are directivity-normalised (1); the half-wave dipole uses the
# rounded directivity 1.643 against the exact 4 / Cin(2 pi) = 1.64085; the 3GPP element
# is normalised to 8 dBi maximum GAIN, not directivity, so its mean is 0.6568
# (Sionna's compute_gain prints efficiency 65.678 %, directivity 9.83 dB).
def _hw_dipole_mean() -> float:
    si, ci = sici(2 * np.pi)
    cin = np.euler_gamma + np.log(2 * np.pi) - ci
    return 1.643 / (4.0 / cin)


EXPECTED_MEAN_GAIN = {"iso": 1.0, "dipole": 1.0, "hw_dipole": _hw_dipole_mean(), "tr38901": 0.656798}


@pytest.mark.parametrize("pattern", PATTERNS)
@pytest.mark.parametrize("polarization", ["VH", "cross"])
def test_gain_integrates_to_sionna_normalisation(pattern: str, polarization: str) -> None:
    d, w = sphere_grid()
    for orientation in [(0.0, 0.0, 0.0), (0.4, -1.1, 2.3)]:
        g = antenna_gain(Antenna(pattern, polarization, orientation), d)
        mean = np.einsum("ij,ijp->p", w, g) / (4 * np.pi)
        np.testing.assert_allclose(mean, EXPECTED_MEAN_GAIN[pattern], rtol=1e-5 if pattern == "tr38901" else 1e-9)
    if pattern != "tr38901":  # the directivity normalisation asked for, within 1e-3 + the
        # 1.643 rounding for hw_dipole (its mean is 1.00127, i.e. 1.3e-3 high)
        assert abs(EXPECTED_MEAN_GAIN[pattern] - 1.0) < 1.5e-3


def test_tr38901_table_values() -> None:
    ant = Antenna("tr38901")

    def gain_at(theta_deg: float, phi_deg: float) -> float:
        t, p = np.radians(theta_deg), np.radians(phi_deg)
        return float(antenna_gain_dbi(ant, [np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])[0])

    assert gain_at(90, 0) == pytest.approx(8.0, abs=1e-12)  # boresight = local +x
    assert gain_at(90, 32.5) == pytest.approx(5.0, abs=1e-12)  # 65 deg HPBW
    assert gain_at(90 + 32.5, 0) == pytest.approx(5.0, abs=1e-12)
    assert gain_at(90, 180) == pytest.approx(8.0 - 30.0, abs=1e-12)  # front-back ratio
    assert gain_at(180, 0) == pytest.approx(8.0 - 12 * (90 / 65) ** 2, abs=1e-12)
    assert gain_at(0, 0) == pytest.approx(8.0 - 12 * (90 / 65) ** 2, abs=1e-12)


def test_tr38901_look_at_orientation_points_boresight() -> None:
    rng = np.random.default_rng(10)
    for d in random_directions(rng, 20):
        theta, phi = math.acos(d[2]), math.atan2(d[1], d[0])
        ant = Antenna("tr38901", orientation=(phi, theta - math.pi / 2, 0.0))  # Sionna look_at
        assert antenna_gain_dbi(ant, d)[0] == pytest.approx(8.0, abs=1e-9)
    down = Antenna("tr38901", orientation=(0.0, 0.3, 0.0))  # positive pitch tilts down
    assert antenna_gain_dbi(down, [math.cos(0.3), 0, -math.sin(0.3)])[0] == pytest.approx(8.0)


@pytest.mark.parametrize("pattern", ["dipole", "hw_dipole"])
@pytest.mark.parametrize("model", MODELS)
def test_dipole_zero_on_its_axis(pattern: str, model: str) -> None:
    axis = np.array([[0, 0, 1.0], [0, 0, -1.0]])
    near = np.array([[1e-12, 0, 1.0], [0, -1e-300, -1.0]])
    for pol in POLARIZATIONS:
        ant = Antenna(pattern, pol, polarization_model=model)
        assert np.all(antenna_field(ant, axis) == 0)
        assert np.all(np.abs(antenna_field(ant, near)) <= 1.3e-12)  # ~ sqrt(1.5) sin(theta)
    # Rolled by 90 degrees the axis is Rx(pi/2) z = -y.
    rolled = Antenna(pattern, "V", (0.0, 0.0, math.pi / 2), model)
    np.testing.assert_allclose(antenna_field(rolled, [[0, 1.0, 0], [0, -1.0, 0]]), 0, atol=1e-15)
    assert antenna_gain_dbi(Antenna(pattern), [0, 0, 1])[0] == -np.inf  # no warning either
    g = antenna_gain(Antenna(pattern), [1.0, 0, 0])[0]
    assert g == pytest.approx(1.5 if pattern == "dipole" else 1.643, rel=1e-14)


def test_v_and_h_orthogonal() -> None:
    rng = np.random.default_rng(11)
    d = random_directions(rng, 500)
    for pattern in PATTERNS:
        ori = tuple(rng.uniform(-3, 3, 3))
        c = antenna_field(Antenna(pattern, "VH", ori), d)
        np.testing.assert_allclose(np.sum(np.conj(c[:, 0]) * c[:, 1], -1), 0, atol=1e-14)
        np.testing.assert_allclose(np.sum(abs(c[:, 0]) ** 2, -1), np.sum(abs(c[:, 1]) ** 2, -1), rtol=1e-12)
    # Model 1: V and H are dipoles along z and -y; orthogonal in the horizontal plane
    # and in the x-z plane only (Sionna RT behaves the same way).
    phi = rng.uniform(-np.pi, np.pi, 100)
    horiz = np.stack([np.cos(phi), np.sin(phi), 0 * phi], -1)
    c1 = antenna_field(Antenna("iso", "VH", polarization_model="tr38901_1"), horiz)
    np.testing.assert_allclose(np.sum(np.conj(c1[:, 0]) * c1[:, 1], -1), 0, atol=1e-14)
    c1 = antenna_field(Antenna("iso", "VH", polarization_model="tr38901_1"), [0.0, 0.6, 0.8])
    assert abs(np.sum(np.conj(c1[0]) * c1[1])) > 0.1


@pytest.mark.parametrize("model", MODELS)
def test_vh_ports_are_v_and_h(model: str) -> None:
    rng = np.random.default_rng(12)
    d = random_directions(rng, 200)
    ori = (0.3, 0.2, -0.7)
    vh = antenna_field(Antenna("hw_dipole", "VH", ori, model), d)
    np.testing.assert_array_equal(vh[:, 0], antenna_field(Antenna("hw_dipole", "V", ori, model), d)[:, 0])
    np.testing.assert_array_equal(vh[:, 1], antenna_field(Antenna("hw_dipole", "H", ori, model), d)[:, 0])


def test_cross_is_plus_minus_45_degree_slants() -> None:
    assert polarization_slant_angles("cross") == (-math.pi / 4, math.pi / 4)
    rng = np.random.default_rng(13)
    d = random_directions(rng, 300)
    # Model 2: the slant rotates (C_theta, C_phi) = (cos z, sin z) C~ -> (V -+ H) / sqrt 2.
    vh = antenna_field(Antenna("tr38901", "VH", (1.0, 0.2, 0.4)), d)
    cross = antenna_field(Antenna("tr38901", "cross", (1.0, 0.2, 0.4)), d)
    np.testing.assert_allclose(cross[:, 0], (vh[:, 0] - vh[:, 1]) / math.sqrt(2), atol=1e-14)
    np.testing.assert_allclose(cross[:, 1], (vh[:, 0] + vh[:, 1]) / math.sqrt(2), atol=1e-14)
    # Model 1: TR 38.901 eq. 7.3-3 written with angles, unrotated antenna.
    c1 = antenna_field(Antenna("iso", "cross", polarization_model="tr38901_1"), d)
    t, p = np.arccos(d[:, 2]), np.arctan2(d[:, 1], d[:, 0])
    for port, z in enumerate((-math.pi / 4, math.pi / 4)):
        norm = np.sqrt(1 - (math.cos(z) * np.cos(t) - math.sin(z) * np.sin(p) * np.sin(t)) ** 2)
        cos_psi = (math.cos(z) * np.sin(t) + math.sin(z) * np.sin(p) * np.cos(t)) / norm
        sin_psi = math.sin(z) * np.cos(p) / norm
        np.testing.assert_allclose(c1[:, port], np.stack([cos_psi, sin_psi], -1), atol=1e-12)


def test_rotation_matrix_is_rz_ry_rx() -> None:
    a, b, c = 0.3, -0.8, 1.9
    rz = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    rx = np.array([[1, 0, 0], [0, math.cos(c), -math.sin(c)], [0, math.sin(c), math.cos(c)]])
    np.testing.assert_allclose(rotation_matrix((a, b, c)), rz @ ry @ rx, atol=1e-15)
    r = rotation_matrix(np.random.default_rng(0).uniform(-4, 4, (7, 3)))
    np.testing.assert_allclose(r @ np.swapaxes(r, -1, -2), np.broadcast_to(np.eye(3), r.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(r), 1.0)


def test_yaw_equals_evaluating_at_rotated_directions() -> None:
    rng = np.random.default_rng(14)
    d = random_directions(rng, 400)
    for pattern in PATTERNS:
        for yaw in (0.7, -2.5):
            rz = rotation_matrix((yaw, 0.0, 0.0))
            for pol in ("VH", "cross"):
                base = antenna_field(Antenna(pattern, pol), d)
                turned = antenna_field(Antenna(pattern, pol, (yaw, 0.0, 0.0)), d @ rz.T)
                np.testing.assert_allclose(turned, base, atol=1e-12)


@pytest.mark.parametrize("model", MODELS)
def test_any_orientation_rotates_the_field_vector(model: str) -> None:
    rng = np.random.default_rng(15)
    d = random_directions(rng, 300)
    for pattern in PATTERNS:
        ori = tuple(rng.uniform(-3, 3, 3))
        r = rotation_matrix(ori)
        f0 = field_vector(antenna_field(Antenna(pattern, "cross", polarization_model=model), d), d[:, None, :])
        rd = d @ r.T
        f1 = field_vector(antenna_field(Antenna(pattern, "cross", ori, model), rd), rd[:, None, :])
        np.testing.assert_allclose(f1, f0 @ r.T, atol=1e-12)


def test_global_components_match_tr38901_psi_form() -> None:
    """TR 38.901 §7.1.3: F = [[cos psi, -sin psi], [sin psi, cos psi]] F' with angles."""
    rng = np.random.default_rng(16)
    d = random_directions(rng, 300)
    ori = (0.5, -0.4, 1.2)
    r = rotation_matrix(ori)
    dl = d @ r
    t, p = np.arccos(dl[:, 2]), np.arctan2(dl[:, 1], dl[:, 0])
    th_l = np.stack([np.cos(t) * np.cos(p), np.cos(t) * np.sin(p), -np.sin(t)], -1)
    th_g, ph_g = spherical_unit_vectors(d)
    cos_psi, sin_psi = np.sum(th_g * (th_l @ r.T), -1), np.sum(ph_g * (th_l @ r.T), -1)
    local = np.sqrt(1.5) * np.sin(t)  # V dipole, model 2: (C~, 0)
    expected = np.stack([cos_psi * local, sin_psi * local], -1)
    np.testing.assert_allclose(antenna_field(Antenna("dipole", "V", ori), d)[:, 0], expected, atol=1e-12)


def test_num_ports_and_shapes() -> None:
    assert [Antenna(polarization=p).num_ports for p in POLARIZATIONS] == [1, 1, 2, 2]
    d = np.zeros((4, 5, 3))
    d[..., 0] = 1.0
    assert antenna_field(Antenna(polarization="cross"), d).shape == (4, 5, 2, 2)
    assert antenna_field(Antenna(), d).dtype == np.complex128
    assert antenna_gain_dbi(Antenna(polarization="VH"), [1.0, 0, 0]).shape == (2,)
    assert Antenna(orientation=(1, 2, 3)).orientation == (1.0, 2.0, 3.0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"pattern": "patch"}, r"\['iso', 'dipole', 'hw_dipole', 'tr38901'\]"),
        ({"polarization": "RHCP"}, r"\['V', 'H', 'VH', 'cross'\]"),
        ({"polarization_model": "x"}, r"\['tr38901_1', 'tr38901_2'\]"),
        ({"orientation": (0.0, 1.0)}, "three"),
        ({"orientation": (0.0, np.nan, 1.0)}, "finite"),
        ({"orientation": "abc"}, "three"),
    ],
)
def test_invalid_antenna_lists_the_choices(kwargs: dict, match: str) -> None:  # type: ignore[type-arg]
    with pytest.raises(WavepathsError, match=match):
        Antenna(**kwargs)


def test_bad_directions_raise() -> None:
    with pytest.raises(WavepathsError, match=r"\(\.\.\., 3\)"):
        antenna_field(Antenna(), [1.0, 0.0])
    with pytest.raises(WavepathsError, match="Antenna"):
        antenna_field("iso", [1.0, 0.0, 0.0])  # type: ignore[arg-type]


direction_strategy = st.one_of(
    st.sampled_from(POLES),
    st.tuples(*[st.floats(-1.0, 1.0)] * 3).filter(lambda v: any(c != 0.0 for c in v)),
)
angle = st.sampled_from([0.0, math.pi / 2, -math.pi / 2, math.pi]) | st.floats(-4.0, 4.0)


@settings(max_examples=150, deadline=None)
@given(
    st.lists(direction_strategy, min_size=1, max_size=8),
    st.sampled_from(PATTERNS),
    st.sampled_from(POLARIZATIONS),
    st.sampled_from(MODELS),
    st.tuples(angle, angle, angle),
)
def test_no_nan_anywhere_including_poles(directions, pattern, polarization, model, orientation) -> None:  # type: ignore[no-untyped-def]
    ant = Antenna(pattern, polarization, orientation, model)
    c = antenna_field(ant, np.asarray(directions))
    assert c.shape == (len(directions), ant.num_ports, 2)
    assert np.all(np.isfinite(c))
    g = antenna_gain(ant, np.asarray(directions))
    assert np.all(g <= 10 ** 0.8 + 1e-9)
    if model == "tr38901_2":  # model 1 loses gain only within pole_tolerance of its axis
        unpolarised_gain = antenna_gain(Antenna(pattern, "V", orientation), np.asarray(directions))
        np.testing.assert_allclose(g, np.broadcast_to(unpolarised_gain, g.shape), rtol=1e-12)


def _los_coupling(tx: Antenna, rx: Antenna, d_tx: np.ndarray) -> np.ndarray:
    """f_rx^H f_tx of a line-of-sight path as 3-D vectors (Sionna's jones_vec_dot)."""
    d_rx = -d_tx  # the receiver looks back toward the transmitter
    f_tx = field_vector(antenna_field(tx, d_tx), d_tx[..., None, :])
    f_rx = field_vector(antenna_field(rx, d_rx), d_rx[..., None, :])
    return np.einsum("...pk,...qk->...pq", np.conj(f_rx), f_tx)


def test_los_coupling_obeys_friis_and_polarisation() -> None:
    rng = np.random.default_rng(17)
    d = random_directions(rng, 100)
    for pattern in PATTERNS:
        tx = Antenna(pattern, "VH", tuple(rng.uniform(-1, 1, 3)))
        rx = Antenna(pattern, "VH", tuple(rng.uniform(-1, 1, 3)))
        c = _los_coupling(tx, rx, d)
        # |f_rx^H f_tx| <= sqrt(G_tx G_rx) (Cauchy-Schwarz), and the 2x2 port
        # coupling of a dual-polarised pair is sqrt(G_tx G_rx) times a 2x2 rotation,
        # reflection or less (Friis with polarisation mismatch).
        g_tx, g_rx = antenna_gain(tx, d), antenna_gain(rx, -d)
        assert np.all(np.abs(c) <= np.sqrt(g_rx[:, :, None] * g_tx[:, None, :]) + 1e-12)
        np.testing.assert_allclose(np.abs(np.linalg.det(c)), g_tx[:, 0] * g_rx[:, 0], rtol=1e-9)


def test_h_to_h_line_of_sight_has_opposite_sign_to_v_to_v() -> None:
    """Sionna's "H" is phi_hat-polarised (loop-like): phi_hat(-d) = -phi_hat(d)."""
    d = np.array([[1.0, 0, 0], [0.6, 0.8, 0]])
    vv = _los_coupling(Antenna("dipole", "V"), Antenna("dipole", "V"), d)[:, 0, 0]
    hh = _los_coupling(Antenna("dipole", "H"), Antenna("dipole", "H"), d)[:, 0, 0]
    np.testing.assert_allclose(vv, 1.5, rtol=1e-14)
    np.testing.assert_allclose(hh, -1.5, rtol=1e-14)


@pytest.mark.parametrize("pattern", ["iso", "dipole", "hw_dipole", "tr38901"])
@pytest.mark.parametrize("polarization", ["V", "H", "VH", "cross"])
@pytest.mark.parametrize("model", ["tr38901_1", "tr38901_2"])
def test_field_vectors_are_the_field_components_on_the_global_basis(pattern, polarization, model) -> None:
    """antenna_field_vectors = C_theta theta_hat + C_phi phi_hat of antenna_field, for
    oriented antennas, random directions and the poles of both frames; transverse."""
    from wavepaths.em.antennas import antenna_field_vectors
    from wavepaths.em.polarization import spherical_unit_vectors

    rng = np.random.default_rng(7)
    d = rng.normal(size=(500, 3))
    d = np.concatenate([d, [[0, 0, 1], [0, 0, -1], [1e-12, 0, 1], [1, 0, 0]]])
    for orientation in [(0.0, 0.0, 0.0), (0.3, -0.7, 1.1), (0.0, np.pi / 2, 0.0)]:
        ant = Antenna(pattern, polarization, orientation=orientation, polarization_model=model)
        c = antenna_field(ant, d)
        b = spherical_unit_vectors(d)
        ref = c[..., 0:1] * b.theta_hat[:, None, :] + c[..., 1:2] * b.phi_hat[:, None, :]
        got = antenna_field_vectors(ant, d)
        assert got.shape == ref.shape
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)
        u = d / np.linalg.norm(d, axis=1, keepdims=True)
        assert np.abs(np.einsum("npj,nj->np", got, u)).max() < 1e-12


def test_compiled_field_vectors_equal_the_numpy_reference():
    """The compiled kernel of ``antenna_field_vectors`` against its numpy reference, every
    pattern, polarisation, polarisation model and three orientations, on random directions,
    the poles, directions within 1e-10 of them, and vectors of extreme length: within
    rounding (1e-14 of the largest component: model 1 normalises by a norm that vanishes on
    the dipole axis), and the reference's errors on bad input."""
    pytest.importorskip("numba")
    from wavepaths.em.antennas import _antenna_field_vectors_numpy, _compiled_field_vectors

    assert _compiled_field_vectors() is not None
    rng = np.random.default_rng(5)
    d = np.concatenate([rng.normal(size=(2000, 3)), rng.normal(size=(50, 3)) * [1e-10, 1e-10, 1.0],
                        [[0, 0, 1], [0, 0, -1], [1e-12, 0, 1], [0, 1e-10, -1], [1e-300, 0, 0], [1e200, 1e200, 0],
                         [0, 0, 1e-320]]])
    for pattern in ("iso", "dipole", "hw_dipole", "tr38901"):
        for polarization in ("V", "H", "VH", "cross"):
            for model in ("tr38901_1", "tr38901_2"):
                for orientation in ((0.0, 0.0, 0.0), (0.3, -0.7, 1.1), (0.0, np.pi / 2, 0.0)):
                    ant = Antenna(pattern, polarization, orientation, model)
                    got = antenna_field_vectors(ant, d)
                    ref = _antenna_field_vectors_numpy(ant, d, 1e-9)
                    assert got.shape == ref.shape
                    assert np.abs(got - ref).max() <= 1e-14 * np.abs(ref).max(), (pattern, polarization, model)
    ant = Antenna("dipole", "cross")
    assert antenna_field_vectors(ant, np.ones((2, 4, 3))).shape == (2, 4, 2, 3)
    for bad, match in (([[0.0, 0.0, 0.0]], "non-zero"), ([[np.nan, 0.0, 1.0]], "finite"), (np.zeros((2, 2)), "shape")):
        with pytest.raises(WavepathsError, match=match):
            antenna_field_vectors(ant, bad)


def test_antenna_arguments_of_the_wrong_kind_get_a_clear_error_and_degrees_a_warning() -> None:
    """A review found a list as polarisation raising a bare TypeError, a string or booleans
    accepted as an orientation, and (90, 0, 0) taken silently as radians."""
    import warnings

    from wavepaths.errors import WavepathsError

    for bad in (dict(polarization=["V"]), dict(orientation="123"), dict(orientation=(True, 0, 0)),
                dict(orientation=(0.0, "1", 0.0))):
        with pytest.raises(WavepathsError):
            Antenna("iso", **bad)
    with pytest.warns(UserWarning, match="radians"):
        Antenna("tr38901", orientation=(90.0, 0.0, 0.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert Antenna("tr38901", orientation=(-np.pi, np.pi / 2, 2 * np.pi)).orientation == (-np.pi, np.pi / 2, 2 * np.pi)
