"""The total field across a dielectric wedge's reflection boundaries at oblique incidence on
the edge: Luebbers' face coefficients as the faces' reflections in KP's edge-fixed bases
(wavepaths.em.utd.wedge_reflection_matrices) keep it continuous; the scalar pairs
(r_te with D_s, r_tm with D_h) left a jump of 1.3 dB at beta_0 = 42 deg."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths import TraceOptions, trace
from wavepaths.em.antennas import Antenna
from wavepaths.em.fresnel import fresnel_half_space
from wavepaths.em.materials import PEC, Material
from wavepaths.em.utd import (
    diffraction_jones,
    diffraction_jones_matrices,
    edge_fixed_reflection,
    luebbers_coefficients,
    wedge_reflection_matrices,
)
from wavepaths.fields import FieldConfig, compute_fields
from wavepaths.scene.builtin import builtin_arrays
from wavepaths.scene.model import build_scene

LOSSY = Material("lossy", "custom", a=5.0, c=0.05, thickness_m=2.0)


def _wedge(material: Material):
    # the built-in wedge (n = 1.5): 0-face z = 0, y < 0; n-face y = 0, z < 0; edge along x
    v, t, o, m, names, mats = builtin_arrays("wedge")
    return build_scene(v, t, o, m, names, tuple(material for _ in mats))


def _unit(v):
    return np.asarray(v, float) / np.linalg.norm(v)


def _across_reflection_boundary(scene, tx: np.ndarray, mirror_axis: int, f: float, compiled: bool):
    """|E_total| / E_free at receivers 8 m from the edge, d across the boundary of the face
    that mirrors ``tx`` along ``mirror_axis``, and whether the reflected path is found."""
    img = tx.copy()
    img[mirror_axis] *= -1
    dirn = _unit(-img)  # the reflected ray through the edge point (0, 0, 0)
    perp = _unit(np.cross([1.0, 0.0, 0.0], dirn))
    d = np.array([-1e-6, -1e-7, 1e-7, 1e-6])
    rx = 8.0 * dirn + d[:, None] * perp
    paths = trace(scene, tx[None], rx, TraceOptions(max_reflections=1, diffraction=True, diffraction_reflections=0))
    fr = compute_fields(scene, paths, FieldConfig(f, reflection_model="half_space", compiled=compiled))
    free = (299792458.0 / f) / (4 * np.pi * (np.linalg.norm(tx) + 8.0))
    total = np.abs(fr._pair_sum(fr.a_phased)[0]) / free
    refl = np.array([((paths.rx_index == r) & (paths.depth == 1) & (paths.interactions[:, 0] == 1)).any()
                     for r in range(len(d))])
    return total, refl


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("material", [LOSSY, PEC], ids=["lossy", "pec"])
@pytest.mark.parametrize("tx,axis", [((4.0, 3.0, -2.0), 1), ((4.0, -3.0, 2.0), 2), ((1.0, 3.0, -2.0), 1)],
                         ids=["n-face, beta_0 42 deg", "0-face, beta_0 42 deg", "n-face, beta_0 74 deg"])
def test_the_total_field_is_continuous_across_a_reflection_boundary_at_oblique_incidence(tx, axis, material,
                                                                                         compiled):
    """Receivers 1e-7 m either side of where the reflected path appears (100 MHz): the total
    field changes by less than 1e-5 of itself (it changed by 14 % on the lossy wedge at
    beta_0 = 42 deg before the faces' reflections were full matrices)."""
    total, refl = _across_reflection_boundary(_wedge(material), np.array(tx), axis, 1e8, compiled)
    assert refl[0] != refl[-1]  # the reflected path is found on one side only
    assert np.abs(np.diff(total)).max() < 1e-5 * total.max()


def test_a_faces_reflection_in_the_edge_fixed_bases():
    """diag(r_te, r_tm) with incidence normal to the edge, diag(-1, 1) for PEC at every
    beta_0, full at oblique incidence on a dielectric, with the norm of diag(r_te, r_tm)."""
    e, nrm, fb = np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0])
    eta = 5.0 - 9.0j
    for bx, full in ((0.0, False), (1.0, True), (4.0, True)):
        k_in = _unit([-bx, -3.0, 2.0])
        k_out = k_in - 2 * k_in.dot(nrm) * nrm
        r = fresnel_half_space(eta, abs(k_in.dot(nrm)))
        g = edge_fixed_reflection(r.r_te, r.r_tm, k_in, k_out, nrm, e, fb)
        off = np.abs(g[[0, 1], [1, 0]]).max()
        assert (off > 1e-3) == full
        if not full:
            np.testing.assert_allclose(np.diag(g), [r.r_te, r.r_tm], rtol=1e-14)
        np.testing.assert_allclose(np.linalg.norm(g, 2), max(abs(r.r_te), abs(r.r_tm)), rtol=1e-12)
        np.testing.assert_allclose(edge_fixed_reflection(-1.0, 1.0, k_in, k_out, nrm, e, fb), np.diag([-1.0, 1.0]),
                                   atol=1e-15)


