"""The field chain end to end, against things no one here wrote: Friis, image theory,
the exact Sommerfeld half-plane solution, reciprocity, continuity across boundaries."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.constants import speed_of_light

from wavepaths import TraceOptions, trace
from wavepaths.em.antennas import Antenna
from wavepaths.exact.halfplane import halfplane_plane_wave
from wavepaths.fields import FieldConfig, compute_fields, transfer_matrices
from wavepaths.scene import load_scene

from ..conftest import quads_scene


@pytest.mark.parametrize("f", [0.9e9, 3.5e9, 28e9])
@pytest.mark.parametrize("d", [1.0, 37.0, 1500.0])
def test_free_space_path_gain_is_friis(f, d):
    s = quads_scene([[[-1, -1, -100], [1, -1, -100], [1, 1, -100], [-1, 1, -100]]])  # far away
    p = trace(s, [[0, 0, 0]], [[d, 0, 0]], TraceOptions(max_reflections=0, diffraction=False))
    r = compute_fields(s, p, FieldConfig(frequency_hz=f))
    lam = speed_of_light / f
    assert len(p) == 1
    assert abs(r.a[0]) == pytest.approx(lam / (4 * np.pi * d), rel=1e-12)
    assert r.path_gain_db()[0, 0] == pytest.approx(-20 * np.log10(4 * np.pi * d / lam), abs=1e-9)


def test_field_strength_from_power():
    s = quads_scene([[[-1, -1, -100], [1, -1, -100], [1, 1, -100], [-1, 1, -100]]])
    p = trace(s, [[0, 0, 0]], [[100.0, 0, 0]], TraceOptions(max_reflections=0, diffraction=False))
    r = compute_fields(s, p, FieldConfig(frequency_hz=1e9, tx_power_dbm=30.0))
    # isotropic 1 W at 100 m: E = sqrt(eta_0 P / 4 pi) / d (the textbook sqrt(30 P) / d, 30 ~ eta_0 / 4 pi)
    from wavepaths.fields.result import ETA_0
    assert r.field_strength()[0, 0] == pytest.approx(np.sqrt(ETA_0 / (4 * np.pi)) / 100.0, rel=1e-9)


def test_pec_ground_cancels_tangential_field_at_the_surface():
    s = quads_scene([[[-100, -100, 0], [100, -100, 0], [100, 100, 0], [-100, 100, 0]]])
    tx = np.array([[0.0, 0.0, 10.0]])
    rx = np.array([[40.0, 3.0, 1e-3]])  # k h = 0.02: the tangential field nearly cancels
    p = trace(s, tx, rx, TraceOptions(max_reflections=1, diffraction=False))
    assert sorted(p.depth.tolist()) == [0, 1]
    T = transfer_matrices(s, p, FieldConfig(frequency_hz=1e9))
    from wavepaths.em.polarization import spherical_unit_vectors
    k = 2 * np.pi * 1e9 / speed_of_light
    direct = int(np.flatnonzero(p.depth == 0)[0])
    vertical = []
    for pol in (0, 1):
        total = np.zeros(3, complex)
        for i in range(len(p)):
            b = spherical_unit_vectors(p.arrival_directions[i])
            e = T[i, 0, pol] * b.theta_hat + T[i, 1, pol] * b.phi_hat
            e = e * np.exp(-1j * k * p.lengths[i])
            total += e
            if i == direct:
                e_direct = e
        # E_x, E_y vanish on a perfect conductor (to O(k h)); E_z doubles (the image's E_z equals
        # the direct one's, to O(k h) in phase and h / r in amplitude)
        assert np.hypot(abs(total[0]), abs(total[1])) < 0.05 * np.abs(T[0, :, pol]).max()
        assert abs(total[2] - 2 * e_direct[2]) < 0.05 * np.linalg.norm(e_direct)
        vertical.append(abs(e_direct[2]) / np.linalg.norm(e_direct))
    assert max(vertical) > 0.2  # one polarisation has a vertical part worth doubling


def halfplane_total(s, tx, rx_pts, pol, freq, edge_dihedron):
    """Normalised total field u of a point source far away, soft or hard, from wavepaths."""
    p = trace(s, tx, rx_pts, TraceOptions(max_reflections=1, diffraction=True, diffraction_reflections=0))
    keep = (p.depth == 0) | (p.interactions[:, 0] == 1) | (p.primitive[:, 0] == edge_dihedron)
    p = p.select(keep)
    cfg = FieldConfig(frequency_hz=freq)
    T = transfer_matrices(s, p, cfg)
    from wavepaths.em.polarization import spherical_unit_vectors
    x = np.array([1.0, 0, 0])
    k = cfg.wavenumber
    dep = spherical_unit_vectors(p.departure_directions)
    arr = spherical_unit_vectors(p.arrival_directions)
    out = np.zeros(len(rx_pts), complex)
    for i in range(len(p)):
        d = p.departure_directions[i]
        e0 = x if pol == "soft" else np.cross(x, d)  # hard: H along the edge
        c = np.array([e0 @ dep.theta_hat[i], e0 @ dep.phi_hat[i]])
        ev = T[i] @ c
        E = ev[0] * arr.theta_hat[i] + ev[1] * arr.phi_hat[i]
        u = E[0] if pol == "soft" else np.cross(p.arrival_directions[i], E)[0]
        out[p.rx_index[i]] += u * np.exp(-1j * k * p.lengths[i])
    s_prime = np.linalg.norm(tx[0])
    return out / (cfg.wavelength / (4 * np.pi * s_prime) * np.exp(-1j * k * s_prime))


@pytest.mark.parametrize("pol", ["soft", "hard"])
@pytest.mark.parametrize("k_rho", [10.0, 50.0])
def test_half_plane_total_field_matches_sommerfeld(pol, k_rho):
    s = load_scene("half_plane")  # screen y = 0, z < 0; its face points along -z from the edge
    edge = int(np.argmin(np.abs(s.dihedra.origin[:, 2]) + np.abs(s.dihedra.direction[:, 1]) + np.abs(s.dihedra.direction[:, 2])
                         + 10 * (s.dihedra.face_count != 1)))
    freq = 3e9
    k = 2 * np.pi * freq / speed_of_light
    rho = k_rho / k
    phi_p = np.deg2rad(60.0)
    u = lambda phi: np.stack([np.zeros_like(phi), np.sin(phi), -np.cos(phi)], axis=-1)
    s_prime = 2e4
    tx = s_prime * u(np.array([phi_p]))
    phis = np.deg2rad(np.array([10, 30, 59, 90, 119.5, 120.5, 150, 180, 200, 239.5, 240.5, 270, 300, 330, 350]))
    got = halfplane_total(s, tx, rho * u(phis), pol, freq, edge)
    ref = halfplane_plane_wave(k_rho, phis, phi_p, pol)
    # point source at 2e4 m instead of a plane wave: O(rho / s') = O(1e-4) differences
    np.testing.assert_allclose(got, ref, atol=3e-3)


def street_canyon_with(material):
    from wavepaths.scene import build_scene
    from wavepaths.scene.builtin import builtin_arrays
    v, t, o, _, names, _ = builtin_arrays("street_canyon")
    return build_scene(v, t, o, np.zeros(len(t), int), names, [material])


@pytest.mark.parametrize("pol", ["V", "H"])
def test_reciprocity_of_the_complex_coefficient_pec(pol):
    from wavepaths.em.materials import PEC
    s = street_canyon_with(PEC)
    a, b = np.array([[-30.0, 3.0, 6.0]]), np.array([[35.0, -4.0, 1.5]])
    opts = TraceOptions(max_reflections=2, diffraction_reflections=1)
    c = FieldConfig(frequency_hz=2e9, tx_antenna=Antenna("iso", pol), rx_antenna=Antenna("iso", pol))
    f, r = trace(s, a, b, opts), trace(s, b, a, opts)
    fa, ra = compute_fields(s, f, c).a, compute_fields(s, r, c).a
    key = lambda p, i, rev: (tuple(p.interactions[i, : p.depth[i]][:: -1 if rev else 1]),
                             tuple(p.primitive[i, : p.depth[i]][:: -1 if rev else 1]))
    back = {key(r, j, True): j for j in range(len(r))}
    assert len(back) == len(f) > 20
    for i in range(len(f)):
        j = back[key(f, i, False)]
        assert fa[i] == pytest.approx(ra[j], rel=1e-9, abs=1e-18)  # path by path, phase included


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("model", ["slab", "half_space"])
def test_lossy_wedges_are_reciprocal_path_by_path(compiled, model):
    """Swapping transmitter and receiver on the street canyon's concrete (reflections to order
    2, diffraction with a reflection before or after it): each path's 2x2 coefficient
    (ports V and H at both ends) is the transpose of its reverse's. Luebbers' coefficient
    takes R0 at the source's angle and Rn at the observer's; with the faces labelled by the
    edge alone, a diffracted path's coefficient changed 24 times on a swap (found by a
    review). The chain labels them so that phi' <= phi (fields.chain._reciprocal_face_order)."""
    s = load_scene("street_canyon")
    opts = TraceOptions(max_reflections=2, diffraction_reflections=1)
    cfg = FieldConfig(frequency_hz=3.5e9, tx_antenna=Antenna("iso", "VH"), rx_antenna=Antenna("iso", "VH"),
                      compiled=compiled, reflection_model=model)
    key = lambda p, i, rev: (tuple(p.interactions[i, : p.depth[i]][:: -1 if rev else 1]),
                             tuple(p.primitive[i, : p.depth[i]][:: -1 if rev else 1]))
    diffracted = 0
    for a, b in (([[-30.0, 3.0, 6.0]], [[35.0, -4.0, 1.5]]), ([[-52.0, -6.0, 14.0]], [[20.0, 7.0, 2.0]])):
        f, r = trace(s, a, b, opts), trace(s, b, a, opts)
        fa, ra = compute_fields(s, f, cfg).a, compute_fields(s, r, cfg).a
        back = {key(r, j, True): j for j in range(len(r))}
        assert len(back) == len(f)
        for i in range(len(f)):
            j = back[key(f, i, False)]
            assert np.max(np.abs(fa[i] - ra[j].T)) <= 1e-12 * np.max(np.abs(fa[i])), key(f, i, False)
        diffracted += int((f.interactions == 2).any(axis=1).sum())
    assert diffracted > 40


