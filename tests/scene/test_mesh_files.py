"""Plain mesh files: OBJ polygon faces triangulated exactly, glTF/GLB rotated to +Z up.

trimesh splits an OBJ face into a fan from its first vertex, which covers area outside a
concave face; the plain loader ear-clips such faces, while the XML reader keeps Mitsuba's
fans and warns. glTF is +Y up by its specification, wavepaths +Z up.
"""

from __future__ import annotations

import base64
import importlib.util
import json
import struct
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

from wavepaths.errors import SceneError, WavepathsError
from wavepaths.scene import WavepathsWarning, load_scene
from wavepaths.scene.obj_faces import polygon_planes, triangulate_polygon

# An L-shaped roof at 10 m (175 m^2) and a U-shaped slab (500 m^2), counter-clockwise.
L_SHAPE = np.array([[0, 0], [20, 0], [20, 5], [5, 5], [5, 20], [0, 20]], float)
U_SHAPE = np.array([[0, 0], [30, 0], [30, 20], [20, 20], [20, 10], [10, 10], [10, 20], [0, 20]], float)
# The U with extra vertices on its edges (three collinear vertices in a row, several times).
U_COLLINEAR = np.array([[0, 0], [10, 0], [20, 0], [30, 0], [30, 20], [20, 20], [20, 15], [20, 10],
                        [15, 10], [10, 10], [10, 20], [0, 20], [0, 10]], float)


# ----------------------------------------------------------------------------- helpers


