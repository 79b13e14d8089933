"""PLY and OFF files read as polygons (``scene/ply_off_reader.py``): concave faces keep their
area, every PLY encoding gives the same geometry, bad files name their place.

The geometry is checked against the polygons written (shoelace areas, even-odd inside
tests of the triangles' interior points) and, for triangle files, against trimesh's reader.
"""

from __future__ import annotations

import struct
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

from wavepaths.errors import SceneError
from wavepaths.scene import WavepathsWarning, load_scene
from wavepaths.scene.ply_off_reader import read_off, read_ply

from .test_mesh_files import L_SHAPE, U_SHAPE, assert_exact_triangulation, shoelace

ENCODINGS = ["ascii", "binary_little_endian", "binary_big_endian"]


def write_ply(path: Path, vertices: np.ndarray, faces: list[list[int]], fmt: str = "ascii",
              extra: bool = False, count_type: str = "uchar", index_type: str = "int") -> Path:
    """A PLY file of ``vertices`` (float x, y, z) and polygon ``faces``. ``extra``: vertex
    normals and a colour byte before and after the coordinates, a face flag after the list,
    and an ``edge`` element after the faces, which a reader must read past."""
    head = ["ply", f"format {fmt} 1.0", "comment written by the wavepaths tests", f"element vertex {len(vertices)}"]
    vprops = [("uchar", "red")] if extra else []
    vprops += [("float", "x"), ("double", "y"), ("float", "z")]
    vprops += [("float", "nx"), ("float", "ny"), ("float", "nz")] if extra else []
    head += [f"property {t} {n}" for t, n in vprops]
    head += [f"element face {len(faces)}", f"property list {count_type} {index_type} vertex_indices"]
    if extra:
        head += ["property ushort flags", "element edge 2", "property int vertex1", "property int vertex2"]
    head.append("end_header")
    codes = {"uchar": "B", "ushort": "H", "int": "i", "uint": "I", "float": "f", "double": "d", "short": "h"}
    rows_v = [([7] if extra else []) + [float(x) for x in p] + ([0.0, 0.0, 1.0] if extra else []) for p in vertices]
    rows_f = [[len(f), *map(int, f)] + ([3] if extra else []) for f in faces]
    rows_e = [[0, 1], [1, 2]] if extra else []
    if fmt == "ascii":
        body = "".join(" ".join(repr(x) if isinstance(x, float) else str(x) for x in r) + "\n"
                       for r in rows_v + rows_f + rows_e).encode()
    else:
        o = "<" if fmt == "binary_little_endian" else ">"
        vcode = "".join(codes[t] for t, _ in vprops)
        body = b"".join(struct.pack(o + vcode, *r) for r in rows_v)
        for f in faces:
            code = codes[count_type] + codes[index_type] * len(f) + ("H" if extra else "")
            body += struct.pack(o + code, len(f), *f, *([3] if extra else []))
        body += b"".join(struct.pack(o + "ii", *r) for r in rows_e)
    path.write_bytes(("\n".join(head) + "\n").encode() + body)
    return path