def test_total_field_is_continuous_across_wedge_boundaries():
    s = load_scene("wedge")  # faces: z = 0 (y < 0) and y = 0 (z < 0), edge on x
    d = s.dihedra
    edge = int(np.nonzero(d.face_count == 2)[0][0])
    tx = np.array([[0.0, 30.0, -10.0]])
    cfg = FieldConfig(frequency_hz=3e9)
    # receivers on a circle around the edge, crossing the shadow boundary of the tx
    sb = np.arctan2(10.0, -30.0)  # direction of the incident ray continuing past the edge
    for eps in (1e-6, 1e-9):
        ang = np.array([sb - eps, sb + eps])
        rx = np.stack([np.zeros(2), 3 * np.cos(ang), 3 * np.sin(ang)], axis=1)
        p = trace(s, tx, rx, TraceOptions(max_reflections=1, diffraction_reflections=0))
        p = p.select((p.depth == 0) | (p.interactions[:, 0] == 1) | (p.primitive[:, 0] == edge))
        for pol in ("V", "H"):
            c = FieldConfig(frequency_hz=3e9, tx_antenna=Antenna("iso", pol), rx_antenna=Antenna("iso", pol))
            g = compute_fields(s, p, c).path_gain_db()[0]
            assert abs(g[0] - g[1]) < 0.01, (eps, pol, g)
            # without the diffracted field, geometrical optics jumps by about 6 dB here
            go = compute_fields(s, p.select(p.depth == 0) if False else p.select(p.interactions[:, 0] != 2)
                                if p.max_depth else p, c).path_gain_db()[0]
            assert abs(go[0] - go[1]) > 3
    del cfg


