"""`TraceOptions(free_edges=False)`: no diffraction on edges of one face, nothing else changed."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths import TraceOptions, load_scene, trace

DIFFRACTION = 2


def keys(paths) -> set:
    """(tx, rx, ((kind, primitive), ...)) of each path, without the padding of shorter paths."""
    return {(int(paths.tx_index[i]), int(paths.rx_index[i]),
             tuple((int(k), int(p)) for k, p in zip(paths.interactions[i], paths.primitive[i]) if k != 0))
            for i in range(len(paths))}


def on_free_edge(scene, key) -> bool:
    return any(k == DIFFRACTION and scene.dihedra.face_count[p] == 1 for k, p in key[2])


@pytest.mark.parametrize("name, candidates", [("three_face_edge", "exhaustive"), ("street_canyon", "exhaustive"),
                                              ("street_canyon", "launched")])
def test_free_edges_off_drops_exactly_the_paths_diffracted_on_them(name, candidates):
    scene = load_scene(name)
    rng = np.random.default_rng(3)
    lo, hi = scene.bounds
    rx = rng.uniform(lo, hi, (40, 3))
    rx[:, 2] = rng.uniform(0.5, 3.0, 40) if name == "street_canyon" else rx[:, 2] + 0.37
    tx = np.array([[-60.0, 0.3, 10.0]]) if name == "street_canyon" else np.array([[7.3, 1.1, 6.2]])
    opts = dict(max_reflections=1, diffraction_reflections=1, diffraction_candidates=candidates)
    from wavepaths.coverage import inside_solid_objects, solid_objects

    rx = rx[~inside_solid_objects(scene, rx, solid_objects(scene))]
    every = trace(scene, tx, rx, TraceOptions(**opts))
    fixed = trace(scene, tx, rx, TraceOptions(**opts, free_edges=False))
    free = {k for k in keys(every) if on_free_edge(scene, k)}
    assert free  # the scene has free edges that diffract
    assert keys(fixed) == keys(every) - free
    assert fixed.stats["dihedra_skipped_free_edges"] == int((scene.dihedra.face_count[scene.dihedra.diffracting] == 1).sum())
