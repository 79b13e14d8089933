"""The occlusion rule of wavepaths.raycast, held by both casters, in both directions.

A segment is blocked where it passes through a face (from one side of its plane to the
other, inside the closed triangle); touching a face at an end, lying in its plane or
grazing it does not block. Every case is checked with the float64 numpy caster and the
Embree caster (with its compiled set-up and confirmation when numba is installed, and
with the numpy reference), a -> b and b -> a.
"""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths.raycast.embree import EmbreeRayCaster
from wavepaths.raycast.numpy_caster import NumpyRayCaster
from wavepaths.scene import load_scene, transformed

from ..conftest import boxes_scene, quads_scene

WALL = [[-5, 0, 0], [5, 0, 0], [5, 0, 4], [-5, 0, 4]]  # y = 0, two triangles, diagonal (-5,0,0)-(5,0,4)


def both_casters(scene, a, b):
    """(k,) bool, asserting the two casters and the two directions all agree bit for bit."""
    a, b = np.atleast_2d(np.asarray(a, float)), np.atleast_2d(np.asarray(b, float))
    out = []
    for caster in (NumpyRayCaster(scene), EmbreeRayCaster(scene), EmbreeRayCaster(scene, compiled=False)):
        fwd, bwd = caster.occluded(a, b), caster.occluded(b, a)
        np.testing.assert_array_equal(fwd, bwd)
        out.append(fwd)
    np.testing.assert_array_equal(out[0], out[1])
    np.testing.assert_array_equal(out[0], out[2])
    return out[0]


def test_crossing_a_face_blocks_and_no_segment_leaks_through_its_diagonal():
    s = quads_scene([WALL])
    t = np.linspace(0.0, 1.0, 101)[1:-1]
    on_diag = np.stack([-5 + 10 * t, np.zeros_like(t), 4 * t], axis=1)  # the edge the two triangles share
    a = on_diag + [0.3, -2.0, 0.1]
    b = 2 * on_diag - a  # through the diagonal point, at an angle
    assert both_casters(s, a, b).all()
    assert both_casters(s, [[0, -3, 2]], [[0.5, 3, 1]]).all()
    # through an edge of the wall's boundary (its top edge), crossing its plane: blocked
    assert both_casters(s, [[1, -1, 3]], [[1, 1, 5]]).all()
    # just past it (1e-9 m above the top edge): free
    assert not both_casters(s, [[1, -1, 3 + 2e-9]], [[1, 1, 5 + 2e-9]]).any()


@pytest.mark.parametrize("where", [[0.7, 0, 1.3], [5, 0, 2], [5, 0, 4], [0, 0, 0]], ids=["face", "edge", "vertex", "bottom_edge"])
def test_an_end_on_a_face_touches_it_and_is_not_blocked(where):
    s = quads_scene([WALL])
    p = np.array([where], float)
    others = np.array([[1, -3, 2], [-2, 4, 1], [0.7, 5, 1.3], [9, -1, 8]], float)
    assert not both_casters(s, np.repeat(p, 4, axis=0), others).any()


def test_a_segment_in_a_faces_plane_is_not_blocked_by_it():
    s = quads_scene([WALL])
    assert not both_casters(s, [[-8, 0, 1]], [[8, 0, 3]]).any()  # across the whole wall, in its plane
    assert not both_casters(s, [[-1, 0, 1]], [[2, 0, 1]]).any()  # inside it


@pytest.mark.parametrize("off", [0.0, 1e-10, 1e-8, 1e-6, -1e-7])
@pytest.mark.parametrize("shift", [0.0, 1e6], ids=["rotated", "rotated_at_1e6_m"])
def test_a_segment_in_a_walls_plane_is_blocked_by_a_shelf_through_the_wall(shift, off, rng):
    """One end on a wall, the other on it or a hair off it (``off`` m), the segment (nearly)
    in the wall's plane, a shelf crossing the wall between them: blocked by the shelf.
    Rotated by 37 degrees the float32 half-rays graze the wall itself on the way, whose plane
    holds the target end; taking that for "this half is clear" let 30 of these 2,000
    segments through with both ends on the wall, and up to 83 of 4,000 with one end off it.
    A hit clears a half only at the ray's far end (Embree's hit distance) and on a face that
    does not hold both ends."""
    wall = [[0, -10, 0], [0, 10, 0], [0, 10, 10], [0, -10, 10]]
    shelf = [[-1, -10, 5], [1, -10, 5], [1, 10, 5], [-1, 10, 5]]
    c, s_ = np.cos(np.radians(37.0)), np.sin(np.radians(37.0))
    R = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
    t = np.array([shift, -2 * shift, 30.0])
    scene = transformed(quads_scene([wall, shelf]), R, t)
    n = 2000
    a = np.c_[np.zeros(n), rng.uniform(-9, 9, n), rng.uniform(0.5, 4.5, n)] @ R.T + t
    b = np.c_[np.full(n, off), rng.uniform(-9, 9, n), rng.uniform(5.5, 9.5, n)] @ R.T + t
    assert both_casters(scene, a, b).all()


