"""Dihedra of edges that meet other edges at T-junctions (seed §3.2: one dihedron per edge
segment with every face on it)."""

from __future__ import annotations

import numpy as np
import pytest


def test_t_junction_splits_a_corner_into_the_shared_flat_stretch_and_the_free_corner():
    """A low block (10 m) against a tall one (20 m), facades continuing each other: the line
    x = y = 0 is a flat facade up to 10 m (four faces, no diffraction) and the tall block's
    right-angled corner above (two faces, n = 1.5). Without the split the corner was one
    20 m dihedron with the low block's faces too (180 degrees: never diffracting), so the
    D path over the upper corner was lost."""
    from wavepaths.em.materials import PEC
    from wavepaths.scene import build_scene
    from wavepaths.scene.builtin import SceneBuilder
    from wavepaths.search import TraceOptions, trace

    b = SceneBuilder()
    b.add_prism("tall", PEC, [(0, 0), (10, 0), (10, 10), (0, 10)], 20.0)
    b.add_prism("low", PEC, [(-10, 0), (0, 0), (0, 10), (-10, 10)], 10.0)
    scene = build_scene(*b.arrays())
    dh = scene.dihedra
    on = np.nonzero((np.linalg.norm(dh.origin[:, :2], axis=1) < 1e-9) & (np.abs(dh.direction[:, 2]) > 0.999))[0]
    spans = sorted((round(float(min(z0, z0 + dz)), 9), round(float(max(z0, z0 + dz)), 9), int(d))
                   for d, z0, dz in zip(on, dh.origin[on, 2], dh.length[on] * dh.direction[on, 2]))
    assert [(lo, hi) for lo, hi, _ in spans] == [(0.0, 10.0), (10.0, 20.0)]
    low_part, high_part = spans[0][2], spans[1][2]
    assert dh.faces_per_dihedron[low_part] == 4 and not dh.diffracting[low_part]
    assert dh.faces_per_dihedron[high_part] == 2 and dh.diffracting[high_part]
    assert np.degrees(dh.max_sector[high_part]) == pytest.approx(270.0, abs=1e-9)
    # tx and rx on either side of the corner, the Keller point at z = 15.65 on the free corner
    p = trace(scene, np.array([[20.0, -20.0, 19.0]]), np.array([[-20.0, -10.0, 13.0]]),
              TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=0))
    d_paths = [i for i in range(len(p)) if p.depth[i] == 1 and p.primitive[i, 0] == high_part]
    assert len(d_paths) == 1
    P = p.vertices[d_paths[0], 1]
    assert P[:2] == pytest.approx([0.0, 0.0], abs=1e-9) and 10.0 < P[2] < 20.0
    # and nothing diffracts on the flat stretch below the low roof
    assert not any(p.primitive[i, 0] == low_part for i in range(len(p)) if p.depth[i] == 1)


@pytest.mark.parametrize("h", [1e-8, 1e-6])
@pytest.mark.parametrize("side", [(-1.0, 1.0), (1.0, 1.0)])
def test_a_sliver_along_an_edge_adds_no_face_to_it(h, side):
    """A 10 m cube whose top front edge carries a sliver triangle 4-C-5, its tip C within the
    weld tolerance of the edge (a T-junction patch of a CAD export) but its area above the
    degenerate-area threshold, so it is kept. The edge keeps its two faces and its 270/90
    degree sectors, every face direction a unit vector: the sliver's entries had a zero or
    rounding-noise direction (its tip is the split vertex), or came back as half-faces of
    the sliver 'polygon', and split the air sector (a transmitter there lost the diffraction)."""
    from wavepaths.em.materials import PEC
    from wavepaths.scene.model import build_scene
    from wavepaths.topology.sectors import sector_table

    L = 10.0
    v = np.array([[0, 0, 0], [L, 0, 0], [L, L, 0], [0, L, 0], [0, 0, L], [L, 0, L], [L, L, L], [0, L, L]], float)
    tris = []
    for a, b, c, d in ((0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)):
        tris += [[a, b, c], [a, c, d]]
    v = np.vstack([v, [[L / 2, side[0] * h, L + side[1] * h]]])
    tris = np.array(tris + [[4, 8, 5]])
    scene = build_scene(v, tris, np.zeros(len(tris), int), np.zeros(len(tris), int), ["o"], [PEC])
    assert scene.dropped_degenerate == 0  # the sliver is kept as a triangle
    d = scene.dihedra
    table = sector_table(d)
    top_front = [i for i in range(len(d.length)) if np.allclose(d.origin[i], [0, 0, L], atol=1e-6)
                 and abs(d.direction[i][0]) > 0.9]
    assert len(top_front) == 1
    i = top_front[0]
    faces = d.face_direction[d.faces(i)]
    np.testing.assert_allclose(np.linalg.norm(faces, axis=1), 1.0, atol=1e-12)
    assert d.faces_per_dihedron[i] == 2 and d.diffracting[i]
    np.testing.assert_allclose(np.sort(np.rad2deg(table.width[i][: table.count[i]])), [90.0, 270.0], atol=1e-4)  # the tip bends the edge by h / 5 m


