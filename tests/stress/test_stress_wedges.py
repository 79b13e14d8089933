"""Wedges at the ends of their range, and meshes that make geometry hard: n near 1
(almost flat), n near 2 and n = 2, very short and very long edges, nearly parallel edges,
sliver triangles."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths import TraceOptions, trace
from wavepaths.exact.halfplane import halfplane_plane_wave
from wavepaths.exact.wedge import wedge_plane_wave
from wavepaths.em.materials import PEC
from wavepaths.scene import WavepathsWarning, build_scene

from ..conftest import quads_scene
from ..search.brute_force import enumerate_paths
from .helpers import DIFF, REFL, check_laws, halfplane_scalar_total, top_edge, total_field

OPTS = TraceOptions(max_reflections=1, diffraction_reflections=0)
C0 = 299_792_458.0


def tri_scene(vertices, triangles, objects=None):
    v, t = np.asarray(vertices, float), np.asarray(triangles)
    o = np.zeros(len(t), int) if objects is None else np.asarray(objects)
    return build_scene(v, t, o, np.zeros(len(t), int), [f"o{i}" for i in range(o.max() + 1)], [PEC])


def engine_keys(scene, tx, rx, **opts):
    """{(kinds letters, primitives): length} for one pair; duplicates fail."""
    p = trace(scene, tx[None], rx[None], TraceOptions(**opts))
    out = {}
    for i in range(len(p)):
        d = int(p.depth[i])
        key = (tuple("RD"[int(t) - 1] for t in p.interactions[i, :d]), tuple(int(x) for x in p.primitive[i, :d]))
        assert key not in out, f"path found twice: {key}"
        out[key] = p.lengths[i]
    return out, p


def assert_complete(scene, tx, rx, **opts):
    """Same path set as the brute-force enumerator (no shared search code), same lengths."""
    ref = enumerate_paths(scene, tx, rx, **opts)
    got, p = engine_keys(scene, tx, rx, **opts)
    assert set(got) == set(ref), (sorted(set(ref) - set(got)), sorted(set(got) - set(ref)))
    for k in ref:
        assert got[k] == pytest.approx(ref[k], rel=1e-9)
    check_laws(scene, p)
    return got, p


# ---- n near 1 ----------------------------------------------------------------------------------
ROOF_W = 20.0


def roof(dn: float):
    """Two 80 m x 20 m plates on the x axis bent by (n - 1) pi: exterior angle n pi on top."""
    a = dn * np.pi
    d = np.array([0, np.cos(a), -np.sin(a)]) * ROOF_W
    qa = [[-40, -ROOF_W, 0], [40, -ROOF_W, 0], [40, 0, 0], [-40, 0, 0]]
    qb = [[-40, 0, 0], [40, 0, 0], [40, d[1], d[2]], [-40, d[1], d[2]]]
    return quads_scene([qa, qb], objects=[0, 0])


def wedge_go(k_rho, phi, phi_p, n, sign):
    """Geometrical optics of the infinite wedge with faces phi = 0 and n pi, written out: the
    incident plane wave where |phi - phi'| < pi, the 0-face reflection where phi + phi' < pi,
    the n-face reflection where phi + phi' > (2n - 1) pi (R = ``sign``: -1 soft, +1 hard).
    The receivers stay off the boundaries, so no boundary weight is needed."""
    return (np.where(np.abs(phi - phi_p) < np.pi, np.exp(1j * k_rho * np.cos(phi - phi_p)), 0)
            + sign * np.where(phi + phi_p < np.pi, np.exp(1j * k_rho * np.cos(phi + phi_p)), 0)
            + sign * np.where(phi + phi_p > (2 * n - 1) * np.pi,
                              np.exp(1j * k_rho * np.cos(phi + phi_p - 2 * n * np.pi)), 0))


def bend_dihedron(scene):
    """The roof's bend (the dihedron on the x axis), or None once the plates are one polygon."""
    d = scene.dihedra
    score = np.abs(d.origin[:, 1]) + np.abs(d.origin[:, 2]) + np.abs(d.direction[:, 1]) + np.abs(d.direction[:, 2])
    on_axis = np.nonzero(score < 1e-9)[0]
    assert len(on_axis) <= 1
    return int(on_axis[0]) if len(on_axis) else None