def test_a_segment_over_a_roof_in_its_plane_grazes_the_walls_top_edge():
    """touching_blocks-like: a block 0..4 x 0..4 x 0..6. The segment lies in the roof's plane
    z = 6, crosses the roof and leaves it over the top edge of the wall y = 0: it runs along
    the surface (not blocked). 1e-9 m lower it passes under the roof edge through the wall
    and the block (blocked); 1e-9 m higher it is free."""
    s = boxes_scene([((0, 0, 0), (4, 4, 6))])
    a, b = np.array([[3.0, 5.0, 6.0]]), np.array([[1.2, -3.0, 6.0]])
    assert not both_casters(s, a, b).any()
    assert both_casters(s, a - [0, 0, 1e-9], b - [0, 0, 1e-9]).all()
    assert not both_casters(s, a + [0, 0, 1e-9], b + [0, 0, 1e-9]).any()
    # a segment in the roof plane that reaches the roof from outside over a vertex
    assert not both_casters(s, [[-2.0, -2.0, 6.0]], [[2.0, 2.0, 6.0]]).any()


@pytest.mark.parametrize("neighbour, cases", [
    # B as tall as A: every leg in the shared plane x = 0 between them is inside
    (((0, -5, 0), (10, 5, 15)), [((-20, 1.5), (20, 1.5), True), ((-20, 2.0), (20, 14.0), True)]),
    # B lower (12 m): above it the shared plane has air on B's side, a leg there runs along A's face
    (((0, -5, 0), (10, 5, 12)), [((-20, 1.5), (20, 1.5), True), ((-20, 13.0), (20, 14.0), False),
                                 ((-20, 2.0), (20, 14.0), True)]),
    # B shifted sideways (y 2..12): the leg runs along A's face in air up to y = 2, then between
    (((0, 2, 0), (10, 12, 15)), [((-20, 1.5), (20, 1.5), True), ((-20, 1.5), (1.0, 1.5), False)]),
], ids=["same_height", "lower", "shifted"])
@pytest.mark.parametrize("shift", [0.0, 1e6], ids=["here", "at_1e6_m"])
def test_a_leg_in_the_plane_of_two_buildings_shared_wall_is_blocked(neighbour, cases, shift):
    """Two closed boxes touching along x = 0 (each with its own face there, as extruded city
    footprints are): A x -10..0, y -5..5, z 0..15. A leg lying in the plane x = 0 enters the
    plane's strip between them at a wall's edge, where the graze rule lets a leg that runs
    along a face pass; with solid on both sides it runs inside the two buildings and is
    blocked (a review found the line of sight and ground reflections through 20 m of
    building). Along a part of A's face with air beside it, it still grazes freely."""
    s = boxes_scene([((-10, -5, 0), (0, 5, 15)), neighbour], ground=50)
    if shift:
        s = transformed(s, translation=[shift, -shift, 0.0])
    for (ya, za), (yb, zb), blocked in cases:
        a = np.array([[shift, ya - shift, za]])
        b = np.array([[shift, yb - shift, zb]])
        assert both_casters(s, a, b).tolist() == [blocked], ((ya, za), (yb, zb))
        assert both_casters(s, a - [1e-3, 0, 0], b - [1e-3, 0, 0]).all()  # 1 mm into A
        assert not both_casters(s, a, a + [0, -1.0, 0]).any()  # outside both, in the plane


@pytest.mark.parametrize("alpha", [1e-3, 1e-4])
def test_the_face_next_to_an_end_point_still_blocks(alpha):
    """A thin wedge: A is the plane y = 0 (z < 0), B leaves the common edge at the interior
    angle alpha. A point P on B at 0.5 m from the edge lies alpha * 0.5 m (5e-4, 5e-5 m)
    behind A, below the old ray offset (1e-6 of the 112 m diagonal = 1.1e-4 m) for 1e-4:
    the segment from P to a point in front of A crosses A and is blocked."""
    a = [[-50, 0, -50], [50, 0, -50], [50, 0, 0], [-50, 0, 0]]
    d = np.array([0, -np.sin(alpha), -np.cos(alpha)]) * 50
    b = [[-50, 0, 0], [50, 0, 0], [50, d[1], d[2]], [-50, d[1], d[2]]]
    s = quads_scene([a, b], objects=[0, 0])
    p = np.array([[3.0, 0.0, 0.0]]) + 0.5 * d / 50  # on B, 0.5 m from the edge
    front = np.array([[1.0, 4.0, -2.0], [-3.0, 2.0, -20.0]])
    assert both_casters(s, np.repeat(p, 2, axis=0), front).all()
    inside = p + [0.0, 0.0, -10.0] + [0, -alpha * 5, 0]  # deeper inside the wedge, between A and B
    assert not both_casters(s, p, inside).any()