def write_off(path: Path, vertices: np.ndarray, faces: list[list[int]], keyword: str = "OFF") -> Path:
    lines = [keyword, "# a comment", f"{len(vertices)} {len(faces)} 0"]
    lines += [" ".join(repr(float(x)) for x in p) for p in vertices]
    lines += [" ".join(map(str, [len(f), *f])) + (" 255 0 0" if keyword == "COFF" else "") for f in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def polygon_3d(xy: np.ndarray, z: float = 10.0) -> np.ndarray:
    return np.column_stack([xy, np.full(len(xy), z)])


@pytest.mark.parametrize("fmt", ENCODINGS)
@pytest.mark.parametrize("start", [0, 2])
def test_concave_ply_face_is_triangulated_exactly(tmp_path, fmt, start):
    # From vertex 2 trimesh's fan covers the square that closes the L (400 m^2, not 175)
    order = list(np.roll(np.arange(len(L_SHAPE)), -start))
    path = write_ply(tmp_path / "l.ply", polygon_3d(L_SHAPE), [order], fmt)
    scene = load_scene(str(path))
    assert_exact_triangulation(scene, L_SHAPE)
    assert scene.object_names == ("l",)
    if start == 2 and fmt == "ascii":
        assert trimesh.load(str(path), process=False).area == pytest.approx(400.0)  # the fan this replaces


@pytest.mark.parametrize("keyword", ["OFF", "COFF"])
@pytest.mark.parametrize("start", range(len(U_SHAPE)))
def test_concave_off_face_is_triangulated_exactly(tmp_path, keyword, start):
    order = list(np.roll(np.arange(len(U_SHAPE)), -start))
    scene = load_scene(str(write_off(tmp_path / "u.off", polygon_3d(U_SHAPE, 0.0), [order], keyword)))
    assert_exact_triangulation(scene, U_SHAPE)


def test_off_counts_may_share_the_keyword_line(tmp_path):
    p = tmp_path / "t.off"
    p.write_text("OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    assert load_scene(str(p)).areas.sum() == pytest.approx(0.5, rel=1e-15)


@pytest.mark.parametrize("fmt", ENCODINGS)
def test_mixed_faces_extra_properties_and_elements(tmp_path, fmt):
    # An L (6 vertices), a quad and a triangle in one face element; vertex properties around
    # x, y, z, a face flag after the list, an edge element after the faces. trimesh refuses
    # the binary form of such a file ("PLY is unexpected length")
    quad = np.array([[30, 0, 0], [32, 0, 0], [32, 3, 0], [30, 3, 0]], float)
    tri = np.array([[40, 0, 0], [41, 0, 0], [40, 1, 0]], float)
    v = np.vstack([polygon_3d(L_SHAPE), quad, tri])
    faces = [[2, 3, 4, 5, 0, 1], [6, 7, 8, 9], [10, 11, 12]]
    for count_type, index_type in [("uchar", "int"), ("ushort", "uint")]:
        path = write_ply(tmp_path / f"m_{count_type}.ply", v, faces, fmt, extra=True, count_type=count_type,
                         index_type=index_type)
        poly = read_ply(str(path))
        np.testing.assert_array_equal(poly.vertices, v)  # integers: exact in float32
        assert poly.counts.tolist() == [6, 4, 3]
        assert poly.indices.tolist() == sum(faces, [])
        scene = load_scene(str(path))
        assert scene.areas.sum() == pytest.approx(175.0 + 6.0 + 0.5, rel=1e-12)
        assert scene.num_triangles == 4 + 2 + 1


@pytest.mark.parametrize("fmt", ENCODINGS)
def test_triangle_files_read_as_trimesh_reads_them(tmp_path, fmt):
    # A random closed mesh (an icosphere, jittered): the same vertices and faces as trimesh's
    # reader gives for the same file, whatever the encoding
    rng = np.random.default_rng(3)
    ico = trimesh.creation.icosphere(subdivisions=2)
    v = np.asarray(ico.vertices) * (5 + rng.random((len(ico.vertices), 1)))
    path = write_ply(tmp_path / "ico.ply", v, np.asarray(ico.faces).tolist(), fmt)
    ours = read_ply(str(path))
    theirs = trimesh.load(str(path), process=False)
    np.testing.assert_array_equal(ours.vertices, np.asarray(theirs.vertices, np.float64))
    np.testing.assert_array_equal(ours.indices.reshape(-1, 3), np.asarray(theirs.faces))
    assert load_scene(str(path)).areas.sum() == pytest.approx(theirs.area, rel=1e-12)


def test_binary_quads_take_the_one_pass_read(tmp_path):
    # every face a convex quad: the fixed-length read, and two triangles per quad
    n = 50
    x = np.arange(n + 1, dtype=float)
    v = np.array([[a, b, 0.0] for b in (0.0, 1.0) for a in x])
    faces = [[i, i + 1, n + 2 + i, n + 1 + i] for i in range(n)]
    path = write_ply(tmp_path / "strip.ply", v, faces, "binary_little_endian")
    poly = read_ply(str(path))
    assert poly.counts.tolist() == [4] * n and poly.unit == "face"
    scene = load_scene(str(path))
    assert scene.num_triangles == 2 * n and scene.areas.sum() == pytest.approx(float(n), rel=1e-12)


def test_a_bent_ply_face_is_named_by_its_place(tmp_path):
    # (OFF: the keyword, a comment, the counts and four vertices come first: the face is line 8)
    v = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 3], [0, 10, 0]], float)
    with pytest.warns(WavepathsWarning, match=r"not planar .* at face 1"):
        load_scene(str(write_ply(tmp_path / "bent.ply", v, [[0, 1, 2, 3]], "binary_little_endian")))
    with pytest.warns(WavepathsWarning, match=r"not planar .* at line 8"):
        load_scene(str(write_off(tmp_path / "bent.off", v, [[0, 1, 2, 3]])))


@pytest.mark.parametrize("fmt", ENCODINGS)
def test_bad_ply_files_give_one_clear_error(tmp_path, fmt):
    v = polygon_3d(L_SHAPE)
    with pytest.raises(SceneError, match=r"names vertex 6; the file has 6 vertices") as info:
        load_scene(str(write_ply(tmp_path / "oob.ply", v, [[0, 1, 2], [3, 4, 6]], fmt)))
    # (ASCII: 10 header lines and 6 vertices before the faces; the second face is line 18)
    assert ("line 18" if fmt == "ascii" else "face 2") in str(info.value)
    with pytest.raises(SceneError, match="at least 3 vertices"):
        read_ply(str(write_ply(tmp_path / "two.ply", v, [[0, 1]], fmt)))
    good = write_ply(tmp_path / "cut.ply", v, [[0, 1, 2, 3, 4, 5]], fmt).read_bytes()
    (tmp_path / "cut.ply").write_bytes(good[:-6])
    with pytest.raises(SceneError, match=r"ends inside its 'face'|malformed 'face' record"):
        read_ply(str(tmp_path / "cut.ply"))


