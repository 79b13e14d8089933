"""Every Sionna RT built-in scene loads, with the triangle count of its meshes.

The scenes ship inside the sionna-rt package (sionna/rt/scenes/<name>/<name>.xml); they
are found without importing Sionna (no Dr.Jit needed) and skipped only when the package is
not installed.
"""

from __future__ import annotations

import glob
import importlib.util
import os
import warnings

import numpy as np
import pytest
import trimesh

from wavepaths.scene import WavepathsWarning, load_scene
from wavepaths.scene.mitsuba import iter_shape_files


def _scene_files():
    spec = importlib.util.find_spec("sionna")
    if spec is None or spec.origin is None:
        return []
    root = os.path.join(os.path.dirname(spec.origin), "rt", "scenes")
    return sorted(glob.glob(os.path.join(root, "*", "*.xml")))


SCENES = _scene_files()


@pytest.mark.skipif(not SCENES, reason="sionna-rt is not installed (pip install 'wavepaths[sionna]')")
@pytest.mark.parametrize("xml", SCENES, ids=[os.path.basename(p)[:-4] for p in SCENES])
def test_sionna_builtin_scene_loads_with_all_its_triangles(xml):
    faces = 0
    for rel in iter_shape_files(xml):
        mesh = trimesh.load(os.path.join(os.path.dirname(xml), rel), force="mesh", process=False)
        faces += len(mesh.faces)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", WavepathsWarning)  # a few city meshes carry zero-area slivers
        scene = load_scene(xml)
    assert scene.num_triangles + scene.dropped_degenerate == faces
    assert scene.num_polygons > 0 and np.isfinite(scene.bounds).all()
    assert len(scene.object_names) == len(list(iter_shape_files(xml)))


@pytest.mark.skipif(not SCENES, reason="sionna-rt is not installed (pip install 'wavepaths[sionna]')")
def test_sionna_scenes_load_by_name():
    """`load_scene("simple_street_canyon")` (and `wavepaths info simple_street_canyon`) is that
    scene's XML file, found without importing Sionna; an unknown name still says what exists."""
    from wavepaths.errors import SceneError
    from wavepaths.scene.loaders import sionna_scene_file

    xml = [p for p in SCENES if os.path.basename(p) == "simple_street_canyon.xml"][0]
    assert sionna_scene_file("simple_street_canyon") == xml
    by_name, by_file = load_scene("simple_street_canyon"), load_scene(xml)
    assert by_name.source == xml
    assert np.array_equal(by_name.vertices[by_name.triangles], by_file.vertices[by_file.triangles])
    assert sionna_scene_file("../simple_street_canyon") is None
    with pytest.raises(SceneError, match="Sionna RT's scenes"):
        load_scene("no_such_scene")