def _box_across_ground_border(x0: float, x1: float):
    """A closed 4 x 2 x 3 m PEC box from ``x0`` to ``x1`` standing on a ground plane that ends
    at x = 0 (it covers x in [-20, 0]): the box's foot edges along x cross the ground's border,
    and the ground's border edge x = 0 runs under the box's floor for |y| <= 1."""
    from wavepaths.em.materials import PEC
    from wavepaths.scene import build_scene
    from wavepaths.scene.builtin import SceneBuilder

    b = SceneBuilder()
    b.add_quad("ground", PEC, [(-20, -20, 0), (0, -20, 0), (0, 20, 0), (-20, 20, 0)])
    b.add_box("box", PEC, (x0, -1, 0), (x1, 1, 3))
    return build_scene(*b.arrays())


@pytest.mark.parametrize("x0, x1", [(-1.0, 3.0), (-3.0, 1.0)])
def test_an_edge_partly_inside_a_coplanar_polygon_is_split_at_its_border(x0, x1):
    """The box's front foot edge (y = -1, z = 0) lies on the ground for x < 0 (the ground's two
    half-faces: sectors of 90 and 180 degrees, no diffraction) and hangs in the air for x > 0
    (wall and floor: 270 degrees). Before the split the midpoint decided for the whole edge:
    with the box at [-1, 3] the foot diffracted on the ground too (a spurious path through the
    ground), at [-3, 1] it never diffracted (a missed path over the overhang)."""
    from wavepaths.search import TraceOptions, trace

    scene = _box_across_ground_border(x0, x1)
    dh = scene.dihedra
    foot = np.nonzero((np.abs(dh.direction[:, 0]) > 0.999) & (np.abs(dh.origin[:, 1] + 1.0) < 1e-9)
                      & (np.abs(dh.origin[:, 2]) < 1e-9))[0]
    pieces = sorted((float(min(dh.origin[i, 0], dh.end[i, 0])), float(max(dh.origin[i, 0], dh.end[i, 0])), int(i))
                    for i in foot)
    assert [(lo, hi) for lo, hi, _ in pieces] == [pytest.approx((x0, 0.0), abs=1e-9), pytest.approx((0.0, x1), abs=1e-9)]
    on_ground, in_air = pieces[0][2], pieces[1][2]
    assert not dh.diffracting[on_ground] and np.degrees(dh.max_sector[on_ground]) == pytest.approx(180.0, abs=1e-6)
    assert dh.diffracting[in_air] and np.degrees(dh.max_sector[in_air]) == pytest.approx(270.0, abs=1e-6)
    # a transmitter beside the box and a receiver below the floor level, in the plane x = const:
    # the Keller point is (x, -1, 0); over the overhang it is a path, on the ground it is not
    opts = TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=0)
    for x, expected in ((-0.5, 0), (0.5, 1)):
        p = trace(scene, np.array([[x, -6.0, 1.0]]), np.array([[x, 0.0, -3.0]]), opts)
        at_foot = [i for i in range(len(p)) if p.depth[i] == 1
                   and np.allclose(p.vertices[i, 1], [x, -1.0, 0.0], atol=1e-9)]
        assert len(at_foot) == expected, (x, at_foot)


