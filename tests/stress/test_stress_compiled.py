"""Property-based tests (Hypothesis): the compiled kernels find exactly the paths of the numpy
reference, with transmitters and receivers anywhere, on vertices, edges and faces or 1e-9 m
off them (the defined edge cases), where the culling margins are tightest."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import assume, given, note
from hypothesis import strategies as st

from wavepaths.search import TraceOptions, kernels, trace

from ..search.helpers import path_keys
from .test_stress_properties import SCENES, SETTINGS, points

pytestmark = pytest.mark.skipif(not kernels.available(), reason="numba is not installed (the `fast` extra)")

OPTS = TraceOptions(max_reflections=2, diffraction=True, diffraction_reflections=2, rx_batch=3)


@SETTINGS
@given(st.data())
def test_compiled_and_numpy_find_the_same_paths(data):
    name = data.draw(st.sampled_from(sorted(SCENES)))
    scene = SCENES[name]
    tx = data.draw(points(name))[None, :]
    rx = np.array([data.draw(points(name)) for _ in range(4)])
    assume(np.linalg.norm(rx - tx, axis=1).min() > 1e-6)
    with warnings.catch_warnings():  # points on faces are defined edge cases; trace warns of them
        warnings.simplefilter("ignore")
        fast = trace(scene, tx, rx, OPTS)
        ref = trace(scene, tx, rx, OPTS.with_(compiled=False))
    note(f"{name} tx={tx.tolist()} rx={rx.tolist()} paths={len(ref)}")
    assert path_keys(fast) == path_keys(ref)


@SETTINGS
@given(st.data())
def test_compiled_and_numpy_occlusion_decide_alike(data):
    """The Embree caster with its compiled set-up and confirmation, and with the numpy
    reference: the same verdict, both directions, for segments between points on vertices,
    edges and faces or 1e-9 m off them (where the float64 confirmation decides). The float64
    tree (the compiled default on these small scenes) gives the exact rule's verdict itself:
    the float64 test against every triangle."""
    from wavepaths.raycast import canonical
    from wavepaths.raycast.embree import EmbreeRayCaster

    name = data.draw(st.sampled_from(sorted(SCENES)))
    scene = SCENES[name]
    a = np.array([data.draw(points(name)) for _ in range(6)])
    b = np.array([data.draw(points(name)) for _ in range(6)])
    ref, fast = EmbreeRayCaster(scene, compiled=False), EmbreeRayCaster(scene, compiled=True, bvh=False)
    tree = scene.raycaster
    assert tree._bvh is not None
    note(f"{name} a={a.tolist()} b={b.tolist()}")
    for x, y in ((a, b), (b, a)):
        np.testing.assert_array_equal(fast.occluded(x, y), ref.occluded(x, y))
        A, B, _ = canonical(x - scene.center, y - scene.center)
        np.testing.assert_array_equal(tree.occluded(x, y), tree._exact.blocked(A, B, index=False))