ROOF_K_RHO = 200.0  # receivers at k rho = 200 (3.2 m) from the bend
ROOF_SOURCE = 2e7  # [m] the plane wave's source: curvature K^2 / (2 k R) = 1.6e-5 of phase across the ring
ROOF_PHI_P = np.deg2rad(60.0)  # reflection boundaries at phi = 120 deg and 120 deg + 360 (n - 1) deg
ROOF_PHIS = np.deg2rad(np.array([1, 5, 20, 45, 90, 110, 117, 119, 121.5, 123, 130, 160, 175, 179.5]))


@pytest.mark.parametrize("pol", ["V", "H"])
@pytest.mark.parametrize("dn", [1e-4, 1e-5, 3.2e-6, 3.0e-6])
def test_nearly_flat_wedge_tends_to_the_flat_plate(dn, pol):
    """As n -> 1 the bent plate becomes the flat one, through the flat-edge threshold
    (coplanar_angle = 1e-5 rad, i.e. n - 1 = 3.18e-6, where the bend stops being a dihedron).
    Exact reference: Macdonald's eigenfunction series for the wedge of exterior angle
    n pi = (1 + dn) pi (the flat plate's image solution at n = 1), a plane wave from
    phi' = 60 deg (a source 2e7 m away in the plane x = 0 across the bend, so beta_0 = pi/2),
    receivers at k rho = 200 all around on the top side, from 0.5 deg off the faces and 1 deg
    off the reflection boundaries (in their transition regions) to far from both. phi is
    measured from the bent plate over the top (faces at 0 and n pi). V: E across the edge
    (hard), H: E along it (soft).

    * The bend's own diffracted field (exact: series minus the wedge's geometrical optics,
      ~ (n - 1) away from the boundaries: 4e-9 .. 3e-3 of the incident field here) within
      1.25e-3 of itself: UTD's asymptotic error, measured 6.25e-4 = 1 / (8 k rho) at every
      receiver, dn and polarisation (3.6e-4 .. 5e-4 in the transition regions); a bend
      diffracting 1.5x (or 1.002x) too strongly fails.
    * The total field (line of sight, reflections, the bend) within 5e-5 of the unit
      incident field (measured 2.4e-5, 1.6e-5 of it the source's finite distance); the bent
      and flat plates differ there by 3.5e-3 (dn = 3.2e-6) to 0.11 (dn = 1e-4).
    * Below the threshold the plates are one polygon in a fitted plane (area-weighted normal
      and offset) that departs from them by up to delta = W pi dn / 4 (4.7e-5 m): the
      reflection's phase is off by at most 2 k delta, and the bend's diffraction (at most
      8.6e-5) is missing: total within 2 k delta + max |u_d| + 5e-5 = 6.0e-3 (measured 5.05e-3).
    """
    scalar = {"V": "hard", "H": "soft"}[pol]  # the bend lies along x, the rays in the yz plane
    sign = -1.0 if scalar == "soft" else 1.0
    s = roof(dn)
    n = 1.0 + dn
    a = dn * np.pi
    k = 2 * np.pi * 3e9 / C0

    def u(phi):  # phi from the bent plate (direction -a in the yz plane) over the top
        return np.stack([np.zeros_like(phi), np.cos(phi - a), np.sin(phi - a)], axis=-1)

    tx, rx = ROOF_SOURCE * u(np.array([ROOF_PHI_P])), (ROOF_K_RHO / k) * u(ROOF_PHIS)
    exact = wedge_plane_wave(ROOF_K_RHO, ROOF_PHIS, ROOF_PHI_P, n, scalar)
    exact_d = exact - wedge_go(ROOF_K_RHO, ROOF_PHIS, ROOF_PHI_P, n, sign)
    bend = bend_dihedron(s)
    assert (bend is None) == (a < 1e-5), (dn, bend)
    # line of sight and reflections (edge -1: no diffraction kept), then with the bend's
    no_bend = halfplane_scalar_total(s, tx, rx, scalar, 3e9, -1, OPTS)
    assert np.isfinite(no_bend).all()
    if bend is None:
        delta = ROOF_W * a / 4
        tol = 2 * k * delta + np.abs(exact_d).max() + 5e-5
        assert np.abs(no_bend - exact).max() <= tol, (np.abs(no_bend - exact), tol)
        return
    total = halfplane_scalar_total(s, tx, rx, scalar, 3e9, bend, OPTS)
    diffracted = total - no_bend  # the bend's path alone (the rest cancels to rounding)
    rel = np.abs(diffracted - exact_d) / np.abs(exact_d)
    assert (rel <= 0.25 / ROOF_K_RHO).all(), rel
    assert np.abs(total - exact).max() <= 5e-5, np.abs(total - exact)