def test_a_long_border_edge_keeps_its_diffraction_outside_a_floor_lying_on_part_of_it():
    """The ground's border edge x = 0 (40 m) runs under the box's 2 m wide floor: only that
    stretch gets the floor's half-faces, which make it flat (ground and floor coplanar: no
    dihedron there). Before the split the floor covered its midpoint, and the whole 40 m edge
    lost its diffraction."""
    scene = _box_across_ground_border(-1.0, 3.0)
    dh = scene.dihedra
    border = np.nonzero((np.abs(dh.direction[:, 1]) > 0.999) & (np.abs(dh.origin[:, 0]) < 1e-9)
                        & (np.abs(dh.origin[:, 2]) < 1e-9))[0]
    spans = sorted((round(float(min(dh.origin[i, 1], dh.end[i, 1])), 9), round(float(max(dh.origin[i, 1], dh.end[i, 1])), 9),
                    bool(dh.diffracting[i])) for i in border)
    assert spans == [(-20.0, -1.0, True), (1.0, 20.0, True)]


@pytest.mark.parametrize("degrees", [0.0, 10.0, 30.0, 45.0])
def test_a_rotation_keeps_the_tolerances_and_the_diffracting_edges(degrees):
    """A 10 m box 1.7e-4 m above a 100 m ground, turned about z: the tolerances scale with the
    scene's size, which a rotation leaves alone (the bounding box's diagonal grew by up to
    sqrt(2) here and took the box's foot in and out of the plane tolerance: 16 diffracting
    edges unrotated, 12 at 30 and 45 degrees). The foot stays a right-angled wedge (its gap
    is above 1e-6 of the size) every way round."""
    from wavepaths.em.materials import PEC
    from wavepaths.scene import build_scene

    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    ground = np.array([[-50, -50, 0], [50, -50, 0], [50, 50, 0], [-50, 50, 0]], float)
    lo, hi = np.array([-5, -5, 1.7e-4]), np.array([5, 5, 10.0])
    corners = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])])
    box_tris = [[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]]
    v = np.vstack([ground, corners]) @ rot.T
    t = np.array([[0, 1, 2], [0, 2, 3]] + [[4 + i for i in tri] for tri in box_tris])
    scene = build_scene(v, t, np.array([0, 0] + [1] * 12), np.zeros(14, int), ["ground", "box"], [PEC])
    assert scene.diagonal == pytest.approx(2 * np.linalg.norm(v - v.mean(axis=0), axis=1).max(), rel=1e-12)
    dh = scene.dihedra
    mid = ((dh.origin + 0.5 * dh.length[:, None] * dh.direction) @ rot)[:, 2]
    feet = np.abs(mid - 1.7e-4) < 1e-6
    assert feet.sum() == 4 and dh.diffracting[feet].all()
    assert int(dh.diffracting.sum()) == 16  # the box's 12 edges and the ground's 4 borders


def test_vertices_near_edges_finds_every_pair_a_brute_force_finds():
    """The T-junction search registers each edge piece by piece along it (a diagonal edge's
    bounding box covered the whole grid): every (vertex, edge) pair whose vertex lies within
    the tolerance of the segment is among its candidates, against all pairs tested directly."""
    from wavepaths.topology.grid import vertices_near_edges

    rng = np.random.default_rng(4)
    a = rng.uniform(0, 1000, (300, 3)) * [1, 1, 0.02]
    b = rng.uniform(0, 1000, (300, 3)) * [1, 1, 0.02]
    t = rng.uniform(0, 1, (2000, 1))
    pick = rng.integers(0, 300, 2000)
    points = np.vstack([a[pick] + t * (b[pick] - a[pick]) + rng.normal(0, 0.3, (2000, 3)),
                        rng.uniform(0, 1000, (500, 3)) * [1, 1, 0.02]])
    tol = 0.5
    vi, ei = vertices_near_edges(a, b, np.minimum(a, b) - tol, np.maximum(a, b) + tol, tol, points)
    got = set(zip(vi.tolist(), ei.tolist()))
    assert len(got) == len(vi)  # each pair once
    d = b - a
    s = np.clip(np.einsum("pej,ej->pe", points[:, None, :] - a[None], d) / np.einsum("ej,ej->e", d, d), 0, 1)
    dist = np.linalg.norm(points[:, None, :] - (a[None] + s[..., None] * d[None]), axis=2)
    near = set(zip(*[x.tolist() for x in np.nonzero(dist <= tol)]))
    assert len(near) > 1000 and near <= got
