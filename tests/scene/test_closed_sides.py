"""Which side of each polygon reflects: closed objects with a volume, contact faces,
double-sided screens, duplicated faces; and which points lie inside a closed object."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths import TraceOptions, trace
from wavepaths.em.materials import PEC, itu_material
from wavepaths.scene import build_scene, load_scene
from wavepaths.scene.closed import points_inside_closed

from ..conftest import box_arrays, quads_scene

SCREEN = [[-5, 0, 0], [5, 0, 0], [5, 0, 4], [-5, 0, 4]]  # normal -y (right-hand rule)


def reflecting_side(scene, i):
    """The unit vector of the side polygon ``i`` reflects on, 0 if both, None if hidden."""
    if scene.hidden_polygons[i]:
        return None
    return scene.outward_sign[i] * scene.polygon_normal[i]


def polygon_at(scene, point, normal):
    """Polygons through ``point`` with normal +-``normal``."""
    n = scene.polygon_normal
    on = (np.abs(n @ np.asarray(normal, float)) > 1 - 1e-9) & (np.abs(n @ point - scene.polygon_offset) < 1e-9)
    return np.nonzero(on)[0]


def test_box_on_ground_walls_reflect_outside_and_its_floor_is_a_contact_face():
    s = load_scene("box_on_ground")
    box = s.object_names.index("box")
    for i in np.nonzero(s.polygon_object == box)[0]:
        c = s.vertices[s.triangles[s.polygon_triangles(i)]].reshape(-1, 3).mean(axis=0)
        side = reflecting_side(s, i)
        if abs(c[2]) < 1e-9:  # the floor, lying on the ground
            assert side is None
        else:  # outward: away from the box's centre (0, 0, 5)
            assert side is not None and side @ (c - [0, 0, 5]) > 0
    ground = np.nonzero(s.polygon_object == s.object_names.index("ground"))[0]
    assert all(np.all(reflecting_side(s, int(i)) == 0) for i in ground)


def test_the_shared_face_of_stacked_boxes_is_hidden_on_both_boxes():
    v1, t1 = box_arrays((0, 0, 0), (4, 4, 3))
    v2, t2 = box_arrays((0, 0, 3), (4, 4, 6))
    s = build_scene(np.concatenate([v1, v2]), np.concatenate([t1, t2 + 8]), np.repeat([0, 1], 12),
                    np.zeros(24, int), ["low", "high"], [PEC])
    shared = polygon_at(s, np.array([2.0, 2.0, 3.0]), [0, 0, 1])
    assert len(shared) == 2 and s.hidden_polygons[shared].all()
    assert (~s.hidden_polygons).sum() == s.num_polygons - 2
    assert (s.outward_sign[~s.hidden_polygons] != 0).all()


@pytest.mark.parametrize("how", ["two_objects", "two_materials", "one_polygon"])
def test_a_double_sided_screen_reflects_once_on_each_side(how):
    """The same quad twice with opposite orientations: as two objects, as one closed object
    of two materials (no volume), or welded into one polygon. Each side of the screen
    reflects exactly once, with the image-method length."""
    quads = [SCREEN, SCREEN[::-1]]
    v = np.array(quads[0] + quads[1], float)
    t = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    obj = {"two_objects": [0, 0, 1, 1], "two_materials": [0] * 4, "one_polygon": [0] * 4}[how]
    mat = {"two_objects": [0] * 4, "two_materials": [0, 0, 1, 1], "one_polygon": [0] * 4}[how]
    s = build_scene(v, t, np.array(obj), np.array(mat), ["a", "b"], [PEC, itu_material("concrete")])
    assert not s.hidden_polygons.any()
    if how == "one_polygon":
        assert s.num_polygons == 1 and s.outward_sign[0] == 0
    else:
        assert s.num_polygons == 2 and (s.outward_sign == 1).all()  # each copy on its front side
    for y in (-3.0, 3.0):
        tx, rx = np.array([[-2.0, y, 1.0]]), np.array([[2.5, 1.5 * y, 2.5]])
        p = trace(s, tx, rx, TraceOptions(max_reflections=1, diffraction=False))
        refl = np.nonzero(p.depth == 1)[0]
        assert len(refl) == 1, (how, y, p.primitive[refl])
        image = tx[0] * [1, -1, 1]
        assert p.lengths[refl[0]] == pytest.approx(np.linalg.norm(rx[0] - image), rel=1e-12)
        # the side that reflects is the front of the copy found
        assert s.polygon_normal[p.primitive[refl[0], 0]] @ [0, np.sign(y), 0] > 0 or how == "one_polygon"


def test_a_duplicated_face_reflects_once():
    """Two objects with the same quad, same orientation (a duplicated wall): one copy is
    hidden, the other reflects on both sides."""
    s = quads_scene([SCREEN, SCREEN])
    assert s.hidden_polygons.sum() == 1
    assert s.outward_sign[~s.hidden_polygons][0] == 0


def test_a_plate_lying_on_a_larger_screen_is_hidden():
    small = [[-1, 0, 1], [1, 0, 1], [1, 0, 2], [-1, 0, 2]]
    s = quads_scene([SCREEN, small[::-1]])
    assert list(s.hidden_polygons) == [False, True]


def test_points_inside_closed_objects():
    s = load_scene("three_face_edge")  # a closed block (0..4)^3 with an awning hinged on its roof edge
    block = s.object_names.index("block")
    pts = np.array([[2.0, 2.0, 2.0], [3.9, 0.1, 3.99], [4.1, 2.0, 2.0], [2.0, 2.0, 4.1], [5.0, 2.0, 3.5]])
    got = points_inside_closed(s, pts)
    np.testing.assert_array_equal(got[:, block], [True, True, False, False, False])
    assert not got[:, s.object_names.index("awning")].any()
    # a closed object without volume (a double-sided screen) has no inside
    screen = build_scene(np.array(SCREEN + SCREEN[::-1], float), np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]]),
                         np.zeros(4, int), np.zeros(4, int), ["s"], [PEC])
    assert not points_inside_closed(screen, [[0.0, 0.0, 1.0], [0.0, 1e-9, 1.0], [0.0, -1.0, 1.0]]).any()


@pytest.mark.parametrize("name", ["street_canyon", "three_face_edge", "touching_blocks"])
def test_the_box_prefilter_of_points_inside_closed_changes_no_answer(name, rng, monkeypatch):
    """Points outside every closed object's (padded) box skip the parity test: the answers
    on points in and around the scene, on its vertices and on its faces are those of the
    parity test run on every point (boxes made infinite), also in chunks of a few pairs."""
    from wavepaths.scene import closed

    s = load_scene(name)
    lo, hi = s.bounds
    tri = s.vertices[s.triangles[rng.integers(0, len(s.triangles), 400)]]
    pts = np.concatenate([rng.uniform(lo - 2, hi + 2, (3000, 3)), s.vertices,
                          np.einsum("kij,ki->kj", tri, rng.dirichlet(np.ones(3), 400))])
    got = points_inside_closed(s, pts)
    boxes = s.object_boxes
    n = len(s.object_names)
    s.__dict__["object_boxes"] = (np.full((n, 3), -np.inf), np.full((n, 3), np.inf))  # every point near
    ref = points_inside_closed(s, pts)
    np.testing.assert_array_equal(got, ref)
    assert ref.any() and not ref.all()
    s.__dict__["object_boxes"] = boxes
    monkeypatch.setattr(closed, "BOX_PAIRS", 7)
    np.testing.assert_array_equal(points_inside_closed(s, pts), ref)


def test_the_solid_objects_are_computed_once_per_scene_and_read_only():
    """Every coverage tile asks which objects are solids (through its receivers' image trees);
    the answer is the scene's, computed once: the box of box_on_ground is a solid, its ground
    is not, and the cached mask cannot be changed by a caller."""
    from wavepaths.scene.closed import compute_solid_objects_mask, solid_objects_mask

    scene = load_scene("box_on_ground")
    mask = solid_objects_mask(scene)
    assert mask is solid_objects_mask(scene) and not mask.flags.writeable
    np.testing.assert_array_equal(mask, compute_solid_objects_mask(scene))
    names = list(scene.object_names)
    assert mask[names.index("box")] and not mask[names.index("ground")]
    with pytest.raises(ValueError):
        mask[0] = not mask[0]
