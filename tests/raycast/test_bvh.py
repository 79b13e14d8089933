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
                         edge_tol=1e-12)
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