def test_diagonal_face_matrices_give_luebbers_coefficients():
    """J = -[(D1 + D2) I + D4 G0 + D3 Gn] with diagonal G's is diag(-D_s, -D_h) of
    luebbers_coefficients; and wedge_reflection_matrices at beta_0 = 90 deg are diagonal."""
    phi = np.linspace(0.1, 2.9, 9)
    pp, n, k, L = 0.7, 1.5, 73.3, 4.0
    r = (-0.6 + 0.1j, 0.4 - 0.2j, -0.7 + 0.05j, 0.3 - 0.1j)
    g0 = np.broadcast_to(np.diag(r[:2]), (len(phi), 2, 2))
    gn = np.broadcast_to(np.diag(r[2:]), (len(phi), 2, 2))
    got = diffraction_jones_matrices(phi, pp, np.pi / 2, n, k, L, "utd", g0, gn)
    d_s, d_h = luebbers_coefficients(phi, pp, np.pi / 2, n, k, L, *r)
    np.testing.assert_allclose(got[:, 0, 0], -d_s, rtol=1e-13)
    np.testing.assert_allclose(got[:, 1, 1], -d_h, rtol=1e-13)
    np.testing.assert_array_equal(got[:, 0, 1], 0)
    np.testing.assert_allclose(diffraction_jones_matrices(phi, pp, np.pi / 2, n, k, L, "gtd", g0, gn),
                               diffraction_jones(phi, pp, np.pi / 2, n, k, L, "gtd", *r), rtol=1e-13)
    # beta_0 = 90 deg: an incident ray in the plane normal to the edge, faces y = 0 and z = 0
    e, s_in = np.array([1.0, 0, 0]), _unit([0.0, -3.0, 2.0])
    s_out = _unit([0.0, 1.0, 1.0])
    G0, Gn = wedge_reflection_matrices(*r, e, s_in, s_out, np.array([0, 1.0, 0]), np.array([0, 0, 1.0]),
                                       np.array([0, 0, 1.0]))
    np.testing.assert_allclose(G0, np.diag(r[:2]), atol=1e-15)
    np.testing.assert_allclose(Gn, np.diag(r[2:]), atol=1e-15)


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("beta_deg", [90.0, 50.0])
def test_the_diffracted_field_is_continuous_where_the_face_labels_switch(compiled, beta_deg):
    """The chain labels a dielectric wedge's faces so that the source lies nearer the 0-face
    than the observer (phi' <= phi, for reciprocity): the labels switch where the observer
    crosses the source's angle, phi = phi'. Both labellings give the same coefficient there,
    so the diffracted field is continuous across it (receivers 1e-7 rad apart), and away
    from it the two sides differ by a finite amount (the test sees the switch)."""
    scene = _wedge(LOSSY)
    # 0-face z = 0 (y < 0), n-face y = 0 (z < 0), free space between: phi from -y toward +z ...
    # the source at phi' = 60 deg from the 0-face, 10 m from the edge, beta_0 from its x offset
    pp = np.radians(60.0)
    d_perp = np.array([0.0, -np.cos(pp), np.sin(pp)])  # the 0-face direction is -y, the edge's normal side +z
    x_off = 10.0 / np.tan(np.radians(beta_deg)) if beta_deg != 90.0 else 0.0
    tx = np.array([-x_off, 0.0, 0.0]) + 10.0 * d_perp
    eps = np.array([-1e-3, -1e-7, 1e-7, 1e-3])
    ang = pp + eps
    rx = np.stack([np.full(4, x_off * 0.8), -8.0 * np.cos(ang), 8.0 * np.sin(ang)], axis=1)
    paths = trace(scene, tx[None], rx, TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=0))
    dh = scene.dihedra
    edge = np.nonzero((np.abs(dh.direction[:, 0]) > 0.999) & (np.abs(dh.origin[:, 1]) < 1e-9)
                      & (np.abs(dh.origin[:, 2]) < 1e-9) & dh.diffracting)[0]
    assert len(edge) == 1
    paths = paths.select((paths.depth == 1) & (paths.primitive[:, 0] == edge[0]))
    assert sorted(paths.rx_index.tolist()) == [0, 1, 2, 3]
    a = compute_fields(scene, paths, FieldConfig(3e9, tx_antenna=Antenna("iso", "VH"), rx_antenna=Antenna("iso", "VH"),
                                                 reflection_model="half_space", compiled=compiled)).a
    a = a[np.argsort(paths.rx_index)]
    scale = np.max(np.abs(a))
    assert np.max(np.abs(a[1] - a[2])) < 1e-5 * scale
    assert np.max(np.abs(a[0] - a[3])) > 1e-4 * scale
