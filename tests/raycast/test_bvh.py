"""The float64 tree of the occlusion queries (wavepaths.raycast.bvh): the exact rule, segment
for segment, and the tree itself."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from wavepaths.raycast import bvh, canonical, embree
from wavepaths.raycast.embree import EmbreeRayCaster
from wavepaths.scene import load_scene
from wavepaths.search import TraceOptions, trace

from .test_embree_compiled import _segments, _street_canyon

needs_numba = pytest.mark.skipif(embree._compiled() is None, reason="numba is not installed (the `fast` extra)")


def _exact(caster: EmbreeRayCaster, scene, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The float64 rule against every triangle (no index): the reference."""
    A, B, _ = canonical(a - scene.center, b - scene.center)
    return caster._exact.blocked(A, B, index=False)


@needs_numba
@pytest.mark.parametrize("name,moved", [("street_canyon", False), ("street_canyon", True), ("touching_blocks", False),
                                        ("three_face_edge", False), ("box_on_ground", False)])
def test_the_tree_decides_every_segment_by_the_exact_rule(name, moved, rng):
    """The same verdicts as the float64 rule against every triangle, both directions: free
    segments (ends outside the scene's box too), vertex to vertex (along edges, through shared
    edges and corners), face points to free points (the search's legs), zero-length ones;
    also with the street canyon moved to 1e6 m and rotated."""
    scene = _street_canyon(moved) if name == "street_canyon" else load_scene(name)
    a, b = _segments(scene, rng, 3000)
    caster = EmbreeRayCaster(scene, bvh=True)
    assert caster._bvh is not None
    expect = _exact(caster, scene, a, b)
    assert 0.05 < expect.mean() < 0.95  # both outcomes are exercised
    np.testing.assert_array_equal(caster.occluded(a, b), expect)
    np.testing.assert_array_equal(caster.occluded(b, a), expect)
    # the legs of chains, read in place (occluded_legs), as the search casts them
    V = np.stack([a, b, a[::-1]], axis=1)
    alive = np.arange(0, len(a), 3)
    np.testing.assert_array_equal(caster.occluded_legs(V, alive, 0, 1), expect[alive])
    assert caster.rays_cast == 0  # no float32 ray was needed


@needs_numba
def test_segments_with_ends_that_are_not_finite_get_the_exact_rules_answer():
    scene = load_scene("street_canyon")
    caster = EmbreeRayCaster(scene, bvh=True)
    a = np.array([[0.0, 0.0, 1.5], [np.inf, 0.0, 1.5], [np.nan, 0.0, 1.5], [-60.0, 0.0, 10.0]])
    b = np.array([[np.inf, 0.0, 1.5], [0.0, 0.0, 1.5], [0.0, 0.0, 1.5], [60.0, 0.0, 10.0]])
    np.testing.assert_array_equal(caster.occluded(a, b), _exact(caster, scene, a, b))


@needs_numba
def test_the_street_canyons_paths_are_the_same_through_the_tree_and_through_embree():
    """R2+D1 paths to 40 receivers: the tree (default on this scene) and Embree's half-rays
    keep the same paths, vertex for vertex (no segment of this scene is within float32
    reach of a face's edge)."""
    from wavepaths.bench.scenes import STREET_CANYON_TX, sionna_scene_xml, street_canyon_receivers

    rx = street_canyon_receivers(40)
    found = []
    for use in (True, False):
        scene = load_scene(sionna_scene_xml("simple_street_canyon"))
        scene.__dict__["raycaster"] = EmbreeRayCaster(scene, bvh=use)
        found.append(trace(scene, STREET_CANYON_TX, rx, TraceOptions(max_reflections=2, diffraction_reflections=1)))
    tree, emb = found
    assert len(tree) == len(emb) > 500
    for key in ("tx_index", "rx_index", "depth", "interactions", "primitive"):
        np.testing.assert_array_equal(getattr(tree, key), getattr(emb, key))
    np.testing.assert_array_equal(tree.vertices, emb.vertices)