def shoelace(xy: np.ndarray) -> float:
    """Signed area of a polygon in the plane [m^2] (positive: counter-clockwise)."""
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def inside(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Even-odd test of ``(n, 2)`` points against a polygon (points on the border: either)."""
    x, y = points[:, 0:1], points[:, 1:2]
    a, b = polygon, np.roll(polygon, -1, axis=0)
    crosses = (a[:, 1] > y) != (b[:, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xs = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    return ((crosses & (x < xs)).sum(axis=1) % 2) == 1


def samples_in_triangles(tri_xy: np.ndarray) -> np.ndarray:
    """Interior sample points ``(m * 21, 2)`` of ``(m, 3, 2)`` triangles."""
    bary = np.array([[i, j, 8 - i - j] for i in range(1, 7) for j in range(1, 8 - i)], float) / 8
    return np.einsum("sk,mkd->msd", bary, tri_xy).reshape(-1, 2)


def write_obj(path: Path, xy: np.ndarray, z: float = 10.0, start: int = 0, reverse: bool = False) -> Path:
    """One face of the polygon ``xy`` at height ``z``, written from vertex ``start``."""
    order = np.roll(np.arange(len(xy)), -start)
    if reverse:
        order = order[::-1]
    lines = [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y in xy[order]]
    lines.append("f " + " ".join(str(i + 1) for i in range(len(xy))))
    path.write_text("o roof\n" + "\n".join(lines) + "\n")
    return path


def assert_exact_triangulation(scene, xy: np.ndarray, up: float = 1.0) -> None:
    """The scene's triangles tile the polygon ``xy``: same area to 1e-9, every triangle
    inside it and turning like it, no vertex added or dropped."""
    area = abs(shoelace(xy))
    assert scene.areas.sum() == pytest.approx(area, rel=1e-9)
    np.testing.assert_allclose(scene.normals[:, 2], up, atol=1e-12)
    tri_xy = scene.vertices[scene.triangles][:, :, :2]
    assert inside(samples_in_triangles(tri_xy), xy).all()
    assert len(scene.vertices) == len(xy)
    assert len(np.unique(scene.triangles)) == len(xy)


# ----------------------------------------------------------------------------- OBJ polygons


@pytest.mark.parametrize("start", range(len(L_SHAPE)))
@pytest.mark.parametrize("reverse", [False, True])
def test_l_shaped_face_is_triangulated_exactly(tmp_path, start, reverse):
    scene = load_scene(str(write_obj(tmp_path / "l.obj", L_SHAPE, start=start, reverse=reverse)))
    assert_exact_triangulation(scene, L_SHAPE, up=-1.0 if reverse else 1.0)
    assert scene.num_triangles == len(L_SHAPE) - 2


@pytest.mark.parametrize("start", range(len(U_SHAPE)))
def test_u_shaped_face_is_triangulated_exactly(tmp_path, start):
    scene = load_scene(str(write_obj(tmp_path / "u.obj", U_SHAPE, z=0.0, start=start)))
    assert_exact_triangulation(scene, U_SHAPE)
    assert scene.num_triangles == len(U_SHAPE) - 2


@pytest.mark.parametrize("start", range(len(U_COLLINEAR)))
def test_collinear_vertices_give_no_degenerate_triangle(tmp_path, start):
    # A degenerate triangle would be dropped with a warning, an error under pytest.
    scene = load_scene(str(write_obj(tmp_path / "uc.obj", U_COLLINEAR, z=0.0, start=start)))
    assert_exact_triangulation(scene, U_COLLINEAR)
    assert scene.num_triangles == len(U_COLLINEAR) - 2


def test_the_reported_l_roof_lost_its_extra_area(tmp_path):
    # Written from the vertex next to the reflex corner, trimesh's fan covered 400 m^2.
    scene = load_scene(str(write_obj(tmp_path / "roof.obj", L_SHAPE, start=2)))
    assert scene.areas.sum() == pytest.approx(175.0, rel=1e-12)


def test_convex_polygon_keeps_trimesh_fan(tmp_path):
    angles = np.linspace(0, 2 * np.pi, 9)[:-1]
    octagon = np.stack([7 * np.cos(angles), 7 * np.sin(angles)], axis=1)
    path = write_obj(tmp_path / "octagon.obj", octagon, z=3.0)
    scene = load_scene(str(path))
    assert scene.areas.sum() == pytest.approx(shoelace(octagon), rel=1e-12)
    fan = trimesh.load(str(path), process=False)
    assert sorted(map(sorted, scene.triangles.tolist())) == sorted(map(sorted, fan.faces.tolist()))


def test_non_planar_face_is_triangulated_with_a_warning(tmp_path):
    path = write_obj(tmp_path / "bent.obj", L_SHAPE, start=2)
    text = path.read_text().replace("v 5 20 10", "v 5 20 10.5")
    path.write_text(text)
    with pytest.warns(WavepathsWarning, match=r"bent\.obj: 1 face\(s\).*not planar.*line 8"):
        scene = load_scene(str(path))
    assert scene.num_triangles == 4
    assert inside(samples_in_triangles(scene.vertices[scene.triangles][:, :, :2]), L_SHAPE).all()


def test_self_intersecting_face_warns(tmp_path):
    path = tmp_path / "bowtie.obj"
    path.write_text("v 0 0 0\nv 10 10 0\nv 10 0 0\nv 0 10 0\nv 5 20 0\nf 1 2 3 4 5\n")
    with pytest.warns(WavepathsWarning, match=r"bowtie\.obj: 1 face\(s\) are not simple.*line 6"):
        load_scene(str(path))


def test_objects_and_materials_come_from_the_o_and_usemtl_statements(tmp_path):
    """Objects are the file's `o` statements and materials its `usemtl` names (ITU names
    here), whatever trimesh makes of them: it grouped this file by material ("brick" held
    the roof and the wall) and, without a .mtl file, dropped the names."""
    (tmp_path / "m.mtl").write_text("newmtl brick\nKd 1 0 0\nnewmtl glass\nKd 0 0 1\n")
    corners = "".join(f"v {x:g} {y:g} 10\n" for x, y in np.roll(L_SHAPE, -2, axis=0))
    body = (corners + "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\n"
            "o roof\nusemtl brick\nf 1 2 3 4 5 6\n"
            "o slab\nusemtl glass\nf 7 8 9 10\n"
            "o wall\nusemtl brick\nf 7 8 11\n")
    for name, text in (("city.obj", "mtllib m.mtl\n" + body), ("nomtl.obj", body)):
        (tmp_path / name).write_text(text)
        scene = load_scene(str(tmp_path / name))
        assert scene.object_names == ("roof", "slab", "wall")
        assert np.bincount(scene.triangle_object).tolist() == [4, 2, 1]
        material = [scene.materials[m].name for m in scene.triangle_material]
        assert material == ["brick"] * 4 + ["glass"] * 2 + ["brick"]
        assert scene.areas[scene.triangle_object == 0].sum() == pytest.approx(175.0, rel=1e-12)


def test_large_concave_polygon_is_exact():
    k = 4000  # a star: alternate vertices on radii 10 and 4; every inner vertex is reflex
    angles = np.linspace(0, 2 * np.pi, k, endpoint=False)
    radius = np.where(np.arange(k) % 2 == 0, 10.0, 4.0)
    star = np.stack([radius * np.cos(angles), radius * np.sin(angles), np.zeros(k)], axis=1)
    planes = polygon_planes(np.roll(star, -1, axis=0)[None], 1e-9)
    uv = planes.uv[0]
    tris, clean = triangulate_polygon(uv, 1e-9)  # (its O(k^2) cost is not timed here: timings live in benchmarks)
    assert clean and tris.shape == (k - 2, 3)
    a, b, c = (uv[tris[:, i]] for i in range(3))
    doubled = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]
    assert (doubled > 0).all()
    assert doubled.sum() / 2 == pytest.approx(planes.area[0], rel=1e-9)


# ----------------------------------------------------------------------------- XML: Mitsuba's fans


def write_xml(tmp_path: Path, mesh: str) -> Path:
    """An XML scene of one OBJ shape ``mesh`` (relative to ``tmp_path``), as Sionna RT reads them."""
    xml = tmp_path / "scene.xml"
    xml.write_text(f"""<scene version="2.1.0">
      <shape type="obj" id="mesh-roof">
        <string name="filename" value="{mesh}"/>
        <bsdf type="itu-radio-material"><string name="type" value="concrete"/></bsdf>
      </shape>
    </scene>""")
    return xml


def test_xml_keeps_mitsuba_fan_and_warns_on_a_concave_face(tmp_path):
    write_obj(tmp_path / "l.obj", L_SHAPE, start=2)
    message = r"l\.obj has 1 concave face\(s\), e\.g\. line 8: 'f 1 2 3 4 5 6'.*400 m\^2.*175 m\^2"
    with pytest.warns(WavepathsWarning, match=message):
        scene = load_scene(str(write_xml(tmp_path, "l.obj")))
    # Mitsuba 3.9.1 makes the triangles (0, i, i + 1) of the face: 400 m^2 here.
    assert scene.num_triangles == 4
    assert scene.areas.sum() == pytest.approx(400.0, rel=1e-12)


def oriented_triangles(corners: np.ndarray) -> set:
    """Triangles ``(m, 3, 3)`` as a set of corner tuples, each rotated to start at its
    smallest corner (orientation kept), rounded to 0.1 mm (Mitsuba stores float32)."""
    out = set()
    for tri in np.round(corners, 4) + 0.0:
        rows = [tuple(r) for r in tri]
        first = rows.index(min(rows))
        out.add(tuple(rows[first:] + rows[:first]))
    return out


MITSUBA_TRIANGLES = """
import json, sys
import numpy as np
import mitsuba as mi
mi.set_variant("scalar_rgb")
mesh = mi.load_dict({"type": "obj", "filename": sys.argv[1]})
p = np.array(mesh.vertex_positions_buffer()).reshape(-1, 3)
f = np.array(mesh.faces_buffer()).reshape(-1, 3)
with open(sys.argv[2], "w") as out:  # not stdout: Mitsuba logs there
    json.dump(p[f].tolist(), out)
