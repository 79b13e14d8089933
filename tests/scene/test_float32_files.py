"""Mesh files storing float32 coordinates far from the origin (scene/precision.py).

A review (twenty-ninth session) loaded a city written as binary PLY at UTM coordinates: the
0.3 m rounding of float32 there is hundreds of times the weld tolerance, so walls split
into several polygons and false edges diffracted, silently. (The street canyon used here keeps its topology: its walls are large; the review's
gabled 6 x 6 city went from 289 polygons to 615.) The loader now warns, and
``write_mitsuba_xml`` writes such scenes around a local origin with a ``to_world``
translate, which reads back in float64."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

from wavepaths import load_scene, write_mitsuba_xml
from wavepaths.scene import WavepathsWarning, transformed
from wavepaths.scene.precision import FLOAT32_ROUNDING, stores_float32

UTM = np.array([690123.37, 5330456.71, 512.3])
C, S = np.cos(np.radians(17.0)), np.sin(np.radians(17.0))
TURN = np.array([[C, -S, 0.0], [S, C, 0.0], [0.0, 0.0, 1.0]])  # walls off the axes: float32 rounds each corner its own way


def write_ply(path, vertices, faces, dtype: str) -> str:
    """A binary little-endian PLY file with ``dtype`` ("float" or "double") coordinates."""
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(vertices)}\n"
            + "".join(f"property {dtype} {a}\n" for a in "xyz")
            + f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    body = np.asarray(vertices, "<f4" if dtype == "float" else "<f8").tobytes()
    rows = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", 3)])
    rows["n"], rows["i"] = 3, faces
    with open(path, "wb") as fh:
        fh.write(head.encode("ascii") + body + rows.tobytes())
    return str(path)


@pytest.fixture(scope="module")
def canyon():
    return transformed(load_scene("street_canyon"), rotation=TURN)


def loaded(path):
    """The scene at ``path`` and the wavepaths warnings its loading gave."""
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        scene = load_scene(str(path))
    return scene, [str(w.message) for w in rec if issubclass(w.category, WavepathsWarning)]


def test_a_float32_ply_at_utm_coordinates_is_warned_about(canyon, tmp_path):
    far = canyon.vertices + UTM
    scene, said = loaded(write_ply(tmp_path / "f32.ply", far, canyon.triangles, "float"))
    assert len(said) == 1 and "stores its vertices as float32" in said[0] and "local origin" in said[0]
    step = np.abs(np.asarray(far, np.float32)).max() * FLOAT32_ROUNDING
    assert f"{step:.2g} m" in said[0]
    # the rounding it names is real, and bounds the vertices' error (the float64 file: none)
    exact, quiet = loaded(write_ply(tmp_path / "f64.ply", far, canyon.triangles, "double"))
    assert quiet == []
    moved = np.abs(scene.vertices - exact.vertices).max()
    assert 0.1 * step < moved <= step
    np.testing.assert_array_equal(exact.vertices, far)


def test_a_float32_ply_near_the_origin_and_text_files_are_not_warned_about(canyon, tmp_path):
    assert loaded(write_ply(tmp_path / "near.ply", canyon.vertices, canyon.triangles, "float"))[1] == []
    far = canyon.vertices + UTM
    obj = tmp_path / "far.obj"
    obj.write_text("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in far.tolist())
                   + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in canyon.triangles))
    assert loaded(obj)[1] == []


def test_binary_stl_and_glb_store_float32(canyon, tmp_path):
    mesh = trimesh.Trimesh(canyon.vertices + UTM, canyon.triangles, process=False)
    stl, glb, ascii_stl = tmp_path / "far.stl", tmp_path / "far.glb", tmp_path / "text.stl"
    mesh.export(stl)
    mesh.export(glb)
    ascii_stl.write_text(trimesh.exchange.stl.export_stl_ascii(mesh))
    assert stores_float32(str(stl)) and stores_float32(str(glb)) and not stores_float32(str(ascii_stl))
    assert any("float32" in m for m in loaded(stl)[1])
    assert any("float32" in m for m in loaded(glb)[1])  # (read with +Y up: rotated, and still warned)


def test_write_mitsuba_xml_keeps_a_far_scene_exact(canyon, tmp_path):
    far = transformed(canyon, translation=UTM)
    files = write_mitsuba_xml(far, str(tmp_path / "far.xml"))
    assert "translate" in Path(files[0]).read_text()
    back, said = loaded(files[0])
    assert said == []
    # the same vertices to float32 rounding of the local coordinates (about 6e-6 m here, not 0.3 m)
    got = np.unique(np.round(back.vertices, 3), axis=0)
    want = np.unique(np.round(far.vertices, 3), axis=0)
    assert got.shape == want.shape and np.abs(got - want).max() <= 2e-3
    assert len(back.polygon_normal) == len(far.polygon_normal)
    # a scene near the origin is written as before, without a translate
    near = write_mitsuba_xml(canyon, str(tmp_path / "near.xml"))
    assert "translate" not in Path(near[0]).read_text()


def test_a_scene_in_millimetres_is_warned_about(canyon, tmp_path):
    obj = tmp_path / "mm.obj"
    obj.write_text("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in (1000.0 * canyon.vertices).tolist())
                   + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in canyon.triangles))
    said = loaded(obj)[1]
    assert len(said) == 1 and "km; wavepaths reads coordinates in metres" in said[0]
    assert loaded(write_ply(tmp_path / "m.ply", canyon.vertices, canyon.triangles, "double"))[1] == []
