"""Receivers on, and within 1e-9 rad of, incident shadow and reflection boundaries.

Geometrical optics jumps there by a whole path; the UTD diffracted field jumps by the
opposite amount, so the *total* field must stay continuous. The engine decides GO
visibility with ray casts and point-in-polygon tests and the UTD side with float64
angles: any disagreement between the two shows up here as a jump.

Tolerance: over an angle ``2 delta`` around a boundary a smooth total field changes by at
most ``(k rho + sqrt(k L)) 2 delta`` relative (``k rho`` ~ 200 here), i.e. ~4e-7 for
``delta = 1e-9``; we allow 1e-6 of the total. A GO-side error is O(1).
"""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths import TraceOptions, trace
from wavepaths.em.materials import itu_material
from wavepaths.exact.halfplane import halfplane_plane_wave
from wavepaths.scene import build_scene, load_scene
from wavepaths.scene.builtin import builtin_arrays

from ..conftest import quads_scene
from .helpers import go_mask, halfplane_scalar_total, per_receiver, rotate_yz, top_edge, total_field

DELTA = 1e-9  # [rad] the "within 1e-9 rad"
CONTINUITY = 1e-6  # relative to the total field, see the module docstring
OPTS = TraceOptions(max_reflections=1, diffraction_reflections=0)

S1 = (
    "BUG S1: a reflection point up to ~1e-9 (relative barycentric margin of points_in_polygons) "
    "outside its polygon is accepted, so within ~1e-8 rad of a reflection boundary the GO "
    "reflection is kept on the shadow side while UTD takes the shadow-side limit: the total "
    "field jumps by 20-100 %"
)


def wedge_scene(material=None):
    v, t, o, m, names, mats = builtin_arrays("wedge")
    if material is None:
        return build_scene(v, t, o, m, names, mats)
    return build_scene(v, t, o, np.zeros(len(t), int), names, [material])


SCENES = {"half_plane": lambda: load_scene("half_plane"), "wedge": lambda: wedge_scene(),
          "concrete_wedge": lambda: wedge_scene(itu_material("concrete", thickness_m=0.3))}

# (scene, transmitter in the yz plane, which boundary). Half-plane: screen y = 0, z < 0.
# Wedge: faces z = 0 (y < 0) and y = 0 (z < 0), free space outside the quadrant y, z < 0.
CASES = [
    ("half_plane", (0.0, -3.0, 4.0), "shadow"),
    ("half_plane", (0.0, -3.0, 4.0), "reflection y=0"),
    ("wedge", (0.0, -0.8682, 4.924), "shadow"),
    ("wedge", (0.0, -0.8682, 4.924), "reflection z=0"),
    ("wedge", (0.0, 4.33, -2.5), "shadow"),
    ("wedge", (0.0, 4.33, -2.5), "reflection y=0"),
    ("concrete_wedge", (0.0, -0.8682, 4.924), "shadow"),
    ("concrete_wedge", (0.0, 4.33, -2.5), "reflection y=0"),
]


def boundary_direction(tx: np.ndarray, kind: str) -> np.ndarray:
    """Unit direction, from the edge at the origin, of the boundary of ``kind``."""
    if kind == "shadow":
        d = -tx
    elif kind == "reflection z=0":
        d = -(tx * [1, 1, -1])
    else:
        d = -(tx * [1, -1, 1])
    return d / np.linalg.norm(d)


def case_params():
    out = []
    for name, tx, kind in CASES:
        marks = []  # S1 fixed: the diffraction takes the side of the geometrical-optics decision
        out.append(pytest.param(name, tx, kind, id=f"{name}-{kind}", marks=marks))
    return out


def either_side(scene, tx: np.ndarray, kind: str, rho: float, delta: float, pol: str):
    """Two receivers ``rho`` from the edge, ``delta`` [rad] either side of the boundary of
    ``kind``: their total fields (2,), geometrical-optics path counts (2,) and diffracted fields (2,)."""
    b = boundary_direction(tx[0], kind)
    rx = np.array([rho * rotate_yz(b, s * delta) for s in (-1, 1)])
    t, p, f = total_field(scene, tx, rx, OPTS, pol)
    go = go_mask(p)
    return t, np.bincount(p.rx_index[go], minlength=2), per_receiver(p, f.a_phased, 2, ~go)


