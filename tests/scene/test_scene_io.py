"""Loading and writing scenes, bad input, the console script, ray casting."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from wavepaths.errors import SceneError
from wavepaths.raycast.embree import EmbreeRayCaster
from wavepaths.raycast.numpy_caster import NumpyRayCaster
from wavepaths.scene import WavepathsWarning, build_scene, load_scene, transformed, write_mitsuba_xml
from wavepaths.em.materials import PEC


def wavepaths_exe():
    exe = shutil.which("wavepaths") or os.path.join(os.path.dirname(sys.executable), "wavepaths")
    assert os.path.exists(exe), "the console script is not installed next to this Python"
    return exe


@pytest.mark.parametrize("name", ["street_canyon", "slit_shutter", "box_on_ground", "three_face_edge"])
def test_mitsuba_round_trip_keeps_geometry_and_materials(tmp_path, name):
    s = load_scene(name)
    files = write_mitsuba_xml(s, str(tmp_path / "scene.xml"))
    assert all(os.path.exists(f) for f in files)
    r = load_scene(str(tmp_path / "scene.xml"))
    assert r.num_triangles == s.num_triangles
    assert r.summary()["dihedra"] == s.summary()["dihedra"]
    assert r.summary()["dihedra_by_face_count"] == s.summary()["dihedra_by_face_count"]
    np.testing.assert_allclose(r.bounds, s.bounds, atol=1e-5)  # PLY stores float32
    names = {m.name for m in s.materials} - {"pec"}
    assert names <= {m.name for m in r.materials} | {"metal"}


def test_writing_over_a_scene_removes_its_meshes_that_the_new_scene_does_not_use(tmp_path):
    """A folder written twice holds the second scene's meshes only: the street canyon (many
    objects) then the half-plane (one) leaves one PLY in meshes/, and the XML reads back as
    the half-plane. Files the old XML did not name (a user's own, another XML's) stay."""
    xml = str(tmp_path / "scene.xml")
    first = write_mitsuba_xml(load_scene("street_canyon"), xml)
    mesh_dir = tmp_path / "meshes"
    shutil.copy(first[1], mesh_dir / "mine.ply")
    other = write_mitsuba_xml(load_scene("box_on_ground"), str(tmp_path / "other.xml"), mesh_dir="others")
    second = write_mitsuba_xml(load_scene("half_plane"), xml)
    left = sorted(p.name for p in mesh_dir.iterdir())
    assert left == sorted([os.path.basename(f) for f in second[1:]] + ["mine.ply"])
    assert len(first) > len(second) and all(os.path.exists(f) for f in other)
    again = load_scene(xml)
    assert again.num_triangles == load_scene("half_plane").num_triangles
    # a file at that path that is no scene leaves the folder alone
    (tmp_path / "notes.xml").write_text("<notes><shape><string name='filename' value='meshes/mine.ply'/></shape></notes>")
    write_mitsuba_xml(load_scene("half_plane"), str(tmp_path / "notes.xml"))
    assert (mesh_dir / "mine.ply").exists()


def test_xml_transform_and_inline_material(tmp_path):
    (tmp_path / "m").mkdir()
    with open(tmp_path / "m" / "q.obj", "w") as f:
        f.write("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n")
    xml = """<scene version="2.1.0">
      <default name="t" value="0.3"/>
      <shape type="obj" id="mesh-q">
        <string name="filename" value="m/q.obj"/>
        <transform name="to_world"><scale value="2"/><rotate x="1" angle="90"/><translate x="10" y="0" z="0"/></transform>
        <bsdf type="twosided"><bsdf type="itu-radio-material"><string name="type" value="glass"/>
          <float name="thickness" value="$t"/></bsdf></bsdf>
      </shape>
      <shape type="rectangle" id="r"><bsdf type="radio-material"><float name="relative_permittivity" value="3"/>
        <float name="conductivity" value="0.1"/><float name="thickness" value="0.2"/></bsdf></shape>
    </scene>"""
    p = tmp_path / "s.xml"
    p.write_text(xml)
    s = load_scene(str(p))
    assert s.num_triangles == 4
    q = s.vertices[np.unique(s.triangles[s.triangle_object == 0])]
    # scaled by 2, rotated +90 deg about x (y -> z), moved by 10 in x
    np.testing.assert_allclose(np.sort(q[:, 0]), [10, 10, 12, 12], atol=1e-12)
    np.testing.assert_allclose(np.sort(q[:, 2]), [0, 0, 2, 2], atol=1e-12)
    np.testing.assert_allclose(q[:, 1], 0, atol=1e-12)
    kinds = sorted(m.kind for m in s.materials)
    assert kinds == ["custom", "itu"]
    glass = [m for m in s.materials if m.kind == "itu"][0]
    assert glass.thickness_m == pytest.approx(0.3)


@pytest.mark.parametrize(
    "content, ext, message",
    [
        (None, ".obj", "no such file"),
        ("hello", ".xyz", "unknown format"),
        ("<scene><shape type='ply' id='a'><string name='filename' value='nope.ply'/></shape></scene>", ".xml", "missing mesh"),
        ("<scene><bsdf type='itu-radio-material' id='m'><string name='type' value='unobtainium'/></bsdf>"
         "<shape type='rectangle' id='a'><ref id='m'/></shape></scene>", ".xml", "unobtainium"),
        ("<scene><shape type='rectangle' id='a'><ref id='nothere'/></shape></scene>", ".xml", "unknown material"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", ".obj", "no faces"),
        ("v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", ".obj", "NaN"),
    ],
)
def test_bad_scene_files_give_one_clear_error(tmp_path, content, ext, message):
    p = tmp_path / f"bad{ext}"
    if content is not None:
        p.write_text(content)
    with pytest.raises(SceneError, match=message) as info:
        load_scene(str(p))
    assert str(p) in str(info.value)


def test_zero_area_triangles_are_dropped_with_a_counting_warning():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0]], float)
    t = np.array([[0, 1, 2], [0, 1, 3], [1, 1, 2]])
    with pytest.warns(WavepathsWarning, match="dropped 2 zero-area"):
        s = build_scene(v, t, np.zeros(3, int), np.zeros(3, int), ["o"], [PEC])
    assert s.num_triangles == 1 and s.dropped_degenerate == 2


def test_cli_info_runs_as_installed_console_script():
    r = subprocess.run([wavepaths_exe(), "info", "box_on_ground", "--json"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    for key in ("triangles", "objects", "materials", "polygons", "dihedra", "dihedra_by_face_count",
                "skipped_flat_edges", "bounds"):
        assert key in d
    assert d["dihedra_by_face_count"] == {"1": 4, "2": 8, "3+": 4}


def test_cli_bad_file_exits_2_without_traceback(tmp_path):
    r = subprocess.run([wavepaths_exe(), "info", str(tmp_path / "missing.obj")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr and "missing.obj" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def random_segments(scene, rng, k):
    lo, hi = scene.bounds
    pad = 0.2 * (hi - lo) + 1
    a = rng.uniform(lo - pad, hi + pad, size=(k, 3))
    b = rng.uniform(lo - pad, hi + pad, size=(k, 3))
    return a, b


@pytest.mark.parametrize("name", ["street_canyon", "slit_shutter", "three_face_edge"])
def test_embree_agrees_with_the_float64_numpy_caster(rng, name):
    s = load_scene(name)
    a, b = random_segments(s, rng, 4000)
    e = EmbreeRayCaster(s).occluded(a, b)
    n = NumpyRayCaster(s).occluded(a, b)
    # Embree only finds faces, float64 decides: they may disagree only where Embree misses a
    # face crossed within float32 resolution of its edge; none should here
    assert (e != n).sum() == 0, np.nonzero(e != n)
    assert 0.05 < e.mean() < 0.95  # the test is not vacuous


def test_visibility_survives_a_move_to_1e6_metres(rng):
    s = load_scene("street_canyon")
    shift = np.array([1e6, -2e6, 50.0])
    moved = transformed(s, translation=shift)
    a, b = random_segments(s, rng, 4000)
    np.testing.assert_array_equal(
        EmbreeRayCaster(s).occluded(a, b), EmbreeRayCaster(moved).occluded(a + shift, b + shift)
    )


# ---- build_scene and SceneTolerances check their arguments ---------------------------------
def test_build_scene_refuses_malformed_arrays_and_ids_out_of_range():
    """A (6, 2) ``vertices`` array was read as four points, float indices were truncated and
    ids out of range failed later in the search; each is refused now, naming the argument."""
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    t = np.array([[0, 1, 2], [0, 2, 3]])
    ok = build_scene(v, t, [0, 0], [0, 0], ["o"], [PEC])
    assert ok.num_triangles == 2
    cases = [
        ((v.reshape(6, 2), t, [0, 0], [0, 0], ["o"], [PEC]), r"`vertices` must have shape \(n, 3\), got \(6, 2\)"),
        ((v, t + 0.5, [0, 0], [0, 0], ["o"], [PEC]), "`triangles` must hold integer indices"),
        ((v, t, [0, 0], [0, 5], ["o"], [PEC]), r"`triangle_material` must index `materials` \(0..0\), got 0..5"),
        ((v, t, [0, 3], [0, 0], ["o"], [PEC]), r"`triangle_object` must index `object_names` \(0..0\), got 0..3"),
        ((v, t, [0], [0, 0], ["o"], [PEC]), r"`triangle_object` must have one entry per triangle \(2\), got 1"),
        ((v, t + 2, [0, 0], [0, 0], ["o"], [PEC]), r"`triangles` must index `vertices` \(0..3\), got 2..5"),
        ((v, t, [0, 0], [0, 0], ["o"], ["pec"]), "`materials` must be Material objects"),
    ]
    for args, message in cases:
        with pytest.raises(SceneError, match=message):
            build_scene(*args)
    assert build_scene(v, t.astype(float), [0.0, 0.0], [0, 0], ["o"], [PEC]).num_triangles == 2  # whole floats


@pytest.mark.parametrize("kwargs", [{"weld": float("nan")}, {"coplanar_angle": -1.0}, {"ray_offset": -1e-6},
                                    {"flat_angle": 4.0}, {"weld": "1e-6"}, {"plane_distance": True}])
def test_scene_tolerances_must_be_finite_and_in_range(kwargs):
    from wavepaths.errors import WavepathsError
    from wavepaths.scene import SceneTolerances

    name = next(iter(kwargs))
    with pytest.raises(WavepathsError, match=f"`{name}` must be a finite number in"):
        SceneTolerances(**kwargs)
