"""FindDihedron (seed §3.3) against an independent angular-sector reference."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths.topology.dihedra import Dihedra
from wavepaths.topology.find_dihedron import find_dihedron


def synthetic_dihedra(face_angle_sets):
    """Dihedra on the z axis through the origin, with faces at the given angles [rad]."""
    d = len(face_angle_sets)
    counts = np.array([len(a) for a in face_angle_sets])
    ang = np.concatenate(face_angle_sets)
    pf = np.stack([np.cos(ang), np.sin(ang), np.zeros_like(ang)], axis=1)
    normal = np.stack([-np.sin(ang), np.cos(ang), np.zeros_like(ang)], axis=1)
    z = np.zeros(len(ang), dtype=np.int64)
    return Dihedra(
        origin=np.zeros((d, 3)), direction=np.tile([0.0, 0.0, 1.0], (d, 1)), length=np.ones(d),
        face_ptr=np.concatenate([[0], np.cumsum(counts)]), face_triangle=z, face_polygon=z,
        face_direction=pf, face_normal=normal, face_count=counts, max_sector=np.full(d, 2 * np.pi),
        diffracting=np.ones(d, bool), mesh_edges_ptr=np.arange(d + 1), mesh_edges=np.arange(d), skipped_flat_edges=0,
    )


def same_sector_reference(face_angles, a_e, a_r):
    """True when directions a_e and a_r lie strictly in the same sector between faces."""
    f = np.sort(np.mod(face_angles, 2 * np.pi))
    def sector(a):
        return (np.searchsorted(f, np.mod(a, 2 * np.pi), side="right") - 1) % len(f)
    return sector(a_e) == sector(a_r)


def test_matches_the_sector_reference_on_random_edges(rng):
    sets, ae, ar = [], [], []
    for _ in range(3000):
        k = rng.integers(1, 6)
        sets.append(rng.uniform(0, 2 * np.pi, k))
        ae.append(rng.uniform(0, 2 * np.pi))
        ar.append(rng.uniform(0, 2 * np.pi))
    d = synthetic_dihedra(sets)
    ae, ar = np.array(ae), np.array(ar)
    zs = rng.uniform(-3, 3, (len(sets), 2))  # positions along the edge do not matter
    e = np.stack([2 * np.cos(ae), 2 * np.sin(ae), zs[:, 0]], axis=1)
    r = np.stack([5 * np.cos(ar), 5 * np.sin(ar), zs[:, 1]], axis=1)
    res = find_dihedron(d, np.arange(len(sets)), np.zeros((len(sets), 3)), e, r)
    ref = np.array([same_sector_reference(f, a, b) for f, a, b in zip(sets, ae, ar)])
    np.testing.assert_array_equal(res.valid, ref)
    v = res.valid
    # the bounding faces and angles describe the sector: 0 < phi, phi' < n pi
    assert (res.phi_prime[v] > 0).all() and (res.phi_prime[v] < res.wedge_angle[v]).all()
    assert (res.phi[v] > 0).all() and (res.phi[v] < res.wedge_angle[v]).all()
    # the sector's width is the gap between its two bounding faces
    for i in np.nonzero(v)[0][:300]:
        f = np.sort(np.mod(sets[i], 2 * np.pi))
        gaps = np.diff(np.concatenate([f, [f[0] + 2 * np.pi]]))
        assert np.min(np.abs(gaps - res.wedge_angle[i])) < 1e-9


def find_dihedron_as_printed(face_angles, a_e, a_r):
    """A literal transcription of the seed's pseudo-code, copy slips included.

    Its `max` branches assign the min variables, and sit in an ElseIf after the min test.
    """
    ue = np.array([np.cos(a_e), np.sin(a_e), 0.0])
    ur = np.array([np.cos(a_r), np.sin(a_r), 0.0])
    w = np.array([0.0, 0.0, 1.0])
    up = np.cross(ue, w)
    tmin = bmin = np.inf
    tmax = bmax = -np.inf
    has_t = has_b = False
    for a in face_angles:
        pf = np.array([np.cos(a), np.sin(a), 0.0])
        c_i = ue @ pf
        if up @ pf < 0:
            has_b = True
            if c_i < bmin:
                bmin = c_i
            elif c_i > bmax:
                bmin = c_i  # the slip: should be bmax
        else:
            has_t = True
            if c_i < tmin:
                tmin = c_i
            elif c_i > tmax:
                tmin = c_i  # the slip: should be tmax
    c = ue @ ur
    r_in_b = up @ ur < 0
    if r_in_b:
        return (not has_b) or (has_b and has_t and c > bmax) or (not has_t and (c < bmin or c > bmax))
    return (not has_t) or (has_t and has_b and c > tmax) or (not has_b and (c < tmin or c > tmax))


def test_the_printed_pseudo_code_accepts_a_path_through_a_solid_and_ours_does_not():
    # a right-angle solid between faces at 0 and 90 degrees; the source at 180 degrees,
    # the receiver at 45 degrees: inside the solid.
    faces = np.array([0.0, np.pi / 2])
    a_e, a_r = np.pi, np.pi / 4
    assert bool(find_dihedron_as_printed(faces, a_e, a_r))
    d = synthetic_dihedra([faces])
    res = find_dihedron(d, np.array([0]), np.zeros((1, 3)),
                        np.array([[np.cos(a_e), np.sin(a_e), 0]]), np.array([[np.cos(a_r), np.sin(a_r), 1.0]]))
    assert not res.valid[0]
    assert not same_sector_reference(faces, a_e, a_r)
    # and a receiver outside the solid (at 200 degrees) is accepted by both
    res2 = find_dihedron(d, np.array([0]), np.zeros((1, 3)),
                         np.array([[np.cos(a_e), np.sin(a_e), 0]]), np.array([[np.cos(3.5), np.sin(3.5), 0.0]]))
    assert res2.valid[0] and find_dihedron_as_printed(faces, a_e, 3.5)


@pytest.mark.parametrize("n", [1.1, 1.5, 1.9])
def test_wedge_angles_are_utd_angles(n):
    # 0-face at angle 0, n-face at n*pi; source at phi' and observer at phi
    d = synthetic_dihedra([np.array([0.0, n * np.pi])])
    phi_p, phi = 0.3 * n * np.pi, 0.8 * n * np.pi
    res = find_dihedron(d, np.array([0]), np.zeros((1, 3)),
                        np.array([[np.cos(phi_p), np.sin(phi_p), 0.5]]), np.array([[np.cos(phi), np.sin(phi), -2.0]]))
    assert res.valid[0]
    assert res.wedge_angle[0] == pytest.approx(n * np.pi, abs=1e-12)
    assert res.phi_prime[0] == pytest.approx(phi_p, abs=1e-12)
    assert res.phi[0] == pytest.approx(phi, abs=1e-12)
    f = d.face_direction
    np.testing.assert_allclose(f[res.face_0[0]], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(f[res.face_n[0]], [np.cos(n * np.pi), np.sin(n * np.pi), 0], atol=1e-12)


def test_same_sector_is_find_dihedron_anywhere_on_the_edge(rng):
    """The engine replaces FindDihedron at P by one sector lookup per end (a sector is a
    prism around the edge line): same verdict, same true dihedron, same UTD angles, for
    diffraction points anywhere along the edge and ends far from it."""
    from wavepaths.topology.sectors import sector_angle, sector_table

    sets, ae, ar = [], [], []
    for _ in range(3000):
        k = rng.integers(1, 6)
        sets.append(rng.uniform(0, 2 * np.pi, k))
        ae.append(rng.uniform(0, 2 * np.pi))
        ar.append(rng.uniform(0, 2 * np.pi))
    d = synthetic_dihedra(sets)
    n = len(sets)
    ae, ar = np.array(ae), np.array(ar)
    def ends(angle):  # distance to the edge 0.1-50 m, anywhere along it
        pts = np.zeros((n, 3))
        pts[:, :2] = rng.uniform(0.1, 50, n)[:, None] * np.stack([np.cos(angle), np.sin(angle)], 1)
        pts[:, 2] = rng.uniform(-40, 40, n)
        return pts

    e, r = ends(ae), ends(ar)
    p = np.zeros((n, 3))
    p[:, 2] = rng.uniform(-1, 1, n)  # the point on the edge: FindDihedron's P
    idx = np.arange(n)
    ref = find_dihedron(d, idx, p, e, r)
    tab = sector_table(d)
    se, _, phi_e = sector_angle(tab, idx, e, d.origin)
    sr, _, phi_r = sector_angle(tab, idx, r, d.origin)
    # away from faces (the sector lookup's 1e-7 rad margin), the verdicts are the same
    clear = (se >= 0) & (sr >= 0)
    assert clear.mean() > 0.99
    same = clear & (se == sr)
    np.testing.assert_array_equal(same[clear], ref.valid[clear])
    v = same
    faces, count = tab.face[idx[v]], tab.count[idx[v]]
    f0 = faces[np.arange(v.sum()), se[v]]
    fn = faces[np.arange(v.sum()), np.mod(se[v] + 1, count)]
    np.testing.assert_array_equal(f0, ref.face_0[v])
    np.testing.assert_array_equal(fn, ref.face_n[v])
    np.testing.assert_allclose(phi_e[v], ref.phi_prime[v], atol=1e-12)
    np.testing.assert_allclose(phi_r[v], ref.phi[v], atol=1e-12)
    np.testing.assert_allclose(tab.width[idx[v], se[v]], ref.wedge_angle[v], atol=1e-12)