@pytest.mark.parametrize("rho", [3.0, 40.0])
@pytest.mark.parametrize("name, tx, kind", case_params())
def test_total_field_is_continuous_within_1e9_rad_of_a_boundary(name, tx, kind, rho):
    scene = SCENES[name]()
    tx = np.array([tx])
    for pol in ("V", "H"):
        t, go, dif = either_side(scene, tx, kind, rho, DELTA, pol)
        # not vacuous: a boundary indeed. Either the search's geometrical-optics decision
        # switches between the two receivers (the diffracted field alone then jumps), or it puts
        # both, within its float margin of the edge, on one side, and the diffracted field
        # follows it; 1e-3 rad away the diffracted field must jump in any case.
        if go[0] != go[1]:
            assert abs(dif[0] - dif[1]) > 0.1 * abs(t).max(), (pol, dif)
        t2, _, dif2 = either_side(scene, tx, kind, rho, 1e-3, pol)
        assert abs(dif2[0] - dif2[1]) > 0.1 * abs(t2).max(), (pol, dif2)
        assert abs(t[0] - t[1]) <= CONTINUITY * abs(t).max(), (pol, t, abs(t[0] - t[1]) / abs(t).max())
        # and the right value, not only the same on both sides: where the search puts both
        # receivers on one side (a reflection boundary, within its float margin), a diffracted
        # field taking the wrong side is wrong on both alike. Anchor: the mean of the totals
        # 1e-7 rad either side, where the geometrical-optics set switches and the total is
        # continuous (the next test); its distance to the boundary's value is second order in
        # the offset. (A review's mutation, the diffraction on the side opposite to the
        # decision, left the total 17-109 % wrong and passed the test without this.)
        t7, _, _ = either_side(scene, tx, kind, rho, SWITCH_DELTA, pol)
        assert abs(t.mean() - t7.mean()) <= SWITCH_CONTINUITY * abs(t7).max(), (
            pol, t, t7, abs(t.mean() - t7.mean()) / abs(t7).max())


SWITCH_DELTA = 1e-7  # [rad] beyond the search's float margins: the GO path set differs on the two sides
SWITCH_CONTINUITY = 1e-4  # (k rho + sqrt(k L)) 2 delta ~ 4e-5 relative at k rho ~ 200


@pytest.mark.parametrize("rho", [3.0, 40.0])
@pytest.mark.parametrize("name, tx, kind", case_params())
def test_total_field_is_continuous_where_the_geometrical_optics_set_switches(name, tx, kind, rho):
    """The test above may see both receivers on one side of the search's decision (within its
    float margin of the boundary), where continuity holds whatever the diffracted field's
    jump. Here, 1e-7 rad either side, the GO path set must differ between the two receivers
    and the diffracted field must jump by the opposite amount: the total stays continuous to
    the smooth field's own change (tolerance 1e-4 of the total; a wrong sign of a face's
    reflection in the diffraction leaves a jump of about twice the reflected field)."""
    scene = SCENES[name]()
    tx = np.array([tx])
    for pol in ("V", "H"):
        t, counts, dif = either_side(scene, tx, kind, rho, SWITCH_DELTA, pol)
        assert counts[0] != counts[1], (pol, counts)  # the boundary is crossed
        assert abs(dif[0] - dif[1]) > 0.1 * abs(t).max(), (pol, dif)
        assert abs(t[0] - t[1]) <= SWITCH_CONTINUITY * abs(t).max(), (pol, t, abs(t[0] - t[1]) / abs(t).max())


# Receivers placed exactly on a boundary with integer coordinates, so that the float64
# offset of the boundary computes to exactly 0 (the UTD term is then the mean of its
# one-sided limits while the search keeps or drops the GO path). The value must be the
# limit from both sides: the mean of the fields at +-1e-6 rad, which the smooth (C1) total
# field reproduces to O((k rho delta)^2) ~ 4e-7; we allow 1e-5. (1e-6 rad keeps the
# neighbours clear of the reflection-margin bug tested above.)
EXACT = [
    ("half_plane", (0.0, -3.0, 4.0), (0.0, 6.0, -8.0)),  # incident shadow boundary
    ("half_plane", (0.0, -3.0, 4.0), (0.0, -6.0, -8.0)),  # reflection boundary of y = 0
    ("wedge", (0.0, -3.0, 4.0), (0.0, 6.0, -8.0)),  # incident shadow boundary
    ("wedge", (0.0, -3.0, 4.0), (0.0, 6.0, 8.0)),  # reflection boundary of z = 0
    ("wedge", (0.0, 4.0, -3.0), (0.0, 8.0, 6.0)),  # reflection boundary of y = 0
    ("concrete_wedge", (0.0, -3.0, 4.0), (0.0, 6.0, -8.0)),
    ("concrete_wedge", (0.0, 4.0, -3.0), (0.0, 8.0, 6.0)),
]