def test_the_tree_holds_every_triangle_once_inside_its_boxes():
    """Every triangle in exactly one leaf; each node's box holds its triangles' padded boxes
    and its children's boxes; a left child follows its parent."""
    scene = load_scene("street_canyon")
    ex = EmbreeRayCaster(scene, bvh=False)._exact
    t = bvh.build_segment_bvh(ex, leaf_size=2)
    np.testing.assert_array_equal(np.sort(t.triangle), np.arange(len(scene.triangles)))
    lo, hi = ex.lo - ex.pad, ex.hi + ex.pad
    for nd in range(len(t.box)):
        if t.count[nd]:
            tri = t.triangle[t.first[nd]:t.first[nd] + t.count[nd]]
            assert (t.box[nd, :3] <= lo[tri]).all() and (t.box[nd, 3:] >= hi[tri]).all()
            assert t.right[nd] == -1
        else:
            for child in (nd + 1, t.right[nd]):
                assert (t.box[nd, :3] <= t.box[child, :3]).all() and (t.box[nd, 3:] >= t.box[child, 3:]).all()
    # the rows are the triangles' planes and edges in leaf order
    np.testing.assert_array_equal(t.rows[:, :3], ex.normal[t.triangle])
    np.testing.assert_array_equal(t.rows[:, 5:8], ex.inward[t.triangle, 0])


def test_a_tree_of_boxes_that_cannot_be_split_stops_at_its_depth_limit():
    """2,000 triangles with the same box (no split separates them): the depth stays within
    MAX_DEPTH, so the walk's stack is bounded, and every triangle is in a leaf."""
    n = 2000
    box = np.tile([[0.0, 0.0, 0.0]], (n, 1))
    ex = SimpleNamespace(lo=box, hi=box + 1.0, pad=1e-9, normal=np.tile([0.0, 0.0, 1.0], (n, 1)), offset=np.zeros(n),
                         tol=np.full(n, 1e-12), inward=np.zeros((n, 3, 3)), inward_offset=np.zeros((n, 3)),
                         edge_tol=1e-12, box_lo=box, box_hi=box + 1.0)
    t = bvh.build_segment_bvh(ex)
    assert t.depth <= bvh.MAX_DEPTH
    np.testing.assert_array_equal(np.sort(t.triangle), np.arange(n))


@needs_numba
def test_the_caster_builds_the_tree_for_small_scenes_only(monkeypatch):
    scene = load_scene("street_canyon")
    assert EmbreeRayCaster(scene)._bvh is not None
    assert EmbreeRayCaster(scene, bvh=False)._bvh is None
    assert EmbreeRayCaster(scene, compiled=False)._bvh is None  # the numpy reference casts with Embree
    monkeypatch.setattr(bvh, "BVH_MAX_TRIANGLES", len(scene.triangles) - 1)
    assert EmbreeRayCaster(scene)._bvh is None
    assert EmbreeRayCaster(scene, bvh=True)._bvh is not None


# ---- regressions found by an adversarial review (each failed before its fix) ---------------
def _rotation() -> np.ndarray:
    """A fixed generic rotation (every normal then has three non-zero components)."""
    c, s = np.cos(0.7), np.sin(0.7)
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    c, s = np.cos(0.4), np.sin(0.4)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    return rz @ rx