@pytest.mark.parametrize("content, message", [
    ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float32x x\nend_header\n0\n", "line 4: malformed PLY header"),
    ("ply\nformat binary_middle_endian 1.0\nend_header\n", "unknown PLY format"),
    ("plyx\n", "not a PLY file"),
    ("ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
     "needs a 'vertex' and a 'face' element"),
])
def test_bad_ply_headers(tmp_path, content, message):
    p = tmp_path / "h.ply"
    p.write_text(content)
    with pytest.raises(SceneError, match=message):
        load_scene(str(p))


@pytest.mark.parametrize("content, message", [
    ("OFF\n3 1 0\n0 0 0\n1 0 0\n", "ends before its 3 vertices and 1 faces"),
    ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2\n", "line 6: the face announces 4 vertices and gives 3"),
    ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n", "line 6: face names vertex 5"),
    ("OFX\n3 1 0\n", "not an OFF file"),
    ("OFF\nthree 1 0\n", "line 2: malformed counts"),
])
def test_bad_off_files(tmp_path, content, message):
    p = tmp_path / "b.off"
    p.write_text(content)
    with pytest.raises(SceneError, match=message):
        read_off(str(p))


def test_polygon_areas_match_the_shoelace_formula_on_random_star_polygons(tmp_path):
    # star-shaped polygons (concave, up to 40 vertices) in tilted planes: the triangles'
    # area is the polygon's, whatever vertex the file starts from
    rng = np.random.default_rng(11)
    for trial in range(10):
        k = int(rng.integers(5, 40))
        ang = np.sort(rng.uniform(0, 2 * np.pi, k))
        r = rng.uniform(2, 10, k)
        xy = np.column_stack([r * np.cos(ang), r * np.sin(ang)])
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        v = np.column_stack([xy, np.zeros(k)]) @ q.T + rng.normal(size=3) * 20
        order = list(np.roll(np.arange(k), -int(rng.integers(k))))
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            scene = load_scene(str(write_off(tmp_path / f"s{trial}.off", v, [order])))
        assert scene.areas.sum() == pytest.approx(abs(shoelace(xy)), rel=1e-9)


@pytest.mark.parametrize("suffix", [".ply", ".off"])
def test_a_measurement_mesh_from_a_polygon_file_covers_the_polygon(tmp_path, suffix):
    from wavepaths.coverage import MeshGrid

    from .test_mesh_files import inside

    order = [2, 3, 4, 5, 0, 1]  # trimesh's fan from here covers 400 m^2
    v = polygon_3d(L_SHAPE, 1.5)
    path = write_ply(tmp_path / "m.ply", v, [order]) if suffix == ".ply" else write_off(tmp_path / "m.off", v, [order])
    grid = MeshGrid.from_file(str(path))
    tri = grid.vertices[grid.faces]
    areas = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    assert areas.sum() == pytest.approx(175.0, rel=1e-12)
    assert inside(grid.cell_centers()[:, :2], L_SHAPE).all()


@pytest.mark.parametrize("name", ["simple_street_canyon", "etoile"])
def test_sionna_scene_meshes_read_as_trimesh_reads_them(name):
    # Sionna RT's own binary PLY files (normals, texture coordinates): every vertex and face
    # as trimesh reads them (checked on munich's 2,367 files too, outside the suite)
    import glob
    import os

    from wavepaths.scene.loaders import sionna_scene_file

    xml = sionna_scene_file(name)
    if xml is None:
        pytest.skip("sionna-rt is not installed (pip install 'wavepaths[sionna]')")
    files = sorted(glob.glob(os.path.join(os.path.dirname(xml), "meshes", "*.ply")))
    assert files
    for path in files:
        ours, theirs = read_ply(path), trimesh.load(path, process=False)
        np.testing.assert_array_equal(ours.vertices, np.asarray(theirs.vertices, np.float64), err_msg=path)
        np.testing.assert_array_equal(ours.indices.reshape(-1, 3), np.asarray(theirs.faces), err_msg=path)


@pytest.mark.parametrize("suffix", [".ply", ".off"])
def test_a_byte_order_mark_is_read_past(tmp_path, suffix):
    # (some Windows tools write one; trimesh read such files, so they must keep loading)
    v = polygon_3d(L_SHAPE)
    path = write_ply(tmp_path / "m.ply", v, [list(range(6))]) if suffix == ".ply" else write_off(tmp_path / "m.off", v, [list(range(6))])
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    assert load_scene(str(path)).areas.sum() == pytest.approx(175.0, rel=1e-12)
