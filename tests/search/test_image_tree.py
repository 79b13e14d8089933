"""The image tree built with a sphere tree equals the all-pairs reference, chain for chain."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths.errors import WavepathsError
from wavepaths.scene import load_scene
from wavepaths.scene.builtin import BUILTIN_SCENES
from wavepaths.search import images, kernels
from wavepaths.search.spheres import beam_meets_spheres, build_sphere_tree, query_tree
from wavepaths.search.images import build_image_levels, build_image_levels_all_pairs

from .test_completeness import free_point, random_scene


# the builder's exact tests run as numpy expressions (False) or as one compiled loop (True,
# numba): both must keep the reference's chains
COMPILED = [False, pytest.param(True, marks=pytest.mark.skipif(not kernels.available(), reason="numba is not installed"))]


def assert_same_levels(got, ref):
    assert len(got) == len(ref)
    for k, (a, b) in enumerate(zip(got, ref)):
        assert len(a) == len(b), f"order {k}: {len(a)} chains instead of {len(b)}"
        np.testing.assert_array_equal(a.source, b.source)
        np.testing.assert_array_equal(a.polygons, b.polygons)
        np.testing.assert_array_equal(a.images, b.images)


def scene_points(scene, rng, count):
    lo, hi = scene.bounds
    pad = 0.2 * (hi - lo) + 0.5
    return rng.uniform(lo - pad, hi + pad, (count, 3))


@pytest.mark.parametrize("compiled", COMPILED)
@pytest.mark.parametrize("name", sorted(BUILTIN_SCENES))
def test_builtin_scenes_same_chains_as_all_pairs(name, compiled):
    scene = load_scene(name)
    rng = np.random.default_rng(7)
    src = scene_points(scene, rng, 5)
    for skip in (True, False):
        got = build_image_levels(scene, src, 3, skip, compiled=compiled)
        ref = build_image_levels_all_pairs(scene, src, 3, skip)
        assert_same_levels(got, ref)


@pytest.mark.parametrize("compiled", COMPILED)
@pytest.mark.parametrize("seed", range(8))
def test_random_box_scenes_same_chains_as_all_pairs(seed, compiled):
    rng = np.random.default_rng(seed)
    scene = random_scene(rng)
    src = np.array([free_point(rng, scene) for _ in range(3)])
    ref = build_image_levels_all_pairs(scene, src, 3)
    assert len(ref[3]) > 0  # not vacuous
    assert_same_levels(build_image_levels(scene, src, 3, compiled=compiled), ref)


def test_small_chunks_and_blocks_give_the_same_chains(monkeypatch):
    rng = np.random.default_rng(3)
    scene = random_scene(rng)
    src = np.array([free_point(rng, scene) for _ in range(4)])
    ref = build_image_levels(scene, src, 3)
    monkeypatch.setattr(images, "PARENT_CHUNK", 5)
    monkeypatch.setattr(images, "CANDIDATE_BLOCK", 16)
    assert_same_levels(build_image_levels(scene, src, 3), ref)


@pytest.mark.parametrize("compiled", COMPILED)
def test_closed_room_with_source_inside_same_chains(compiled):
    # a closed box: one-sided culling is on outside, off for a source inside
    from ..conftest import boxes_scene

    scene = boxes_scene([((0, 0, 0), (4, 3, 2.5))], ground=8)
    src = np.array([[2.0, 1.5, 1.2], [6.0, -5.0, 1.0]])
    assert_same_levels(build_image_levels(scene, src, 3, compiled=compiled), build_image_levels_all_pairs(scene, src, 3))


def test_tree_too_large_raises(monkeypatch):
    scene = load_scene("street_canyon")
    monkeypatch.setattr(images, "MAX_IMAGES", 3)
    with pytest.raises(WavepathsError, match="image tree of order"):
        build_image_levels(scene, np.array([[0.0, 0.0, 1.5]]), 2)


def test_sphere_tree_query_returns_every_item_passing_the_beam_test():
    rng = np.random.default_rng(11)
    n = 2000
    c = rng.uniform(-100, 100, (n, 3))
    r = rng.exponential(2.0, n)
    r[::97] *= 40  # a few large spheres
    tree = build_sphere_tree(c, r, leaf_size=5, branch=3)
    q = 60
    apex = rng.uniform(-120, 120, (q, 3))
    pc = rng.uniform(-100, 100, (q, 3))
    pr = rng.uniform(0.1, 10, q)

    def node_test(rows, level, nodes):
        cen, rad = tree.centre[level][nodes], tree.radius[level][nodes]
        return beam_meets_spheres(apex[rows], pc[rows], pr[rows], cen, rad, 1e-7)

    found = set()
    for rows, items in query_tree(tree, np.arange(q), node_test, budget=50):
        found |= set(zip(rows.tolist(), items.tolist()))
    rows, items = np.repeat(np.arange(q), n), np.tile(np.arange(n), q)
    exact = beam_meets_spheres(apex[rows], pc[rows], pr[rows], c[items], r[items])
    want = set(zip(rows[exact].tolist(), items[exact].tolist()))
    assert want <= found
    assert len(found) < 0.8 * q * n  # the tree prunes