@pytest.mark.parametrize("name, tx, rx", EXACT, ids=[f"{e[0]}-{i}" for i, e in enumerate(EXACT)])
def test_total_field_exactly_on_a_boundary_is_the_limit_from_both_sides(name, tx, rx):
    scene = SCENES[name]()
    tx, rx = np.array([tx]), np.array(rx)
    pts = np.array([rotate_yz(rx, -1e-6), rx, rotate_yz(rx, 1e-6)])
    for pol in ("V", "H"):
        t, p, f = total_field(scene, tx, pts, OPTS, pol)
        assert abs(t[1] - 0.5 * (t[0] + t[2])) <= 1e-5 * abs(t).max(), (pol, t)
        # and the two sides agree: a smooth field moves by about (k rho) 2e-6 ~ 4e-4 over them
        # (8.9e-4 measured at most); a jump of the total is O(1)
        assert abs(t[0] - t[2]) <= 2e-3 * abs(t).max(), (pol, t)
        dif = per_receiver(p, f.a_phased, 3, ~go_mask(p))
        assert abs(dif[0] - dif[2]) > 0.1 * abs(t).max()  # a boundary indeed


@pytest.mark.parametrize("kind", ["shadow", pytest.param("reflection", marks=())])
@pytest.mark.parametrize("pol", ["soft", "hard"])
def test_half_plane_within_1e9_rad_of_a_boundary_matches_sommerfeld(kind, pol):
    """Exact reference: Sommerfeld's half-plane under a plane wave (tx 2e4 m away), on both
    sides of a boundary, 1e-9 rad from it. Tolerance 3e-3 (unit incident field): the
    point source differs from a plane wave by O(rho / s') ~ 1e-4 and UTD from the exact
    solution by O((k rho)^-3/2) ~ 3e-3 at k rho = 50."""
    s = load_scene("half_plane")
    edge = top_edge(s)
    freq = 3e9
    k = 2 * np.pi * freq / 299_792_458.0
    rho = 50.0 / k
    phi_p = np.deg2rad(60.0)  # measured from the screen (direction -z) toward +y

    def u(phi):
        return np.stack([np.zeros_like(phi), np.sin(phi), -np.cos(phi)], axis=-1)

    tx = 2e4 * u(np.array([phi_p]))
    phi_b = phi_p + np.pi if kind == "shadow" else np.pi - phi_p
    phis = np.array([phi_b - DELTA, phi_b + DELTA])
    got = halfplane_scalar_total(s, tx, rho * u(phis), pol, freq, edge, OPTS)
    ref = halfplane_plane_wave(50.0, phis, phi_p, pol)
    np.testing.assert_allclose(got, ref, atol=3e-3)
    assert abs(got[0] - got[1]) <= CONTINUITY * abs(got).max()


def test_shadow_boundary_of_a_reflected_ray_is_compensated_by_the_reflected_diffraction():
    """A ceiling plate reflects the transmitter; the reflected ray grazes the half-plane's
    edge. Its shadow boundary is compensated by the reflection-then-diffraction path, which
    needs the receiver-side images and the float64 re-cast of reflected segments."""
    screen = [[-50, 0, -50], [50, 0, -50], [50, 0, 0], [-50, 0, 0]]
    ceiling = [[-80, -80, 20], [-80, 80, 20], [80, 80, 20], [80, -80, 20]]
    s = quads_scene([screen, ceiling])
    tx = np.array([[0.0, -3.0, 4.0]])
    image = tx[0] * [1, 1, -1] + [0, 0, 40]
    b = -image / np.linalg.norm(image)  # from the image through the edge at the origin
    rx = np.array([5.0 * rotate_yz(b, s_ * DELTA) for s_ in (-1, 1)])
    opts = TraceOptions(max_reflections=1, diffraction_reflections=1)
    for pol in ("V", "H"):
        t, p, f = total_field(s, tx, rx, opts, pol)
        dif = per_receiver(p, f.a_phased, 2, ~go_mask(p))
        assert abs(dif[0] - dif[1]) > 0.1 * abs(t).max(), (pol, dif)
        assert abs(t[0] - t[1]) <= CONTINUITY * abs(t).max(), (pol, t)


