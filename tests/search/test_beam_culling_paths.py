"""The transmitter-side beam culling (reflections per tile, diffraction sources) changes no path."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths import TraceOptions, trace
from wavepaths.scene import load_scene
from wavepaths.search.apertures import chain_beams_meet, scene_apertures
from wavepaths.search.beams import chains_meeting_edges, edge_tree
from wavepaths.search.context import build_tx_context

from .helpers import path_keys
from .test_completeness import free_point, random_scene


def scenes():
    rng = np.random.default_rng(77)
    out = []
    for _ in range(3):
        scene = random_scene(rng)
        tx = free_point(rng, scene)[None]
        rx = np.array([free_point(rng, scene) for _ in range(12)])
        out.append((scene, tx, rx))
    scene = load_scene("street_canyon")
    rx = np.column_stack([rng.uniform(-95, 95, 20), rng.uniform(-9, 9, 20), np.full(20, 1.5)])
    out.append((scene, np.array([[-60.0, 0.0, 10.0]]), rx))
    return out


@pytest.mark.parametrize("case", range(4))
def test_beam_culling_finds_the_same_paths(case):
    scene, tx, rx = scenes()[case]
    opts = TraceOptions(max_reflections=2, diffraction=True, diffraction_reflections=2, rx_batch=5)
    on = trace(scene, tx, rx, opts)
    off = trace(scene, tx, rx, opts.with_(disable_culling={"reflection_beam", "source_beam"}))
    assert len(on) > 0
    assert path_keys(on) == path_keys(off)
    assert on.stats.get("reflection_order_2_culled_beam", 0) > 0
    assert on.stats.get("diffraction_sources_order_1_culled_beam", 0) > 0
    assert off.stats.get("reflection_order_2_culled_beam", 0) == 0
    assert off.stats.get("diffraction_sources_order_1_culled_beam", 0) == 0
    # the culled source pairs are a subset of the unculled ones, in the same sorted layout
    a = build_tx_context(scene, tx, opts)
    b = build_tx_context(scene, tx, opts.with_(disable_culling={"source_beam"}))
    for sa, sb in zip(a.diffraction_sources, b.diffraction_sources):
        pa = set(zip(sa.chain.tolist(), sa.dihedron.tolist()))
        assert pa <= set(zip(sb.chain.tolist(), sb.dihedron.tolist()))
        assert np.all(np.diff(sa.key) >= 0)


def test_edge_query_returns_only_pairs_passing_the_segment_test():
    rng = np.random.default_rng(5)
    scene = random_scene(rng)
    tx = free_point(rng, scene)[None]
    ctx = build_tx_context(scene, tx, TraceOptions(max_reflections=2, diffraction=True, diffraction_reflections=2))
    diffracting = ctx.diffracting
    tree = edge_tree(scene, diffracting)
    ap = scene_apertures(scene)
    dih = scene.dihedra
    for k in (1, 2):
        lv = ctx.levels[k]
        got = set()
        for c, e in chains_meeting_edges(scene, lv, ap, tree, chunk=7, budget=11):
            pairs = set(zip(c.tolist(), e.tolist()))
            assert not (pairs & got)
            got |= pairs
        c = np.repeat(np.arange(len(lv)), len(diffracting))
        e = np.tile(diffracting, len(lv))
        a = dih.origin[e]
        ok = chain_beams_meet(scene, lv, c, ap.quads, a, end=a + dih.length[e][:, None] * dih.direction[e])
        exact = set(zip(c[ok].tolist(), e[ok].tolist()))
        assert got <= exact
        assert 0 < len(got) < len(c)