# ---- n near 2 and n = 2 ------------------------------------------------------------------------
S7 = (
    "BUG S7: in a thin wedge (interior angle alpha), the hidden inner face lies alpha r behind the "
    "front face at distance r from the edge; when alpha r < ray_offset (1e-6 of the diagonal) the "
    "segment to a reflection point on the hidden face is shortened past the front face, so a "
    "reflection *through* the front face is accepted (error ~ the whole reflected field)"
)
S8 = (
    "BUG S8: a zero-thickness double-sided screen (the same quad twice with opposite orientations, "
    "e.g. a thin wedge welded flat) is taken as a closed object with an arbitrary outward side "
    "and reflects on one side only; as two objects, both copies are 'hidden contact faces' and "
    "reflect on neither side (the missing reflection is the whole GO field)"
)


def thin_wedge(alpha: float, flip: bool = False):
    """A screen y = 0, z < 0, and a second face at the interior angle ``alpha`` behind it."""
    a = [[-50, 0, -50], [50, 0, -50], [50, 0, 0], [-50, 0, 0]]
    d = np.array([0, -np.sin(alpha), -np.cos(alpha)]) * 50
    b = [[-50, 0, 0], [50, 0, 0], [50, d[1], d[2]], [-50, d[1], d[2]]]
    return quads_scene([a, b[::-1] if flip else b], objects=[0, 0])


def double_screen(objects):
    a = [[-50, 0, -50], [50, 0, -50], [50, 0, 0], [-50, 0, 0]]
    return quads_scene([a, a[::-1]], objects=objects)


N2_CASES = [
    pytest.param(lambda: thin_wedge(1e-1), 1e-1, id="interior_0.1"),
    pytest.param(lambda: thin_wedge(1e-2), 1e-2, id="interior_1e-2"),
    pytest.param(lambda: thin_wedge(1e-3), 1e-3, id="interior_1e-3"),  # S7 fixed: no end offsets in the casts
    pytest.param(lambda: thin_wedge(1e-4), 1e-4, id="interior_1e-4"),
    pytest.param(lambda: thin_wedge(1e-6), 0.0, id="interior_1e-6_below_coplanar"),
    pytest.param(lambda: thin_wedge(1e-8, flip=True), 0.0, id="interior_1e-8_welded_same_orientation"),
    # S8 fixed: a closed object without volume is no solid; coincident faces reflect once per side
    pytest.param(lambda: thin_wedge(1e-8), 0.0, id="interior_1e-8_welded_closed"),
    pytest.param(lambda: double_screen([0, 0]), 0.0, id="double_sided_one_object"),
    pytest.param(lambda: double_screen([0, 1]), 0.0, id="double_sided_two_objects"),
]