def test_reciprocity_holds_for_a_receiver_exactly_on_a_reflection_boundary():
    """three_face_edge: the receiver lies on a reflection boundary of the block corner's edge
    (found by the property tests). The diffraction there takes the GO side by a 1e-9 rad
    nudge; moved on phi alone it left the two directions' coefficients 5e-9 apart, half on
    each of phi and phi' it is symmetric: each path's 2x2 transfer matrix is the transpose of
    its reverse's to 1e-13 relative."""
    from wavepaths.fields import FieldConfig, transfer_matrices

    s = load_scene("three_face_edge")
    a = np.array([[3.5341821156612134, -0.05, 4.1746817066270445]])
    b = np.array([[4.465817884338787, -0.05, 3.825318293372955]])
    opts = TraceOptions(max_reflections=2, diffraction=True, diffraction_reflections=1)
    cfg = FieldConfig(3.5e9)
    forward, backward = trace(s, a, b, opts), trace(s, b, a, opts)
    assert len(forward) == len(backward) and (forward.interactions == 2).any()
    tf, tb = transfer_matrices(s, forward, cfg), transfer_matrices(s, backward, cfg)

    def key(p, i, reverse=False):
        seq = list(zip(p.interactions[i, : p.depth[i]].tolist(), p.primitive[i, : p.depth[i]].tolist()))
        return tuple(seq[::-1] if reverse else seq)

    back = {key(backward, i, True): i for i in range(len(backward))}
    for i in range(len(forward)):
        m, r = tf[i], np.swapaxes(tb[back[key(forward, i)]], -1, -2)
        assert np.abs(np.abs(m) - np.abs(r)).max() <= 1e-13 * np.abs(m).max(), key(forward, i)


def test_a_grazing_source_puts_both_near_boundaries_on_their_sides():
    """A transmitter 2e-5 rad off a face of the wedge: its shadow and reflection boundaries lie
    2e-5 rad apart, both within the search's margin. Only the shadow boundary's side was
    given; a receiver exactly on the reflection boundary got the diffracted term's mean there
    beside a whole reflected path (the total fell from 1.12e-3 to 2e-5 in a review's sweep).
    Both sides are given now, and the total is continuous along the sweep for both
    polarisations (5 %). The antennas are pitched by 90 degrees: every path leaves within
    2e-5 rad of +z, an isotropic antenna's pole, where its horizontal polarisation turns with
    the azimuth and the paths' would differ."""
    from wavepaths.em.antennas import Antenna
    from wavepaths.fields import FieldConfig, compute_fields

    from .helpers import yz

    scene = wedge_scene()
    tx = yz(-np.pi / 2 + 2e-5, 4.0)
    b = -tx / np.linalg.norm(tx)
    s = np.array([-6e-5, -5e-5, -4.25e-5, -4e-5, -3.75e-5, -3e-5, -2e-5, -1e-5, 0.0, 1e-5])
    rx = np.array([3.0 * rotate_yz(b, x) for x in s])
    p = trace(scene, tx[None], rx, OPTS)
    go = np.bincount(p.rx_index[go_mask(p)], minlength=len(s))
    assert len(set(go.tolist())) == 3  # both boundaries crossed along the sweep
    for pol in ("V", "H"):
        ant = Antenna("iso", pol, orientation=(0.0, np.pi / 2, 0.0))
        f = compute_fields(scene, p, FieldConfig(3e9, tx_antenna=ant, rx_antenna=ant))
        t = np.zeros(len(s), complex)
        np.add.at(t, p.rx_index, f.a * np.exp(-2j * np.pi * 3e9 * p.delays))
        mag = np.abs(t)
        assert mag.max() > 0 and np.abs(np.diff(mag)).max() <= 0.05 * mag.max(), (pol, mag)