def _all_agree(scene, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rule against every triangle, through the grid, through the tree and through
    Embree's confirmed half-rays where they decide: asserts the first three equal, both ways."""
    from wavepaths.raycast.numpy_caster import NumpyRayCaster

    tree = EmbreeRayCaster(scene, bvh=True)
    assert tree._bvh is not None
    expect = _exact(tree, scene, a, b)
    np.testing.assert_array_equal(NumpyRayCaster(scene).occluded(a, b), expect)
    np.testing.assert_array_equal(tree.occluded(a, b), expect)
    np.testing.assert_array_equal(tree.occluded(b, a), expect)
    return expect


@needs_numba
@pytest.mark.parametrize("name", ["street_canyon", "touching_blocks"])
def test_nearly_coplanar_segments_get_the_same_verdict_from_the_tree_and_the_rule(name, rng):
    """Segments crossing a face at a grazing angle next to one of its edges (ends 1.5 to 1e7
    plane tolerances off the plane, on opposite sides), in a rotated scene: the crossing point
    moves by far more than rounding with one ulp of the ends' plane distances, so the rule's
    sums must be added in the kernels' order (``np.einsum`` added them in another: 75-100
    verdicts of 60,000 differed)."""
    from wavepaths.scene import transformed

    scene = transformed(load_scene(name), _rotation(), np.zeros(3))
    ex = EmbreeRayCaster(scene, bvh=True)._exact
    n = 20000
    T = scene.vertices[scene.triangles]
    f = rng.integers(0, len(T), n)
    e = rng.integers(0, 3, n)
    p = T[f, e] + rng.uniform(size=n)[:, None] * (T[f, (e + 1) % 3] - T[f, e])
    p += ex.inward[f, e] * (rng.normal(size=n) * 10.0 ** rng.uniform(-9, -3, n))[:, None]
    nrm = ex.normal[f]
    v = rng.normal(size=(n, 3))
    v -= np.einsum("ij,ij->i", v, nrm)[:, None] * nrm
    v *= (rng.uniform(2, 40, n) / np.linalg.norm(v, axis=1))[:, None]
    off = (ex.tol[f] * 10.0 ** rng.uniform(0.2, 7, n))[:, None] * nrm
    expect = _all_agree(scene, p + v + off, p - v - off)
    assert 0.5 < expect.mean() < 1.0


@needs_numba
@pytest.mark.parametrize("name,far", [("street_canyon", 1e7), ("touching_blocks", 1e6)])
def test_segments_with_an_end_far_away_meet_the_boxes_of_the_triangles_they_cross(name, far, rng):
    """Segments from up to 1e7 m away through a point exactly on a triangle's edge: the slab
    tests' rounding grows with the far end's coordinates, past the boxes' padding (274 of
    20,000 leaked through touching_blocks' shared edges before the boxes were grown with it)."""
    scene = load_scene(name)
    T = scene.vertices[scene.triangles]
    n = 20000
    t = rng.integers(0, len(T), n)
    e = rng.integers(0, 3, n)
    p = T[t, e] + rng.uniform(size=n)[:, None] * (T[t, (e + 1) % 3] - T[t, e])
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    expect = _all_agree(scene, p + far * d, p - 50.0 * d)
    assert expect.mean() > 0.9


@needs_numba
def test_a_crossing_just_beyond_an_acute_corner_is_decided_alike_by_every_index():
    """A 100 m x 1 m wall (corners of 0.01 rad): crossings 5 to 150 edge tolerances beyond its
    end along the thin triangle's bisector. The three edge conditions alone accept points up
    to 200 edge tolerances out there, beyond the padded boxes the indexes find triangles by:
    the crossing point must also lie in the triangle's box grown by the edge tolerance, so
    that the rule against every triangle, the grid and the tree agree (they did not, either
    way: an oblique segment, and a perpendicular one with the wall in a leaf with a ground)."""
    from wavepaths.em.materials import PEC
    from wavepaths.scene import build_scene

    def scene_of(verts, tris):
        tris = np.asarray(tris)
        return build_scene(np.asarray(verts, float), tris, np.zeros(len(tris), int), np.zeros(len(tris), int), ["w"],
                           [PEC], source="test")

    wall = [[0, 0, 0], [100, 0, 0], [100, 0, 1], [0, 0, 1]]
    ground = [[-10, -10, -1], [110, -10, -1], [110, 10, -1], [-10, 10, -1]]
    for verts, tris, d in ((wall, [[0, 1, 2], [0, 2, 3]], np.array([0.6, 1.0, 0.3])),
                           (wall + ground, [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]], np.array([0.0, 1.0, 0.0]))):
        scene = scene_of(verts, tris)
        tol = EmbreeRayCaster(scene, bvh=True)._exact.edge_tol
        bis = np.array([1.0, 0.0, 0.005]) / np.linalg.norm([1.0, 0.0, 0.005])
        x = -np.array([5, 20, 50, 100, 150])[:, None] * tol * bis
        _all_agree(scene, x + d, x - d)
        # and the wall's own corner region, inside the box: still blocked
        y = np.array([[1e-3, 0.0, 1e-6], [50.0, 0.0, 0.5]])
        assert _all_agree(scene, y + d, y - d).all()


@needs_numba
def test_ends_whose_difference_overflows_are_left_to_the_rule():
    """Finite ends 2e308 apart (``b - a`` overflows): the tree leaves them to the numpy rule
    (which finds no crossing point, NaN), and a blocked one before does not carry over."""
    from wavepaths.em.materials import PEC
    from wavepaths.scene import build_scene

    scene = build_scene(np.array([[0, -1, -1], [0, 1, -1], [0, 1, 1], [0, -1, 1]], float), np.array([[0, 1, 2], [0, 2, 3]]),
                        np.zeros(2, int), np.zeros(2, int), ["w"], [PEC], source="test")
    a = np.array([[-1.0, 0.3, 0.2], [-1e308, 0.3, 0.2], [-1.7e308, 5.0, 5.0]])
    b = np.array([[1.0, 0.3, 0.2], [1e308, 0.3, 0.2], [1.7e308, 5.0, 5.0]])
    tree = EmbreeRayCaster(scene, bvh=True)
    with np.errstate(all="ignore"):
        expect = _exact(tree, scene, a, b)
        np.testing.assert_array_equal(expect, [True, False, False])
        np.testing.assert_array_equal(tree.occluded(a, b), expect)
        np.testing.assert_array_equal(tree.occluded(b, a), expect)
