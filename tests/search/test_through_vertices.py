"""Paths crossing a face's boundary at a reflection point (search/through_vertices.py).

A review's street-canyon queries (twenty-eighth session): ground reflections exactly on a
building's foot line carried paths into and out of the closed building, since each leg only
touches the wall at its end, which the casters' rule lets pass."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from wavepaths import TraceOptions, load_scene, trace
from wavepaths.search.paths import InteractionType

OPTS = TraceOptions(max_reflections=2, diffraction=True, diffraction_reflections=1)


def _trace(scene, tx, rx):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # an end inside a closed building is reported
        return trace(scene, np.array([tx], float), np.array(rx, float), OPTS)


def test_no_path_leaves_a_closed_building_through_a_walls_foot_line():
    # the transmitter inside building_north_1 (x in [-45, -25], y in [10, 30]); the R-R
    # path's ground point (-45, 10.3077, 0) lay on the west wall's foot line; 0.1 mm away
    # the receiver had no path
    scene = load_scene("street_canyon")
    p = _trace(scene, [-20, 17, 5], [[-52.5, 3.5, 1.5], [-52.5, 3.5001, 1.5001]])
    assert len(p) == 0
    assert p.stats["paths_dropped_through_a_face"] == 1


def test_no_path_enters_a_closed_building_through_a_walls_foot_line():
    scene = load_scene("street_canyon")
    p = _trace(scene, [-60, 0, 10], [[-61.5, 14.5, 1.5]])  # the receiver inside building_north_0
    assert len(p) == 0
    assert p.stats["paths_dropped_through_a_face"] == 1


def test_a_reflection_on_a_buildings_corner_edge_with_both_legs_outside_is_kept():
    # a box x in [10, 12], y in [-5, 5]: the reflection on its x = 10 face at (10, 5, 1) lies
    # on the corner edge it shares with the y = 5 face; the legs lie on either side of that
    # face's plane but outside the box (x < 10), where the face is not: a path, the limit of
    # the wall's reflections
    from ..conftest import boxes_scene

    scene = boxes_scene([((10, -5, 0), (12, 5, 3))])
    p = trace(scene, np.array([[0.0, 3.0, 1.0]]), np.array([[0.0, 7.0, 1.0]]), TraceOptions(max_reflections=1))
    refl = np.nonzero(p.interactions[:, 0] == InteractionType.REFLECTION)[0]
    assert len(refl) == 1
    assert np.allclose(p.vertices[refl[0], 1], [10.0, 5.0, 1.0], atol=1e-9)
    assert p.stats.get("paths_dropped_through_a_face", 0) == 0
    # the same query with the wall's reflection point 1 mm inside the face: the same paths
    q = trace(scene, np.array([[0.0, 3.0, 1.0]]), np.array([[0.0, 6.998, 1.0]]), TraceOptions(max_reflections=1))
    assert sorted(q.interactions[:, 0].tolist()) == sorted(p.interactions[:, 0].tolist())


def test_the_compiled_chords_are_the_numpy_ones():
    pytest.importorskip("numba")
    from wavepaths.search._numba_chords import reflection_chords
    from wavepaths.search.through_vertices import CHORD, HEIGHT, reflection_chords_numpy

    scene = load_scene("street_canyon")
    rx = np.array([[x, y, 1.5] for x in np.linspace(-80, 80, 9) for y in np.linspace(-8, 8, 5)])
    p = _trace(scene, [-60, 0, 10], rx)
    args = (np.ascontiguousarray(p.vertices), np.ascontiguousarray(p.interactions), np.ascontiguousarray(p.primitive),
            scene.polygon_normal, CHORD * scene.diagonal, HEIGHT * scene.diagonal)
    A, B, row = reflection_chords(*args)
    A0, B0, row0 = reflection_chords_numpy(*args)
    assert len(row) > 100 and np.array_equal(row, row0)
    assert np.allclose(A, A0, rtol=0, atol=1e-12) and np.allclose(B, B0, rtol=0, atol=1e-12)


def test_the_numpy_reference_drops_the_same_paths():
    from wavepaths.search.through_vertices import crossed_at_reflections

    scene = load_scene("street_canyon")
    opts = TraceOptions(max_reflections=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        p = trace(scene, np.array([[-20.0, 17.0, 5.0]]), np.array([[-52.5, 3.5, 1.5], [-52.5, 3.5001, 1.5001]]),
                  opts.with_(compiled=False))
    assert p.stats["paths_dropped_through_a_face"] == 1
    q = _trace(scene, [-60, 0, 10], [[x, 0.5, 1.5] for x in np.linspace(-80, 80, 17)])
    assert np.array_equal(crossed_at_reflections(scene, q, compiled=False), crossed_at_reflections(scene, q))
