"""Mesh files' objects and materials: OBJ `o`/`g` and `usemtl`, glTF material names.

trimesh misread both: an OBJ ground and box, each with its own `usemtl`, came out as an
object "ground" holding the box's 12 triangles and "ground_1" holding the ground's 2;
without `usemtl` the two `o` objects were merged into one named after the file; and every
triangle was a perfect conductor whatever the file named.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from wavepaths.errors import SceneError, WavepathsError
from wavepaths.scene import WavepathsWarning, load_scene

GROUND = "v -50 -50 0\nv 50 -50 0\nv 50 50 0\nv -50 50 0\n"
BOX = "".join(f"v {x} {y} {z}\n" for z in (0, 10) for x, y in ((-5, -5), (5, -5), (5, 5), (-5, 5)))
BOX_FACES = "f 5 8 7 6\nf 9 10 11 12\nf 5 6 10 9\nf 6 7 11 10\nf 7 8 12 11\nf 8 5 9 12\n"


def write(tmp_path, name: str, text: str) -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def names(scene) -> list[str]:
    return [scene.materials[m].name for m in scene.triangle_material]


def test_o_objects_and_itu_usemtl_names(tmp_path):
    path = write(tmp_path, "city.obj", "o ground\n" + GROUND + "usemtl itu_medium_dry_ground\nf 1 2 3 4\n"
                 "o box\n" + BOX + "usemtl itu_concrete\n" + BOX_FACES)
    scene = load_scene(path)
    assert scene.object_names == ("ground", "box")
    assert np.bincount(scene.triangle_object).tolist() == [2, 12]
    assert names(scene) == ["medium_dry_ground"] * 2 + ["concrete"] * 12
    assert scene.areas[scene.triangle_object == 0].sum() == pytest.approx(100 * 100)
    assert scene.areas[scene.triangle_object == 1].sum() == pytest.approx(10 * 10 * 6)


def test_objects_without_materials_stay_apart_and_take_the_default(tmp_path):
    path = write(tmp_path, "city.obj", "o ground\n" + GROUND + "f 1 2 3 4\no box\n" + BOX + BOX_FACES)
    scene = load_scene(path)
    assert scene.object_names == ("ground", "box")
    assert set(names(scene)) == {"pec"}
    assert set(names(load_scene(path, material="concrete"))) == {"concrete"}  # a name is a material


def test_g_groups_name_objects_when_there_is_no_o(tmp_path):
    path = write(tmp_path, "g.obj", GROUND + "f 1 2 3 4\ng box\n" + BOX + BOX_FACES)
    scene = load_scene(path)
    assert scene.object_names == ("g", "box")  # before the first group: the file's name


def test_negative_indices_count_back_from_the_last_vertex(tmp_path):
    rel = write(tmp_path, "rel.obj", GROUND + "f -4 -3 -2 -1\n" + BOX + "f -8 -5 -6 -7\n")
    absolute = write(tmp_path, "abs.obj", GROUND + "f 1 2 3 4\n" + BOX + "f 5 8 7 6\n")
    a, b = load_scene(rel), load_scene(absolute)
    assert np.array_equal(a.vertices[a.triangles], b.vertices[b.triangles])


@pytest.mark.parametrize("face, message", [("f 1 2 9", r"line 5: face reference '9' names vertex 9; 4 vertices"),
                                           ("f 1 2 x", r"line 5: face reference 'x' is not an integer"),
                                           ("f 1 2", r"line 5: a face needs at least 3 vertices")])
def test_a_bad_face_names_its_line(tmp_path, face, message):
    with pytest.raises(SceneError, match=message):
        load_scene(write(tmp_path, "bad.obj", GROUND + face + "\n"))


def test_unknown_material_names_warn_and_can_be_mapped(tmp_path):
    path = write(tmp_path, "m.obj", "o ground\n" + GROUND + "usemtl Dirt\nf 1 2 3 4\n"
                 "o box\n" + BOX + "usemtl Concrete\n" + BOX_FACES)
    with pytest.warns(WavepathsWarning, match=r"'Dirt' .*default material 'pec'.*materials="):
        scene = load_scene(path)
    assert names(scene) == ["pec"] * 2 + ["concrete"] * 12
    scene = load_scene(path, materials={"Dirt": "medium_dry_ground", "Concrete": "absorber"})  # no warning
    assert names(scene) == ["medium_dry_ground"] * 2 + ["absorber"] * 12


def test_bad_material_arguments_are_refused_up_front(tmp_path):
    path = write(tmp_path, "g.obj", GROUND + "f 1 2 3 4\n")
    with pytest.raises(WavepathsError, match="unknown material name 'concret'"):
        load_scene(path, material="concret")
    with pytest.raises(WavepathsError, match="must be a Material or a material name"):
        load_scene(path, material=3)
    with pytest.raises(WavepathsError, match="must be a mapping"):
        load_scene(path, materials=["concrete"])


def test_gltf_material_names_are_mapped(tmp_path):
    box = trimesh.creation.box(extents=(2, 2, 2))
    box.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(name="itu_glass"))
    plate = trimesh.creation.box(extents=(10, 10, 0.1))
    plate.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(name="Wood"))
    path = str(tmp_path / "s.glb")
    trimesh.Scene({"box": box, "plate": plate}).export(path)
    scene = load_scene(path)
    by_object = {scene.object_names[o]: scene.materials[m].name
                 for o, m in zip(scene.triangle_object, scene.triangle_material)}
    assert by_object == {"box": "glass", "plate": "wood"}


def test_a_material_for_a_scene_with_its_own_materials_is_reported():
    with pytest.warns(WavepathsWarning, match="apply to mesh files"):
        scene = load_scene("street_canyon", material="glass")
    assert "glass" not in {m.name for m in scene.materials}


# ---- found by a second reading of the reader ---------------------------------------------
L_FACE = "f 3 4 5 6 1 2\n"  # an L of area 3 whose fan from its first vertex would leave it
L_VERTS = [(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)]


@pytest.mark.parametrize("style", ["tab", "indented", "negative", "continued_comment"])
def test_concave_faces_are_split_from_the_vertices_the_reader_reads(tmp_path, style):
    """The concave face is split where the reader resolves its vertices: vertex lines with a
    tab or indented, negative references, a comment line ending in a backslash. (Before, a
    second parser with its own rules chose the triangles: area 4 instead of 3, or a crash.)"""
    sep = "\t" if style == "tab" else " "
    lead = "  " if style == "indented" else ""
    verts = "".join(f"{lead}v{sep}{x} {y} 0\n" for x, y in L_VERTS)
    face = "f -4 -3 -2 -1 -6 -5\n" if style == "negative" else L_FACE
    head = "# a note \\\n(its second line)\n" if style == "continued_comment" else ""
    scene = load_scene(write(tmp_path, "l.obj", head + verts + face))
    assert scene.areas.sum() == pytest.approx(3.0, rel=1e-12)
    assert scene.num_triangles == 4


def test_a_bad_face_after_a_split_face_names_the_files_line(tmp_path):
    verts = "".join(f"v {x} {y} 0\n" for x, y in L_VERTS)
    with pytest.raises(SceneError, match=r"line 8: face reference '9'"):
        load_scene(write(tmp_path, "bad.obj", verts + L_FACE + "f 1 2 9\n"))


def test_warnings_point_at_the_callers_line(tmp_path):
    import warnings

    path = write(tmp_path, "m.obj", GROUND + "usemtl Dirt\nf 1 2 3 4\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_scene(path)
    assert [w.filename for w in caught] == [__file__]


def test_spaced_material_names_are_matched():
    from wavepaths.em.materials import material_by_name

    for name in ("ITU Concrete", "itu_concrete", "Mat-ITU_Concrete", "concrete"):
        assert material_by_name(name).name == "concrete"
    assert material_by_name("Medium Dry Ground").name == "medium_dry_ground"


@pytest.mark.parametrize("encoding", ["cp1252", "utf-8-sig", "utf-8"])
def test_an_obj_file_in_a_windows_encoding_loads(tmp_path, encoding):
    """A review found an OBJ with one Latin-1 comment refused ("No module named
    'charset_normalizer'", trimesh's guess of the encoding): such files come from Windows CAD
    and GIS exports. UTF-8, with or without a byte-order mark, and cp1252 all load, the names
    read as written where the encoding says so."""
    text = ("# Bâtiment en béton\no sol\n" + GROUND + "usemtl itu_medium_dry_ground\nf 1 2 3 4\n"
            "o bâtiment\n" + BOX + "usemtl itu_concrete\n" + BOX_FACES)
    path = tmp_path / "city.obj"
    path.write_bytes(text.encode(encoding))
    scene = load_scene(str(path))
    assert scene.object_names == ("sol", "bâtiment")
    assert names(scene) == ["medium_dry_ground"] * 2 + ["concrete"] * 12