@pytest.mark.parametrize("name", ["three_face_edge", "touching_blocks", "street_canyon"])
def test_segments_between_points_on_faces_edges_and_vertices(name, rng):
    """End points exactly on faces, on edges and at vertices (segments along edges, through
    vertices, in the planes of walls and through their edges: the degenerate cases): the
    casters agree bit for bit, both ways. Embree finds the faces; float64 decides."""
    s = load_scene(name)
    tri = s.vertices[s.triangles]
    k = 1500

    def points():
        t = rng.integers(0, len(tri), k)
        w = rng.dirichlet(np.ones(3), k)
        kind = rng.integers(0, 3, k)
        w[kind == 1, 2] = 0.0  # on an edge
        w[kind == 2] = [1.0, 0.0, 0.0]  # at a vertex
        w /= w.sum(axis=1, keepdims=True)
        return np.einsum("kij,ki->kj", tri[t], w)

    a, b = points(), points()
    keep = np.linalg.norm(a - b, axis=1) > 1e-6
    a, b = a[keep], b[keep]
    blocked = both_casters(s, a, b)
    assert 0.05 < blocked.mean() < 0.95


def test_embree_decides_generic_segments_without_float64_fallbacks(rng):
    """Random segments, and segments from points inside faces to random points: Embree's
    nearest face confirms the answer (a blocking face, or the face an end lies on) for all
    but a few (segments lying in a face's plane, as between two points of the ground, are
    decided in float64: the previous test)."""
    s = load_scene("street_canyon")
    tri = s.vertices[s.triangles]
    t = rng.integers(0, len(tri), (2, 2000))
    w = rng.dirichlet(np.ones(3), (2, 2000))
    a = np.einsum("kij,ki->kj", tri[t[0]], w[0])
    lo, hi = s.bounds
    b, c, d = rng.uniform(lo - 5, hi + 5, (3, 2000, 3))
    e = EmbreeRayCaster(s)
    got = e.occluded(np.concatenate([a, c]), np.concatenate([b, d]))
    np.testing.assert_array_equal(got, NumpyRayCaster(s).occluded(np.concatenate([a, c]), np.concatenate([b, d])))
    assert e.exact_fallbacks <= 4e-3 * len(got)


def test_the_rule_survives_a_move_to_1e6_m_and_a_rotation(rng):
    s = load_scene("touching_blocks")
    r = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    t = np.array([1e6, -2e6, 3e5])
    m = transformed(s, rotation=r, translation=t)
    tri = s.vertices[s.triangles]
    idx = rng.integers(0, len(tri), (2, 1000))
    w = rng.dirichlet(np.ones(3), (2, 1000))
    a, b = (np.einsum("kij,ki->kj", tri[idx[j]], w[j]) for j in (0, 1))
    here = both_casters(s, a, b)
    moved = both_casters(m, a @ r.T + t, b @ r.T + t)
    # segments in the plane of a wall through its edges included: the plane tolerance
    # (1e-14 of 2e6 m) absorbs the rounding of the moved coordinates (4e-10 m)
    np.testing.assert_array_equal(here, moved)
    assert 0.1 < here.mean() < 0.9


def test_the_graze_check_gives_the_same_answers_in_chunks(rng):
    """The graze check along a coplanar face's boundary takes its (crossing, neighbour) pairs
    in chunks (a vertex shared by thousands of triangles would hold them all at once): the
    same answers with chunks of one corner as with one chunk, with grazes present."""
    from wavepaths.raycast.numpy_caster import ExactSegments

    scene = load_scene("street_canyon")
    ex = ExactSegments(scene)
    T = scene.vertices[scene.triangles] - scene.center
    m = 3000
    t = rng.integers(0, len(T), m)
    near = rng.uniform(size=(m, 3)) < 0.4
    a = T[t, 0] + 2.0 * (T[t, 1] - T[t, 0])  # in the plane of triangle t: grazes its neighbours in that plane
    b = T[t, 2] - 0.5 * (T[t, 1] - T[t, 2])
    x = T[t, 1] + 1e-15
    whole = ex._grazes_coplanar_face(a, b, x, t, near)
    assert whole.sum() > 100
    for budget in (1, 5, 33):
        np.testing.assert_array_equal(ex._grazes_coplanar_face(a, b, x, t, near, budget=budget), whole)
