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
from .test_stress_properties import MIN_CHECKED, NEAR, SCENES, SETTINGS, end_points, outer_side, point_of_kind, points

pytestmark = pytest.mark.skipif(not kernels.available(), reason="numba is not installed (the `fast` extra)")

OPTS = TraceOptions(max_reflections=2, diffraction=True, diffraction_reflections=2, rx_batch=3)


TALLY = []  # per example of the path search: its receivers (of 4) with paths in the reference


@SETTINGS
@given(st.data())
def check_compiled_and_numpy_find_the_same_paths(data):
    """End points where the engine computes paths: the transmitter and a first receiver from
    end_points (free, snapped or placed for a reflection), three more receivers of any kind
    (points(outside=True)), a free one put on the outer side of the block faces that hold a
    transmitter snapped onto a block (behind them it could see it only around the block)."""
    name = data.draw(st.sampled_from(sorted(SCENES)))
    scene = SCENES[name]
    tx, first, _ = data.draw(end_points(name))
    rx = [first]
    for _ in range(3):
        kind = data.draw(st.sampled_from(NEAR))
        p = data.draw(point_of_kind(name, kind, outside=True))
        rx.append(outer_side(name, tx, p) if kind == "free" else p)
    tx, rx = tx[None, :], np.array(rx)
    assume(np.linalg.norm(rx - tx, axis=1).min() > 10 * scene.length_tolerance(scene.tolerances.weld))  # else refused
    with warnings.catch_warnings():  # points on faces are defined edge cases; trace warns of them
        warnings.simplefilter("ignore")
        fast = trace(scene, tx, rx, OPTS)
        ref = trace(scene, tx, rx, OPTS.with_(compiled=False))
    note(f"{name} tx={tx.tolist()} rx={rx.tolist()} paths={len(ref)}")
    assert path_keys(fast) == path_keys(ref)
    TALLY.append(len(np.unique(ref.rx_index)))


def test_compiled_and_numpy_find_the_same_paths():
    """The search above; an example without paths checks nothing, so most must have some."""
    TALLY.clear()
    check_compiled_and_numpy_find_the_same_paths()
    with_paths = sum(1 for n in TALLY if n)
    assert with_paths >= MIN_CHECKED * len(TALLY), (
        f"too few examples found paths: {with_paths} of {len(TALLY)}, receivers with paths {sum(TALLY)} of {4 * len(TALLY)}")


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