def test_coherence_matrix_form_equals_jones_and_handles_unpolarised_sources():
    from wavepaths.em.polarization import coherence_from_jones, unpolarized_coherence
    from wavepaths.fields.coherence import received_power_gain

    s = load_scene("street_canyon")
    p = trace(s, [[-30.0, 3.0, 6.0]], [[35.0, -4.0, 1.5]], TraceOptions(max_reflections=2, diffraction_reflections=1))
    assert (p.interactions == 2).any() and (p.interactions == 1).any()
    gains = {}
    for tx_pol in ("V", "H"):
        for rx_pol in ("V", "H"):
            c = FieldConfig(2e9, tx_antenna=Antenna("iso", tx_pol), rx_antenna=Antenna("iso", rx_pol))
            gains[tx_pol, rx_pol] = np.abs(compute_fields(s, p, c).a) ** 2
    cfg = FieldConfig(2e9)
    for tx_pol, e in (("V", np.array([1.0, 0.0])), ("H", np.array([0.0, 1.0]))):
        for rx_pol in ("V", "H"):
            g = received_power_gain(s, p, cfg, coherence_from_jones(e), Antenna("iso", rx_pol))
            np.testing.assert_allclose(g, gains[tx_pol, rx_pol], rtol=1e-10, atol=1e-30)
    # an unpolarised source delivers the mean of the two orthogonal polarisations
    for rx_pol in ("V", "H"):
        g = received_power_gain(s, p, cfg, unpolarized_coherence(), Antenna("iso", rx_pol))
        np.testing.assert_allclose(g, 0.5 * (gains["V", rx_pol] + gains["H", rx_pol]), rtol=1e-10, atol=1e-30)