@pytest.mark.parametrize("make, alpha", N2_CASES)
def test_wedges_near_n_2_match_the_exact_series(make, alpha):
    """Exact reference: Macdonald's eigenfunction series for n = 2 - alpha / pi (the
    half-plane's Sommerfeld solution for n = 2), plane wave from phi' = 60 deg (tx 2e4 m away),
    receivers at k rho = 50 all around, including 0.5 deg from the boundaries. Tolerance 3e-3
    of the unit incident field (UTD's asymptotic error at k rho = 50, as for the half-plane)."""
    s = make()
    freq = 3e9
    k = 2 * np.pi * freq / C0
    phi_p = np.deg2rad(60.0)

    def u(phi):
        return np.stack([np.zeros_like(phi), np.sin(phi), -np.cos(phi)], axis=-1)

    tx = 2e4 * u(np.array([phi_p]))
    phis = np.deg2rad(np.array([10, 30, 90, 119.5, 120.5, 150, 200, 239.5, 240.5, 300, 350]))
    n = 2.0 - alpha / np.pi
    for pol in ("soft", "hard"):
        got = halfplane_scalar_total(s, tx, (50.0 / k) * u(phis), pol, freq, top_edge(s), OPTS)
        ref = halfplane_plane_wave(50.0, phis, phi_p, pol) if alpha == 0 else wedge_plane_wave(50.0, phis, phi_p, n, pol)
        np.testing.assert_allclose(got, ref, atol=3e-3, err_msg=pol)


# ---- very short and very long edges --------------------------------------------------------------
GROUND = [[-50, -50, 0], [50, -50, 0], [50, 50, 0], [-50, 50, 0]]


@pytest.mark.parametrize("w", [1e-2, 1e-3, 3e-4])
def test_very_short_edges_diffract_exactly_once_each(w):
    """A w x w plate standing in a 141 m scene (weld tolerance 1.4e-4 m: w = 3e-4 is two
    tolerances). End points are placed so that the Keller point of each of the plate's four
    edges falls inside it: the four diffractions are found, once each, on their cones, and
    the whole path set equals the brute-force enumeration."""
    plate = [[-w / 2, 0, 1], [w / 2, 0, 1], [w / 2, 0, 1 + w], [-w / 2, 0, 1 + w]]
    s = quads_scene([GROUND, plate])
    tx = np.array([0.0, -5.0, 1 + w / 2])
    rx = np.array([0.0, 4.0, 1 + w / 2])
    got, p = assert_complete(s, tx, rx, max_reflections=1, diffraction=True, diffraction_reflections=1)
    short = {i for i in range(len(s.dihedra)) if s.dihedra.length[i] < 2 * w}
    assert len(short) == 4
    hits = [k[1][0] for k in got if k[0] == ("D",)]
    assert sorted(h for h in hits if h in short) == sorted(short)


def test_edges_shorter_than_the_weld_tolerance_are_reported():
    w = 3e-5  # below the weld tolerance 1.4e-4 m of this scene: the plate's corners merge
    plate = [[-w / 2, 0, 1], [w / 2, 0, 1], [w / 2, 0, 1 + w], [-w / 2, 0, 1 + w]]
    with pytest.warns(WavepathsWarning, match="zero-area"):
        quads_scene([GROUND, plate])


@pytest.mark.parametrize("length", [1e4, 1e5])
def test_very_long_edge_matches_sommerfeld_near_its_shadow_boundary(length):
    """A half-plane 1e4 m / 1e5 m long (scene tolerances 0.01 m / 0.1 m); receivers at
    k rho = 50 (0.8 m), 1e-9 rad and 0.5 deg from the incident shadow boundary and elsewhere,
    against the exact solution (tolerance 3e-3 as above)."""
    s = quads_scene([[[-length / 2, 0, -50], [length / 2, 0, -50], [length / 2, 0, 0], [-length / 2, 0, 0]]])
    freq = 3e9
    k = 2 * np.pi * freq / C0
    phi_p = np.deg2rad(60.0)

    def u(phi):
        return np.stack([np.zeros_like(phi), np.sin(phi), -np.cos(phi)], axis=-1)

    tx = 2e4 * u(np.array([phi_p]))
    sb = phi_p + np.pi
    phis = np.array([0.3, 1.2, 2.5, sb - np.deg2rad(0.5), sb - 1e-9, sb + 1e-9, sb + np.deg2rad(0.5), 5.5, 6.1])
    for pol in ("soft", "hard"):
        got = halfplane_scalar_total(s, tx, (50.0 / k) * u(phis), pol, freq, top_edge(s), OPTS)
        np.testing.assert_allclose(got, halfplane_plane_wave(50.0, phis, phi_p, pol), atol=3e-3, err_msg=pol)