"""


@pytest.mark.parametrize("shape, start", [(L_SHAPE, 2), (U_SHAPE, 0), (U_COLLINEAR, 3)])
def test_xml_triangles_are_mitsuba_triangles(tmp_path, shape, start):
    if importlib.util.find_spec("mitsuba") is None:
        pytest.skip("mitsuba is not installed (the sionna extra)")
    mesh = write_obj(tmp_path / "face.obj", shape, start=start)
    out = tmp_path / "mitsuba.json"
    run = subprocess.run([sys.executable, "-c", MITSUBA_TRIANGLES, str(mesh), str(out)], capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", WavepathsWarning)  # concave faces warn, zero-area fan triangles are dropped
        scene = load_scene(str(write_xml(tmp_path, "face.obj")))
    mitsuba = np.array(json.loads(out.read_text()))
    doubled = np.linalg.norm(np.cross(mitsuba[:, 1] - mitsuba[:, 0], mitsuba[:, 2] - mitsuba[:, 0]), axis=1)
    assert oriented_triangles(scene.vertices[scene.triangles]) == oriented_triangles(mitsuba[doubled > 1e-9])


def test_xml_does_not_warn_when_the_fan_is_right(tmp_path):
    write_obj(tmp_path / "l.obj", L_SHAPE, start=0)  # concave, but the fan from its vertex 0 covers it
    scene = load_scene(str(write_xml(tmp_path, "l.obj")))
    assert scene.areas.sum() == pytest.approx(175.0, rel=1e-12)


# ----------------------------------------------------------------------------- glTF up axis


def tower_y_up() -> trimesh.Trimesh:
    """A 4 x 10 x 2 m box standing on y = 0, tall along +Y (glTF's up)."""
    box = trimesh.creation.box(extents=(4, 10, 2))
    box.apply_translation((0, 5, 0))
    return box


def gltf_document(mesh: trimesh.Trimesh) -> tuple[dict, bytes]:
    """A glTF 2.0 document of one mesh node and its binary buffer (hand-written, so that
    nothing converts axes on the way)."""
    v = np.asarray(mesh.vertices, np.float32)
    f = np.asarray(mesh.faces, np.uint32)
    blob = v.tobytes() + f.tobytes()
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "tower"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": len(blob)}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": v.nbytes},
                        {"buffer": 0, "byteOffset": v.nbytes, "byteLength": f.nbytes}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": len(v), "type": "VEC3",
             "min": v.min(axis=0).tolist(), "max": v.max(axis=0).tolist()},
            {"bufferView": 1, "componentType": 5125, "count": int(f.size), "type": "SCALAR"},
        ],
    }
    return doc, blob