def test_a_line_of_sight_blocked_by_another_object_leaves_the_diffraction_at_its_angle():
    """Half-plane screen (edge on the x axis), receiver 1 m from the edge and 0.05 rad on the
    lit side of its shadow boundary; a plate that blocks the line of sight but not the
    diffracted leg. The diffracted path is the same with and without the plate, and so must
    its coefficient be (to rounding): the line of sight is missing because of another object,
    not because the receiver is on the edge's shadow side. A review found it moved onto the
    boundary, 243 % off with its sign flipped, once a distant object made the scene 20 km wide
    (the old margin was 4 ray_offset of the size: 0.08 rad here)."""
    from wavepaths.em.antennas import Antenna
    from wavepaths.fields import FieldConfig, compute_fields

    screen = [[-50, 0, -50], [50, 0, -50], [50, 0, 0], [-50, 0, 0]]
    far = [[2e4, 10, 0], [2e4 + 1, 10, 0], [2e4 + 1, 11, 0], [2e4, 11, 0]]  # only widens the scene
    tx = np.array([0.0, -3.0, 4.0])
    rx = rotate_yz(-tx / np.linalg.norm(tx), 0.05)  # 1 m from the edge
    # the plate: across the line of sight 0.6 m before the receiver, its edge midway between the
    # line of sight and the diffracted leg (25 mm apart there)
    d = (rx - tx) / np.linalg.norm(rx - tx)
    c = rx - 0.6 * d
    q = rx + (((c - rx) @ d) / (-rx @ d)) * -rx
    g = (q - c) / np.linalg.norm(q - c)
    e0 = c + 0.5 * np.linalg.norm(q - c) * g
    x = np.array([1.0, 0.0, 0.0])
    plate = [e0 - 0.5 * x, e0 + 0.5 * x, e0 + 0.5 * x - g, e0 - 0.5 * x - g]
    cfg = FieldConfig(3e9, tx_antenna=Antenna("iso", "V"), rx_antenna=Antenna("iso", "V"))
    got = {}
    for name, quads in (("open", [screen, far]), ("blocked", [screen, far, plate]), ("small", [screen])):
        scene = quads_scene([np.asarray(q_, float).tolist() for q_ in quads])
        p = trace(scene, tx[None], rx[None], OPTS)
        f = compute_fields(scene, p, cfg)
        top = [i for i in range(len(p)) if p.depth[i] == 1 and p.interactions[i, 0] == 2
               and abs(p.vertices[i, 1, 1]) + abs(p.vertices[i, 1, 2]) < 1e-12]
        assert len(top) == 1, name
        got[name] = (f.a[top[0]], p.vertices[top[0], :3], int((p.depth == 0).sum()))
    assert got["open"][2] == 1 and got["blocked"][2] == 0  # the plate does block the line of sight
    np.testing.assert_allclose(got["blocked"][1], got["open"][1], atol=1e-12)
    for name in ("blocked", "small"):
        assert abs(got[name][0] - got["open"][0]) <= 1e-12 * abs(got["open"][0]), (name, got[name][0], got["open"][0])


@pytest.mark.parametrize("phi_p", [1e-2, 1e-3, 1e-4, np.pi - 1e-6, np.pi, np.pi + 1e-6],
                         ids=["1e-2", "1e-3", "1e-4", "coplanar-1e-6", "coplanar", "coplanar+1e-6"])
@pytest.mark.parametrize("pol", ["soft", "hard"])
def test_a_source_grazing_the_face_matches_sommerfeld(phi_p, pol):
    """A source grazing the screen's face (phi' -> 0, the shadow and reflection boundaries
    2 phi' apart), against Sommerfeld's exact half-plane solution, receivers all around the
    edge (kappa rho = 50). The screen is 20 km wide and 40 km deep, so that it is a half-plane
    for the source 2e4 m away (its reflection points lie up to 8 km down the face). Tolerance
    3e-3 of the unit incident field, as for the boundaries above: UTD's asymptotic error at
    k rho = 50 (measured 2e-3 at most, hard, broadside); the soft total vanishes with phi'
    (incident and reflected waves cancel on the face), the hard one tends to twice the
    incident field's, which a 1 % error in the grazing reflection would miss. And a source
    coplanar with the screen beyond its edge (phi' = pi, and 1e-6 rad either side: the
    incident wave grazes both faces), where the hard total is the incident field everywhere
    and the soft one is not (the review found coplanar sources checked only against the
    engine's own output)."""
    W, H = 1e4, 4e4
    s = quads_scene([[[-W, 0, -H], [W, 0, -H], [W, 0, 0], [-W, 0, 0]]])
    freq = 3e9
    k = 2 * np.pi * freq / 299_792_458.0
    rho = 50.0 / k

    def u(phi):
        return np.stack([np.zeros_like(phi), np.sin(phi), -np.cos(phi)], axis=-1)

    phis = np.deg2rad(np.array([20.0, 90.0, 150.0, 179.5, 180.5, 200.0, 270.0, 340.0]))
    got = halfplane_scalar_total(s, 2e4 * u(np.array([phi_p])), rho * u(phis), pol, freq, top_edge(s), OPTS)
    ref = halfplane_plane_wave(50.0, phis, phi_p, pol)
    np.testing.assert_allclose(got, ref, atol=3e-3)