# ---- nearly parallel edges ------------------------------------------------------------------------
S6 = (
    "BUG S6: build_dihedra step 4 merges two edges that share a vertex, carry the same polygon and "
    "whose directions agree within coplanar_angle, even when they leave the vertex on the same "
    "side (the two long sides of a needle triangle): one of them disappears, with its diffraction"
)


@pytest.mark.parametrize(
    "h", [1e-2, 1e-3] + [pytest.param(h, marks=()) for h in (1e-4, 5e-5)]
)
def test_needle_plate_keeps_both_nearly_parallel_edges(h):
    """A needle triangle (0,0,0), (10,0,0), (10,0,h) standing in y = 0: its long edges meet at
    the angle h / 10 (1e-3 .. 5e-6 rad). Both diffract: each has its Keller point inside (checked
    in closed form), so two diffraction paths. The line of sight passes just above the needle,
    in one edge's shadow-boundary region and just lit for the other: each edge's field is
    0.36-0.39 of the direct one, and their transition terms cancel, leaving 3.25 % of it for
    every h <= 1e-3 m (3.4 % at 1e-2). That residual does not vanish with h: single diffraction
    on edges closer than a wavelength misses their interaction (the two edges' smooth terms
    are equal, not opposite), a limit of ray theory, not of the search. Held at 4 % (a review
    found the former 5 % let every diffraction scaled by 1.3 pass; now it fails), with each
    edge's field above 0.3 of the direct one, so that the cancellation is tested."""
    s = tri_scene([[0, 0, 0], [10, 0, 0], [10, 0, h]], [[0, 1, 2]])
    tx, rx = np.array([[5.0, -4.0, 0.3]]), np.array([[5.5, 6.0, -0.2]])
    t, p, f = total_field(s, tx, rx, OPTS)
    check_laws(s, p)
    long_edges = [i for i in range(len(s.dihedra)) if s.dihedra.length[i] > 5]
    on_long = [i for i in range(len(p)) if p.depth[i] == 1 and p.interactions[i, 0] == DIFF and p.primitive[i, 0] in long_edges]
    # closed form: both edges run from the origin, so the Keller parameter along each is
    # t = (t_e d_r + t_r d_e) / (d_e + d_r) with t, d measured on that edge's line
    for end in ([10, 0, 0], [10, 0, h]):
        w = np.array(end, float) / np.linalg.norm(end)
        te, tr = tx[0] @ w, rx[0] @ w
        de, dr = np.linalg.norm(tx[0] - te * w), np.linalg.norm(rx[0] - tr * w)
        assert 0 < (te * dr + tr * de) / (de + dr) < np.linalg.norm(end)
    assert len(on_long) == 2
    los = f.a_phased[p.depth == 0].sum()
    assert all(abs(f.a_phased[i]) > 0.3 * abs(los) for i in on_long)
    assert abs(t[0] - los) <= 0.04 * abs(los), abs(t[0] - los) / abs(los)


