"""Scenes and dihedra: closed-form topology (seed §3.2)."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths.scene import load_scene
from wavepaths.topology.sectors import sector_table

from ..conftest import boxes_scene, quads_scene


def sectors_of(scene, i):
    t = sector_table(scene.dihedra)
    w = t.width[i][: t.count[i]]
    return np.sort(w)


def test_cube_has_twelve_right_angle_wedges():
    s = boxes_scene([((0, 0, 0), (1, 1, 1))])
    d = s.dihedra
    assert len(d) == 12
    assert (d.face_count == 2).all()
    # exterior angle n*pi with n = 1.5
    np.testing.assert_allclose(d.max_sector, 1.5 * np.pi, atol=1e-12)
    assert d.diffracting.all()
    np.testing.assert_allclose(d.length, 1.0, atol=1e-12)
    assert s.num_polygons == 6
    assert d.skipped_flat_edges == 6  # one diagonal per face


def test_single_rectangle_has_four_free_edges():
    s = quads_scene([[[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]]])
    d = s.dihedra
    assert len(d) == 4
    assert (d.face_count == 1).all()
    np.testing.assert_allclose(d.max_sector, 2 * np.pi)
    assert sorted(np.round(d.length, 12).tolist()) == [1.0, 1.0, 2.0, 2.0]


def test_triangulated_quad_diagonal_is_not_a_dihedron():
    s = quads_scene([[[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]]])
    d = s.dihedra
    diag = np.array([1.0, 0.5, 0.0])  # midpoint of the diagonal
    mids = d.origin + 0.5 * d.length[:, None] * d.direction
    assert np.min(np.linalg.norm(mids - diag, axis=1)) > 0.4
    assert d.skipped_flat_edges == 1


def test_box_on_ground_foot_is_a_right_angle_corner_not_a_free_wedge():
    s = boxes_scene([((-1, -1, 0), (1, 1, 2))], ground=10)
    d = s.dihedra
    foot = np.nonzero((np.abs(d.origin[:, 2]) < 1e-12) & (np.abs(d.direction[:, 2]) < 1e-12) & (d.length < 3))[0]
    assert len(foot) == 4
    for i in foot:
        assert d.face_count[i] == 3  # wall, floor of the box, ground
        assert not d.diffracting[i]
        # around the edge: the air corner (pi/2), the box (pi/2), the box floor on the ground (0), underground (pi)
        np.testing.assert_allclose(sectors_of(s, i), [0, np.pi / 2, np.pi / 2, np.pi], atol=1e-9)
    # the box's other 8 edges are ordinary 270 degree wedges
    upper = np.setdiff1d(np.nonzero(d.face_count == 2)[0], foot)
    assert len(upper) == 8
    np.testing.assert_allclose(d.max_sector[upper], 1.5 * np.pi)


def test_two_boxes_touching_along_a_face_share_the_contact_edges():
    s = boxes_scene([((0, 0, 0), (1, 1, 1)), ((1, 0, 0), (2, 1, 1))])
    d = s.dihedra
    on_contact = np.abs(d.origin[:, 0] - 1) < 1e-12
    on_contact &= np.abs(d.direction[:, 0]) < 1e-12
    idx = np.nonzero(on_contact)[0]
    assert len(idx) == 4  # each contact edge represented once
    assert (d.face_count[idx] == 4).all()
    # the contact is flat on the outside: nothing to diffract
    assert not d.diffracting[idx].any()
    # no edge twice anywhere
    keys = np.round(np.concatenate([d.origin, d.end], axis=1), 9)
    keys = np.sort(keys.reshape(-1, 2, 3), axis=1).reshape(-1, 6)
    assert len(np.unique(keys, axis=0)) == len(d)


def test_touching_blocks_edge_has_two_quarter_air_sectors():
    s = load_scene("touching_blocks")
    d = s.dihedra
    i = np.nonzero(d.face_count >= 3)[0]
    assert len(i) == 1
    np.testing.assert_allclose(sectors_of(s, i[0]), [np.pi / 2] * 4, atol=1e-9)
    assert not d.diffracting[i[0]]


def test_three_face_edge_true_dihedron():
    s = load_scene("three_face_edge")
    d = s.dihedra
    i = np.nonzero(d.face_count == 3)[0]
    assert len(i) == 1
    # box top (180 deg), box wall (270 deg), awning (330 deg): sectors 60, 90, 210 degrees
    np.testing.assert_allclose(np.rad2deg(sectors_of(s, i[0])), [60, 90, 210], atol=1e-9)
    assert d.diffracting[i[0]]


def test_collinear_edges_with_the_same_faces_merge():
    # a strip made of two quads side by side: the long edges are split at x = 1
    s = quads_scene(
        [[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[1, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0]]], objects=[0, 0]
    )
    d = s.dihedra
    assert s.num_polygons == 1
    assert len(d) == 4
    assert sorted(np.round(d.length, 9).tolist()) == [1.0, 1.0, 2.0, 2.0]


@pytest.mark.parametrize("name", ["half_plane", "wedge", "box_on_ground", "slit_shutter", "street_canyon",
                                  "three_face_edge", "touching_blocks"])
def test_builtin_scenes_load_and_have_closed_bounds(name):
    s = load_scene(name)
    info = s.summary()
    assert info["triangles"] > 0 and info["dihedra"] > 0
    assert sum(info["dihedra_by_face_count"].values()) == info["dihedra"]
    lo, hi = np.array(info["bounds"])
    assert (hi >= lo).all()


def test_a_finely_faceted_object_survives_welding_in_a_large_scene():
    """A 30 m round tower of 400 facets (1.6 cm wide) on a 20 km ground: the weld tolerance is
    2 cm (1e-6 of the diagonal), so its ring vertices form one chain of 'closer than' pairs.
    Merged transitively the chain collapsed the tower to a point and every one of its 1,600
    triangles was dropped (found by a review); welded greedily, each vertex moves by at most
    the tolerance and the tower keeps its shape (a coarser ring), with a warning."""
    from wavepaths.em.materials import PEC
    from wavepaths.scene.builtin import SceneBuilder
    from wavepaths.scene.model import WavepathsWarning, build_scene

    n = 400
    ang = 2 * np.pi * np.arange(n) / n
    ring = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    verts = np.concatenate([np.c_[ring, np.zeros(n)], np.c_[ring, np.full(n, 30.0)]])
    tris = [[i, (i + 1) % n, n + i] for i in range(n)] + [[(i + 1) % n, n + (i + 1) % n, n + i] for i in range(n)]
    b = SceneBuilder()
    b.add_quad("ground", PEC, [(-1e4, -500, 0), (1e4, -500, 0), (1e4, 500, 0), (-1e4, 500, 0)])
    b.add_mesh("tower", PEC, verts, tris)
    with pytest.warns(WavepathsWarning, match="zero-area"):
        scene = build_scene(*b.arrays())
    tower = scene.triangle_object == scene.object_names.index("tower")
    assert tower.sum() >= n  # at least half the facets remain (pairs of ring vertices merge)
    used = scene.vertices[np.unique(scene.triangles[tower])]
    tol = scene.tolerances.weld * scene.diagonal
    r = np.linalg.norm(used[:, :2], axis=1)
    assert np.all(np.abs(r - 1.0) <= tol) and used[:, 2].max() == pytest.approx(30.0, abs=tol)
    assert np.ptp(used[:, 0]) > 2.0 - 2 * tol and np.ptp(used[:, 1]) > 2.0 - 2 * tol


def test_a_gently_curved_ground_is_not_one_polygon_off_its_plane():
    """A 20 km ground following the Earth in 50 m facets (a fold of 7.8e-6 rad each, under the
    1e-5 rad coplanar angle): neighbours agree, but chaining them made one polygon whose
    facets lay metres off its plane. Each polygon is regrown from a seed, taking the
    neighbours coplanar with the seed by angle or by distance (``coplanar_distance``, 2 mm
    here): every vertex lies within that distance of its polygon's fitted plane (measured
    0.78 mm), far inside the plane tolerance (2 cm)."""
    r_earth = 6371e3
    x = np.arange(0.0, 20000.0 + 1, 50.0)
    th = x / r_earth
    px, pz = r_earth * np.sin(th), r_earth * np.cos(th) - r_earth
    quads = [[(px[i], -50, pz[i]), (px[i + 1], -50, pz[i + 1]), (px[i + 1], 50, pz[i + 1]), (px[i], 50, pz[i])]
             for i in range(len(x) - 1)]
    s = quads_scene(quads, objects=[0] * len(quads))
    assert s.num_polygons > 100  # not one polygon (the folds add up to 3.1e-3 rad)
    tol = s.length_tolerance(s.tolerances.plane_distance)
    for q in range(s.num_polygons):
        v = s.vertices[np.unique(s.triangles[s.polygon_triangles(q)])]
        assert np.abs(v @ s.polygon_normal[q] - s.polygon_offset[q]).max() <= tol
        assert np.abs(v @ s.polygon_normal[q] - s.polygon_offset[q]).max() <= s.length_tolerance(
            s.tolerances.coplanar_distance)
    # no fold between them diffracts (each 7.8e-6 rad: flat within the coplanar angle); only
    # the ground's free borders do
    dh = s.dihedra
    assert dh.diffracting.any() and (dh.faces_per_dihedron[dh.diffracting] == 1).all()


def test_a_flat_ground_in_many_triangles_is_still_one_polygon():
    # the regrowing touches only components that turn: a flat 2 km ground of 800 triangles
    # with float32-rounded vertices (noise far below the angle) is one polygon
    x = np.linspace(0, 2000.0, 401)
    quads = [[(x[i], 0, 0), (x[i + 1], 0, 0), (x[i + 1], 30, 0), (x[i], 30, 0)] for i in range(400)]
    quads = [[tuple(np.float32(c) for c in p) for p in q] for q in quads]
    s = quads_scene(quads, objects=[0] * 400)
    assert s.num_polygons == 1


def test_a_sliver_joined_by_distance_does_not_turn_its_polygon():
    """A 1 km ground of 128 triangles with mixed winding (every second triangle wound the
    other way) and, listed first, a sliver 0.1 mm tall hanging from its border, at right
    angles to it: within ``coplanar_distance`` (0.14 mm) of the ground's plane. With the
    fold cap lifted (``flat_angle`` = 2 rad) it joins the ground's polygon; the triangles were
    oriented by the polygon's first one, the sliver, whose normal is perpendicular to theirs:
    the signs were rounding noise, the ground's area-weighted normal cancelled to (0, -1, 0) and
    its reflection was lost (a review's reproducer). Oriented by the largest triangle, the
    ground stays z = 0 and the reflection has the image method's length. With the default cap
    (1e-2 rad) the sliver is a polygon of its own, with the same result."""
    from wavepaths.em.materials import PEC
    from wavepaths.scene import build_scene
    from wavepaths.scene.tolerances import SceneTolerances
    from wavepaths.search import TraceOptions, trace

    n, size = 8, 1000.0
    xs = np.linspace(0, size, n + 1)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    v = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], 1)
    tris = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = i * (n + 1) + j, (i + 1) * (n + 1) + j, (i + 1) * (n + 1) + j + 1, i * (n + 1) + j + 1
            tris += [[a, b, c], [a, d, c]]  # the second triangle of each quad wound the other way
    v = np.vstack([v, [[size / n / 2, 0.0, -1e-4]]])
    tris = np.array([[n + 1, 0, len(v) - 1]] + tris)  # the sliver first
    tx, rx = np.array([[300.0, 400.0, 20.0]]), np.array([[700.0, 600.0, 10.0]])
    exact = [np.linalg.norm(tx[0] - rx[0]), np.linalg.norm(tx[0] - rx[0] * [1, 1, -1])]
    for tolerances, polygons in ((SceneTolerances(flat_angle=2.0), 1), (SceneTolerances(), 2)):
        s = build_scene(v, tris, np.zeros(len(tris), int), np.zeros(len(tris), int), ["ground"], [PEC],
                        tolerances=tolerances)
        assert s.length_tolerance(s.tolerances.coplanar_distance) > 1e-4
        assert s.num_polygons == polygons
        ground = s.triangle_polygon[1]
        assert abs(s.polygon_normal[ground][2]) == pytest.approx(1.0, abs=1e-12)
        assert abs(s.polygon_offset[ground]) < 1e-5
        p = trace(s, tx, rx, TraceOptions(max_reflections=1, diffraction=False))
        np.testing.assert_allclose(sorted(p.segment_lengths.sum(axis=1)), exact, rtol=1e-9)
