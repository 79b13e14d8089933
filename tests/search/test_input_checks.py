"""Bad inputs to the public API and the command line give a WavepathsError or exit 2 with a
message, never a raw TypeError or ValueError from deep inside."""

from __future__ import annotations

import subprocess
import sys

import pytest

import wavepaths as wp
from wavepaths import TraceOptions, WavepathsError
from wavepaths.fields import FieldConfig


@pytest.mark.parametrize("kwargs", [{"max_reflections": 2.5}, {"diffraction_reflections": "1"},
                                    {"max_reflections": True}])
def test_integer_options_must_be_integers(kwargs):
    with pytest.raises(WavepathsError, match="must be an integer"):
        TraceOptions(**kwargs)


def test_frequency_must_be_a_number():
    with pytest.raises(WavepathsError, match="must be a number"):
        FieldConfig(frequency_hz="3.5e9")


def test_positions_must_be_numbers():
    with pytest.raises(WavepathsError, match="`tx` must be numbers"):
        wp.trace(wp.load_scene("street_canyon"), [["a", 0, 10]], [[0, 0, 1.5]])


def test_python_dash_m_runs_the_command_line():
    r = subprocess.run([sys.executable, "-m", "wavepaths", "info", "street_canyon", "--json"], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert '"triangles": 98' in r.stdout


# ---- results built for one scene, transmitter or option set, given with another ------------
def test_a_context_for_other_transmitters_options_or_scene_is_refused():
    """A review traced 76 paths from a context built for another transmitter (78 exist, the
    shortest 22.30 m, not 80.45 m), with no error. The context must match; the matching one
    gives the paths of a trace without it."""
    import numpy as np

    from wavepaths.search.context import build_tx_context

    scene = wp.load_scene("street_canyon")
    rx = np.array([[20.0, 3.0, 1.5], [0.0, -5.0, 1.5], [50.0, 8.0, 1.5]])
    one = TraceOptions(max_reflections=1)
    ctx = build_tx_context(scene, np.array([[-60.0, 0.0, 10.0]]), one)
    with pytest.raises(WavepathsError, match=r"`context` was built for the transmitters \[\[-60.0, 0.0, 10.0\]\]"):
        wp.trace(scene, [[40, 5, 10]], rx, one, context=ctx)
    with pytest.raises(WavepathsError, match=r"other options \(they differ in \['max_reflections'\]\)"):
        wp.trace(scene, [[-60, 0, 10]], rx, TraceOptions(max_reflections=2), context=ctx)
    from wavepaths.scene import SceneTolerances, with_materials

    for other in (wp.load_scene("street_canyon", tolerances=SceneTolerances(weld=2e-6)),  # the same triangles
                  with_materials(scene, {"concrete": "absorber"})):  # absorbers reflect nothing: no images
        with pytest.raises(WavepathsError, match="another scene"):
            wp.trace(other, [[-60, 0, 10]], rx, one, context=ctx)
    with pytest.raises(WavepathsError, match="`context` must be a TxContext"):
        wp.trace(scene, [[-60, 0, 10]], rx, one, context={"tx": [[-60, 0, 10]]})
    given, own = wp.trace(scene, [[-60, 0, 10]], rx, one, context=ctx), wp.trace(scene, [[-60, 0, 10]], rx, one)
    assert len(given) == len(own) > 10
    np.testing.assert_array_equal(given.vertices, own.vertices)


def test_fields_of_paths_from_another_scene_or_of_wrong_types_are_refused():
    """Paths traced on the half-plane, computed with the street canyon, gave a gain 0.7 dB off
    with no error; wrong types gave AttributeError. Both now name what is wrong."""
    from wavepaths.fields import compute_fields

    half = wp.load_scene("half_plane")
    paths = wp.trace(half, [[-10, 5, -5]], [[10, -5, -5]])
    assert len(paths) and paths.scene_fingerprint == half.geometry_fingerprint
    with pytest.raises(WavepathsError, match="traced in another scene"):
        compute_fields(wp.load_scene("street_canyon"), paths)
    for args, name in (((half, paths, {"frequency_hz": 1e9}), "config"), (("half_plane", paths), "scene"),
                       ((half, [1, 2]), "paths")):
        with pytest.raises(WavepathsError, match=f"`{name}` must be a"):
            compute_fields(*args)
    assert compute_fields(half, paths).a.shape[0] == len(paths)
    # other materials on the same geometry are the same scene for the fields (a material sweep)
    from wavepaths.scene import with_materials

    metal = with_materials(half, {half.materials[0].name: "metal"})
    assert metal.fingerprint != half.fingerprint and metal.geometry_fingerprint == half.geometry_fingerprint
    assert compute_fields(metal, paths).a.shape[0] == len(paths)
    # the fingerprint follows the paths through select(); a selection is still refused elsewhere
    sub = paths.select(paths.depth >= 0)
    with pytest.raises(WavepathsError, match="traced in another scene"):
        compute_fields(wp.load_scene("box_on_ground"), sub)