def test_wide_screen_reproduces_itu_p526_knife_edge_loss():
    from wavepaths.exact.knife_edge import fresnel_nu, knife_edge_loss_db

    s = load_scene("half_plane")  # 100 m x 50 m metal screen in y = 0, top edge on the x axis
    f = 3.5e9
    lam = speed_of_light / f
    d = 1000 * lam
    nus = np.linspace(-1, 3, 9)
    h = nus * np.sqrt(lam * d) / 2  # edge height above the tx-rx line, d1 = d2 = d
    tx = np.stack([np.zeros_like(h), np.full_like(h, -d), -h], axis=1)
    rx = np.stack([np.zeros_like(h), np.full_like(h, d), -h], axis=1)
    np.testing.assert_allclose(fresnel_nu(h, d, d, lam), nus, atol=1e-12)
    dih = s.dihedra
    top_edge = int(np.nonzero((np.abs(dih.direction[:, 0]) > 0.99) & (np.abs(dih.origin[:, 2]) < 1e-9))[0][0])
    loss = {}
    for pol in ("H", "V"):  # E along the edge (soft), E across it (hard)
        c = FieldConfig(f, tx_antenna=Antenna("iso", pol), rx_antenna=Antenna("iso", pol))
        out = []
        for i in range(len(nus)):
            p = trace(s, tx[i : i + 1], rx[i : i + 1], TraceOptions(max_reflections=0, diffraction_reflections=0))
            top = (p.depth == 0) | (p.primitive[:, 0] == top_edge)  # line of sight and the top edge only
            g = compute_fields(s, p.select(top), c).path_gain_db()[0, 0]
            out.append(-(g + 20 * np.log10(4 * np.pi * 2 * d / lam)))  # loss relative to free space
        loss[pol] = np.array(out)
    j = knife_edge_loss_db(nus)
    # a perfectly conducting screen brackets the absorbing-screen J(nu); soft and hard within 0.5 dB of it
    # and their mean within 0.1 dB (ITU-R P.526 §4.1; reference values in diffraction-physics.md §4)
    np.testing.assert_allclose(loss["H"], j, atol=0.5)
    np.testing.assert_allclose(loss["V"], j, atol=0.5)
    np.testing.assert_allclose(0.5 * (loss["H"] + loss["V"]), j, atol=0.1)
    zero = int(np.argmin(np.abs(nus)))
    assert 0.5 * (loss["H"][zero] + loss["V"][zero]) == pytest.approx(6.02, abs=0.05)  # nu = 0: the edge halves the field


def test_paths_shorter_than_a_wavelength_warn():
    # ray optics is a far-field method: 1 mm at 3.5 GHz gives a gain above 0 dB (Friis), which
    # the warning names; 1 m (11.7 wavelengths) does not warn (warnings are errors here)
    from wavepaths.scene import WavepathsWarning

    s = load_scene("street_canyon")
    los = TraceOptions(max_reflections=0, diffraction=False)
    near = trace(s, np.array([[-60.0, 0.0, 10.0]]), np.array([[-60.0, 0.0, 10.001]]), los)
    with pytest.warns(WavepathsWarning, match=r"1 of 1 paths are shorter than a wavelength \(0.0857 m"):
        r = compute_fields(s, near, FieldConfig(3.5e9))
    assert 20 * np.log10(abs(r.a[0])) > 0
    far = trace(s, np.array([[-60.0, 0.0, 10.0]]), np.array([[-60.0, 0.0, 11.0]]), los)
    r = compute_fields(s, far, FieldConfig(3.5e9))
    assert abs(r.a[0]) == pytest.approx(speed_of_light / 3.5e9 / (4 * np.pi * 1.0), rel=1e-12)  # Friis