@pytest.mark.parametrize("tilt", [0.0, 1e-7, 1e-4])
def test_slit_between_nearly_parallel_edges_is_complete(tilt):
    """Two screens of different objects in y = 0, a 5 cm slit between their edges, one screen
    tilted by ``tilt`` in its plane: the path set equals the brute-force enumeration."""
    g = 0.05
    c, sn = np.cos(tilt), np.sin(tilt)
    lower = [[-20, 0, -20], [20, 0, -20], [20, 0, 0], [-20, 0, 0]]
    upper = [[x * c - (z - g) * sn, 0, g + x * sn + (z - g) * c] for x, _, z in
             ([-20, 0, g], [20, 0, g], [20, 0, 20], [-20, 0, 20])]
    s = quads_scene([lower, upper])
    for tx, rx in (((0.3, -4.0, 0.02), (-0.2, 3.0, 0.04)), ((1.0, -2.0, 1.0), (-1.5, 5.0, -0.7))):
        got, _ = assert_complete(s, np.array(tx), np.array(rx), max_reflections=1, diffraction=True,
                                 diffraction_reflections=0)
        assert sum(1 for k in got if k[0] == ("D",)) >= 2


# ---- sliver triangles ---------------------------------------------------------------------------------
def sliver_ground(delta: float):
    """The 100 m ground square as one polygon of slivers: an extra vertex E at ``delta`` from
    the corner A on the bottom edge and a vertex M at height ``delta`` above the bottom edge's
    midpoint; triangles (A, E, D) and (E, M, ...) have aspect ratios up to 1e2 / delta."""
    A, B, C, D = [-50, -50, 0], [50, -50, 0], [50, 50, 0], [-50, 50, 0]
    E, M = [-50 + delta, -50, 0], [0, -50 + delta, 0]
    v = [A, B, C, D, E, M]
    t = [[0, 4, 3], [4, 5, 3], [4, 1, 5], [5, 1, 2], [5, 2, 3]]
    return tri_scene(v, t)


@pytest.mark.parametrize("delta", [1e-2, 1e-3, 5e-4])
def test_sliver_triangles_reflect_exactly_once_with_the_image_length(delta):
    """Reflection points inside the slivers, and 1e-10 m either side of their shared
    (interior, flat) edges: exactly one ground reflection each, at the image-method point and
    length (rel 1e-12), and no diffraction on an interior edge."""
    s = sliver_ground(delta)
    assert s.num_polygons == 1
    v = np.array([1.0, 0.3, -1.0]) / np.linalg.norm([1.0, 0.3, -1.0])
    S = np.array([1.0, 1.0, -1.0])
    # interior edges E-D and E-M and M-D; points on them and just off them, and inside slivers
    pts = []
    for a, b in (([-50 + delta, -50, 0], [-50, 50, 0]), ([-50 + delta, -50, 0], [0, -50 + delta, 0]),
                 ([0, -50 + delta, 0], [-50, 50, 0])):
        a, b = np.array(a), np.array(b)
        m = a + 0.37 * (b - a)
        nrm = np.cross(b - a, [0, 0, 1.0])
        nrm /= np.linalg.norm(nrm)
        pts += [m, m + 1e-10 * nrm, m - 1e-10 * nrm]
    pts += [[-50 + delta / 4, 0.0, 0], [-25.0, -50 + delta / 4, 0]]
    for r0 in np.array(pts, float):
        tx, rx = r0 - 5.0 * v, r0 + 7.0 * v * S
        p = trace(s, tx[None], rx[None], TraceOptions(max_reflections=1, diffraction=True, diffraction_reflections=0))
        refl = np.nonzero((p.depth == 1) & (p.interactions[:, 0] == REFL))[0]
        assert len(refl) == 1, (r0, len(refl))
        np.testing.assert_allclose(p.vertices[refl[0], 1], r0, atol=1e-9)
        assert p.lengths[refl[0]] == pytest.approx(12.0, rel=1e-12)
        diff = p.primitive[p.interactions[:, 0] == DIFF, 0] if p.max_depth else []
        for d in diff:  # only the square's outer border diffracts
            o, w = s.dihedra.origin[d], s.dihedra.direction[d]
            assert max(abs(o[0]), abs(o[1])) == pytest.approx(50.0) and (abs(w[0]) == 1 or abs(w[1]) == 1)
