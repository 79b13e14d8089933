"""Mitsuba XML scenes: what Mitsuba 3 / Sionna RT 2.2 read, wavepaths reads the same way.

Regression tests of the review of the XML loader and writer: <include>, Sionna's legacy
material ids, absorbers, `$name` parameters inside values, malformed numbers, rotation
axes, meshes without faces, duplicate names and unsafe names on export.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import trimesh

from wavepaths.em.materials import ABSORBER, Material, itu_material
from wavepaths.errors import SceneError
from wavepaths.scene import WavepathsWarning, build_scene, load_scene, write_mitsuba_xml

CONCRETE = '<bsdf type="itu-radio-material" id="m"><string name="type" value="concrete"/></bsdf>'


def write_triangle_ply(path):
    mesh = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], process=False)
    mesh.export(str(path), file_type="ply", encoding="binary")


def scene_file(tmp_path, body, name="s.xml"):
    write_triangle_ply(tmp_path / "t.ply")
    p = tmp_path / name
    p.write_text(f'<scene version="2.1.0">\n{body}\n</scene>\n')
    return str(p)


def ply_shape(ident, extra="", ref="m"):
    return f'<shape type="ply" id="{ident}"><string name="filename" value="t.ply"/>{extra}<ref id="{ref}"/></shape>'


# --- 1. <include> and unknown elements ---------------------------------------------------


def test_include_adds_the_included_shapes_relative_to_the_including_file(tmp_path):
    sub = tmp_path / "parts"
    sub.mkdir()
    write_triangle_ply(sub / "t.ply")  # the included file's mesh, next to it
    (sub / "other.xml").write_text(
        '<scene version="2.1.0"><default name="dx" value="10"/>'
        + ply_shape("b", '<transform name="to_world"><translate x="$dx"/></transform>')  # material of the main file
        + "</scene>"
    )
    main = scene_file(tmp_path, CONCRETE + ply_shape("a") + '<include filename="parts/other.xml"/>'
                      + ply_shape("c", '<transform name="to_world"><translate y="$dx"/></transform>'))
    s = load_scene(main)
    assert s.object_names == ("a", "b", "c")
    assert s.num_triangles == 3
    # the included default applies after the include, in the main file too (shared parameters)
    np.testing.assert_allclose(s.bounds, [[0, 0, 0], [11, 11, 0]])


def test_include_cycle_is_refused(tmp_path):
    scene_file(tmp_path, '<include filename="a.xml"/>', name="b.xml")
    a = scene_file(tmp_path, CONCRETE + ply_shape("x") + '<include filename="b.xml"/>', name="a.xml")
    with pytest.raises(SceneError, match="include cycle") as info:
        load_scene(a)
    assert "a.xml" in str(info.value)


def test_missing_included_file_is_an_error(tmp_path):
    p = scene_file(tmp_path, CONCRETE + ply_shape("a") + '<include filename="nope.xml"/>')
    with pytest.raises(SceneError, match="nope.xml"):
        load_scene(p)


@pytest.mark.parametrize("element", ['<ref id="a"/>', '<shapes type="ply"/>', "<instance/>"])
def test_unknown_scene_elements_are_errors_not_dropped(tmp_path, element):
    p = scene_file(tmp_path, CONCRETE + ply_shape("a") + element)
    with pytest.raises(SceneError, match="unsupported element") as info:
        load_scene(p)
    assert p in str(info.value)


def test_non_geometry_objects_are_skipped(tmp_path):
    p = scene_file(tmp_path, '<integrator type="path"/><sensor type="perspective"><float name="fov" value="45"/></sensor>'
                   + CONCRETE + ply_shape("a"))
    assert load_scene(p).num_triangles == 1


# --- 2./3. Sionna's legacy material ids, absorbers, material names -------------------------


def test_legacy_itu_id_on_any_bsdf_is_an_itu_material(tmp_path):
    p = scene_file(tmp_path, '<bsdf type="twosided" id="mat-itu_wood"><bsdf type="principled"/></bsdf>'
                   '<bsdf type="diffuse" id="itu_glass"><float name="thickness" value="0.02"/></bsdf>'
                   + ply_shape("mesh-a", ref="mat-itu_wood") + ply_shape("mesh-b", ref="itu_glass"))
    s = load_scene(p)
    assert s.materials == (itu_material("wood"), itu_material("glass", 0.02))


def test_itu_name_as_id_of_a_non_itu_bsdf_is_refused_as_in_sionna(tmp_path):
    p = scene_file(tmp_path, '<bsdf type="radio-material" id="concrete"/>' + ply_shape("a", ref="concrete"))
    with pytest.raises(SceneError, match="mat-itu_concrete"):
        load_scene(p)


def test_absorber_radio_material_is_read(tmp_path):
    p = scene_file(tmp_path, '<bsdf type="absorber-radio-material" id="m"/>' + ply_shape("a"))
    (mat,) = load_scene(p).materials
    assert mat.is_absorber and mat.name == "m"


def test_radio_material_is_named_by_its_bsdf_id(tmp_path):
    p = scene_file(tmp_path, '<bsdf type="radio-material" id="wallpaper"><float name="relative_permittivity" value="3"/>'
                   '</bsdf>' + ply_shape("a", ref="wallpaper"))
    assert load_scene(p).materials == (Material("wallpaper", "custom", a=3.0),)


# --- 4./5. writing: unique safe names, absorbers; duplicate names on reading ----------------


def one_triangle_scene(names, materials=(itu_material("concrete"),)):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1]], float)
    n = len(names)
    return build_scene(v[: 3 * n], np.arange(3 * n).reshape(n, 3), np.arange(n), np.zeros(n, int), names, materials)


def test_export_of_two_objects_with_the_same_name_keeps_both(tmp_path):
    s = one_triangle_scene(("a", "a"))
    with pytest.warns(WavepathsWarning, match="'a' -> 'a-2'"):
        files = write_mitsuba_xml(s, str(tmp_path / "scene.xml"))
    assert len(set(files)) == len(files) == 3
    r = load_scene(files[0])
    assert r.object_names == ("a", "a-2")
    np.testing.assert_allclose(r.bounds, s.bounds)


@pytest.mark.parametrize("name", ["a/b", "a&b<c>", "bâtiment é", "..", "a\\b:c"])
def test_export_of_an_unsafe_name_keeps_the_name_and_stays_in_the_mesh_folder(tmp_path, name):
    files = write_mitsuba_xml(one_triangle_scene((name,)), str(tmp_path / "scene.xml"))
    assert all(os.path.dirname(f) == str(tmp_path / "meshes") for f in files[1:])
    assert load_scene(files[0]).object_names == (name,)


def test_export_of_an_absorber_is_an_absorber(tmp_path):
    path = str(tmp_path / "scene.xml")
    write_mitsuba_xml(one_triangle_scene(("wall",), (ABSORBER,)), path)
    (bsdf,) = ET.parse(path).getroot().findall("bsdf")
    assert bsdf.get("type") == "absorber-radio-material" and len(bsdf) == 0
    assert load_scene(path).materials == (ABSORBER,)


@pytest.mark.parametrize("ids", [("a", "mesh-a"), ("a", "a")])
def test_two_shapes_with_the_same_object_name_are_refused(tmp_path, ids):
    p = scene_file(tmp_path, CONCRETE + ply_shape(ids[0]) + ply_shape(ids[1]))
    with pytest.raises(SceneError, match="'a'") as info:
        load_scene(p)
    assert p in str(info.value) and ("already used" in str(info.value) or "duplicate id" in str(info.value))


# --- 6. parameters inside values, malformed numbers ---------------------------------------


def test_parameters_are_substituted_inside_values(tmp_path):
    p = scene_file(tmp_path, '<default name="mesh" value="t"/><default name="d" value="1"/><default name="dx" value="5"/>'
                   + CONCRETE + '<shape type="ply" id="a"><string name="filename" value="$mesh.ply"/>'
                   '<transform name="to_world"><translate value="$dx $d 0"/></transform><ref id="m"/></shape>')
    np.testing.assert_allclose(load_scene(p).bounds, [[5, 1, 0], [6, 2, 0]])


def test_undefined_parameter_is_an_error(tmp_path):
    p = scene_file(tmp_path, CONCRETE + ply_shape("a", '<transform name="to_world"><translate x="$dx"/></transform>'))
    with pytest.raises(SceneError, match=r"undefined parameter \$dx"):
        load_scene(p)


@pytest.mark.parametrize("bad", ['<transform name="to_world"><translate x="1m"/></transform>',
                                 '<transform name="to_world"><matrix value="1 2 3"/></transform>',
                                 '<float name="thickness" value="thin"/>'])
def test_malformed_numbers_name_the_file_and_element(tmp_path, bad):
    if "thickness" in bad:
        p = scene_file(tmp_path, f'<bsdf type="itu-radio-material" id="m"><string name="type" value="concrete"/>{bad}'
                       '</bsdf>' + ply_shape("a"))
    else:
        p = scene_file(tmp_path, CONCRETE + ply_shape("a", bad))
    with pytest.raises(SceneError) as info:
        load_scene(p)
    msg = str(info.value)
    assert p in msg and ("<translate" in msg or "<matrix" in msg or "thickness" in msg)


def test_cli_info_on_a_malformed_number_exits_2_without_traceback(tmp_path):
    p = scene_file(tmp_path, CONCRETE + ply_shape("a", '<transform name="to_world"><translate x="1m"/></transform>'))
    exe = shutil.which("wavepaths") or os.path.join(os.path.dirname(sys.executable), "wavepaths")
    r = subprocess.run([exe, "info", p], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr and "1m" in r.stderr and p in r.stderr


# --- 7. rotations as Mitsuba builds them --------------------------------------------------


def mitsuba_rotate(axis, angle_deg):
    """Mitsuba 3 / drjit ``rotate``: cos I + sin [u]x + (1 - cos) u u^T, u as given."""
    u = np.asarray(axis, float)
    a = np.deg2rad(angle_deg)
    k = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    return np.cos(a) * np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * np.outer(u, u)


def rotated_triangle(tmp_path, rotate):
    p = scene_file(tmp_path, CONCRETE + ply_shape("a", f'<transform name="to_world">{rotate}</transform>'))
    s = load_scene(p)
    return s.vertices[s.triangles[0]]


def test_unit_axis_rotation_is_a_rotation(tmp_path):
    tri = rotated_triangle(tmp_path, '<rotate z="1" angle="90"/>')
    np.testing.assert_allclose(tri, [[0, 0, 0], [0, 1, 0], [-1, 0, 0]], atol=1e-12)


def test_non_unit_axis_is_used_as_mitsuba_uses_it_with_a_warning(tmp_path):
    # mi.ScalarTransform4f().rotate([1, 1, 0], 45) (Mitsuba 3.9.1): first row 1, 0.29289323, 0.7071068
    with pytest.warns(WavepathsWarning, match="length 1.41421"):
        tri = rotated_triangle(tmp_path, '<rotate value="1, 1, 0" angle="45"/>')
    expected = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]]) @ mitsuba_rotate([1, 1, 0], 45).T
    np.testing.assert_allclose(tri, expected, atol=1e-12)
    np.testing.assert_allclose(mitsuba_rotate([1, 1, 0], 45)[0], [1, 0.29289323, 0.7071068], atol=1e-7)


def test_zero_rotation_axis_is_an_error(tmp_path):
    p = scene_file(tmp_path, CONCRETE + ply_shape("mesh-a", '<transform name="to_world"><rotate angle="30"/></transform>'))
    with pytest.raises(SceneError, match="rotation axis cannot be zero") as info:
        load_scene(p)
    assert p in str(info.value) and "mesh-a" in str(info.value)


# --- 8. meshes without faces --------------------------------------------------------------


def test_ply_without_faces_is_an_error(tmp_path):
    (tmp_path / "pc.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "end_header\n0 0 0\n1 0 0\n0 1 0\n"
    )
    p = scene_file(tmp_path, CONCRETE + ply_shape("a") + '<shape type="ply" id="b"><string name="filename" '
                   'value="pc.ply"/><ref id="m"/></shape>')
    with pytest.raises(SceneError, match="no faces") as info:
        load_scene(p)
    assert "pc.ply" in str(info.value) and "'b'" in str(info.value)
