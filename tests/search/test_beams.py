"""Beam culling drops only (receiver, chain) pairs that back-tracing would reject."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from wavepaths import TraceOptions
from wavepaths.scene import load_scene
from wavepaths.scene.polygon_query import points_in_polygons
from wavepaths.search import beams as beams_mod
from wavepaths.search.apertures import chain_beams_meet, polygon_quads, quad_side_planes
from wavepaths.search.beams import beams_reaching, build_chain_beams, reflection_candidates
from wavepaths.search.context import build_tx_context
from wavepaths.scene.polygon_shapes import polygon_spheres
from wavepaths.search.images import backtrace

from .test_completeness import free_point, random_scene


def test_polygon_quads_contain_the_points_of_their_polygons():
    rng = np.random.default_rng(5)
    for scene in (load_scene("street_canyon"), load_scene("three_face_edge"), random_scene(rng)):
        quads = polygon_quads(scene)
        p = scene.num_polygons
        # random points in random triangles, tested against the rectangle's beam from an apex off the plane
        tri = rng.integers(len(scene.triangles), size=4000)
        w = rng.dirichlet(np.ones(3), size=len(tri))
        pts = np.einsum("ij,ijk->ik", w, scene.vertices[scene.triangles[tri]])
        poly = scene.triangle_polygon[tri]
        assert points_in_polygons(scene, pts, poly).all()
        n = scene.polygon_normal[poly]
        apex = pts + rng.uniform(0.5, 20, len(tri))[:, None] * rng.choice([-1, 1], len(tri))[:, None] * n
        apex += rng.normal(0, 3, apex.shape)  # anywhere, as long as off the plane
        off = np.abs(np.einsum("ij,ij->i", apex, n) - scene.polygon_offset[poly]) > 1e-3
        planes = quad_side_planes(apex[off], quads[poly[off]])
        ahead = pts[off] + rng.uniform(0, 5, off.sum())[:, None] * (pts[off] - apex[off])
        assert (np.einsum("ikj,ij->ik", planes, ahead - apex[off]) >= -1e-9).all()
        assert p == len(quads)


def all_pairs_valid(scene, lv, rx):
    """(rx row, chain) pairs that back-tracing accepts, all pairs tested."""
    ri = np.repeat(np.arange(len(rx)), len(lv))
    ci = np.tile(np.arange(len(lv)), len(rx))
    ok, _, _ = backtrace(scene, rx[ri], lv, ci)
    return set(zip(ri[ok].tolist(), ci[ok].tolist())), len(ri)


@pytest.mark.parametrize("seed", range(6))
def test_chain_beams_keep_every_pair_that_back_traces(seed):
    rng = np.random.default_rng(100 + seed)
    scene = random_scene(rng)
    tx = free_point(rng, scene)
    ctx = build_tx_context(scene, tx, TraceOptions(max_reflections=3, diffraction=False))
    rx = np.array([free_point(rng, scene) for _ in range(40)])
    for k in (1, 2, 3):
        lv = ctx.levels[k]
        valid, total = all_pairs_valid(scene, lv, rx)
        # point test on every pair
        ri = np.repeat(np.arange(len(rx)), len(lv))
        ci = np.tile(np.arange(len(lv)), len(rx))
        keep = chain_beams_meet(scene, lv, ci, ctx.apertures.quads, rx[ri])
        assert valid <= set(zip(ri[keep].tolist(), ci[keep].tolist()))
        # the same test with each chain's planes computed once for all its targets
        owner = np.repeat(np.arange(len(lv)), len(rx))
        shared = chain_beams_meet(scene, lv, np.arange(len(lv)), ctx.apertures.quads,
                                  rx[np.tile(np.arange(len(rx)), len(lv))], owner=owner)
        np.testing.assert_array_equal(shared.reshape(len(lv), len(rx)).T, keep.reshape(len(rx), len(lv)))
        # the tree query with clusters, then points
        stats = Counter()
        got = set()
        for r, c in reflection_candidates(scene, ctx, k, rx, stats, 1000):
            pairs = list(zip(r.tolist(), c.tolist()))
            assert not (got & set(pairs)) and len(set(pairs)) == len(pairs)  # each pair once
            got |= set(pairs)
        assert valid <= got
        assert stats[f"reflection_order_{k}_culled_beam"] == total - len(got)
        if k >= 2:
            assert len(got) < 0.7 * total  # the culling does something


def test_beam_tree_query_keeps_only_exact_passes_and_every_back_traced_pair():
    rng = np.random.default_rng(42)
    scene = random_scene(rng)
    tx = free_point(rng, scene)
    ctx = build_tx_context(scene, tx, TraceOptions(max_reflections=2, diffraction=False))
    lv = ctx.levels[2]
    centre, radius = polygon_spheres(scene)
    tree = build_chain_beams(scene, lv, centre, radius)
    tc = rng.uniform(-12, 12, (30, 3))
    tc[:, 2] = np.abs(tc[:, 2])
    tr = rng.uniform(0, 3, 30)
    got = set()
    for r, c in beams_reaching(scene, lv, tree, ctx.apertures, tc, tr, budget=7):
        got |= set(zip(r.tolist(), c.tolist()))
    r = np.repeat(np.arange(30), len(lv))
    c = np.tile(np.arange(len(lv)), 30)
    # pairs with a real leg pass both the node test and the exact test; the node test only drops pairs that
    # no ray reaches, so the query returns the pairs passing the exact test whose sphere caps also overlap
    exact = chain_beams_meet(scene, lv, c, ctx.apertures.quads, tc[r], tr[r])
    assert got <= set(zip(r[exact].tolist(), c[exact].tolist()))
    # and for points (radius 0) every pair with a back-traced path is among them
    pts = np.array([free_point(rng, scene) for _ in range(30)])
    got = set()
    for r2, c2 in beams_reaching(scene, lv, tree, ctx.apertures, pts, np.zeros(30), budget=5):
        got |= set(zip(r2.tolist(), c2.tolist()))
    valid, _ = all_pairs_valid(scene, lv, pts)
    assert valid <= got


def test_tiny_clusters_and_blocks(monkeypatch):
    rng = np.random.default_rng(9)
    scene = random_scene(rng)
    tx = free_point(rng, scene)
    ctx = build_tx_context(scene, tx, TraceOptions(max_reflections=2, diffraction=False))
    rx = np.array([free_point(rng, scene) for _ in range(25)])
    monkeypatch.setattr(beams_mod, "RX_CLUSTER", 3)
    got = set()
    for r, c in reflection_candidates(scene, ctx, 2, rx, Counter(), 10):
        got |= set(zip(r.tolist(), c.tolist()))
    valid, _ = all_pairs_valid(scene, ctx.levels[2], rx)
    assert valid <= got


def test_point_clusters_cover_every_point_once_and_respect_the_radius_limit():
    rng = np.random.default_rng(11)
    # a dense patch (clusters of 8 fit under the limit) and scattered points (they do not)
    pts = np.concatenate([rng.uniform(0, 3, (64, 3)), rng.uniform(-500, 500, (40, 3))])
    members, start, centre, radius = beams_mod.point_clusters(pts, 8, max_radius=5.0)
    assert sorted(members.tolist()) == list(range(len(pts)))
    sizes = np.diff(start)
    assert sizes.max() <= 8 and sizes.min() >= 1
    for i in range(len(sizes)):
        p = pts[members[start[i]:start[i + 1]]]
        assert np.all(np.linalg.norm(p - centre[i], axis=1) <= radius[i])
        assert radius[i] <= 5.0 or sizes[i] == 1
    assert (sizes == 8).sum() >= 6  # the dense patch stays in full clusters
    unlimited = beams_mod.point_clusters(pts, 8)
    assert np.all(np.diff(unlimited[1])[:-1] == 8)