def write_gltf(path: Path, mesh: trimesh.Trimesh) -> Path:
    """A ``.gltf`` (JSON, buffer as a data URI) or ``.glb`` (binary container) file."""
    doc, blob = gltf_document(mesh)
    if path.suffix == ".gltf":
        doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
        path.write_text(json.dumps(doc))
        return path
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    blob += b"\0" * (-len(blob) % 4)
    chunks = struct.pack("<I4s", len(js), b"JSON") + js + struct.pack("<I4s", len(blob), b"BIN\0") + blob
    path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks)
    return path


def signed_volume(scene) -> float:
    """Volume of a closed mesh [m^3], positive when its faces turn outward."""
    t = scene.vertices[scene.triangles]
    return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6)


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_gltf_y_up_becomes_z_up(tmp_path, suffix):
    scene = load_scene(str(write_gltf(tmp_path / f"tower{suffix}", tower_y_up())))
    np.testing.assert_allclose(scene.bounds, [[-2, -1, 0], [2, 1, 10]], atol=1e-6)
    assert signed_volume(scene) == pytest.approx(80.0, rel=1e-6)  # a rotation: faces still turn outward
    # (x, y, z) -> (x, -z, y): the glTF corner (2, 10, 1) is at (2, -1, 10)
    assert np.linalg.norm(scene.vertices - [2, -1, 10], axis=1).min() < 1e-6


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_up_axis_z_keeps_the_file_axes(tmp_path, suffix):
    scene = load_scene(str(write_gltf(tmp_path / f"tower{suffix}", tower_y_up())), up_axis="z")
    np.testing.assert_allclose(scene.bounds, [[-2, 0, -1], [2, 10, 1]], atol=1e-6)
    assert signed_volume(scene) == pytest.approx(80.0, rel=1e-6)


def test_up_axis_y_rotates_other_mesh_formats(tmp_path):
    path = tmp_path / "tower.obj"
    tower_y_up().export(str(path))
    np.testing.assert_allclose(load_scene(str(path)).bounds, [[-2, 0, -1], [2, 10, 1]], atol=1e-9)
    np.testing.assert_allclose(load_scene(str(path), up_axis="y").bounds, [[-2, -1, 0], [2, 1, 10]], atol=1e-9)


def test_up_axis_is_checked(tmp_path):
    with pytest.raises(WavepathsError, match="up_axis must be one of"):
        load_scene("street_canyon", up_axis="x")
    with pytest.raises(SceneError, match="applies to mesh files"):
        load_scene("street_canyon", up_axis="y")
    np.testing.assert_allclose(load_scene("street_canyon", up_axis="z").bounds, load_scene("street_canyon").bounds)


def test_the_command_line_takes_the_up_axis(tmp_path, capsys):
    """`--up-axis` on `info` (and `paths`, `coverage`) is load_scene's `up_axis`."""
    from wavepaths.cli import main

    path = write_gltf(tmp_path / "tower.gltf", tower_y_up())
    heights = {}
    for axis in ("auto", "z"):
        assert main(["info", str(path), "--json", "--up-axis", axis]) == 0
        lo, hi = np.array(json.loads(capsys.readouterr().out)["bounds"])
        heights[axis] = hi - lo
    assert heights["auto"] == pytest.approx([4, 2, 10]) and heights["z"] == pytest.approx([4, 10, 2])
    assert main(["info", "street_canyon", "--up-axis", "y"]) == 2  # a built-in scene is +Z up
    assert "up_axis" in capsys.readouterr().err
