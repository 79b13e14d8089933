"""Reading OBJ files: vertices, triangles, objects and material names.

trimesh reads an OBJ file's geometry well but not its labels: without a ``.mtl`` file it
drops the ``usemtl`` names, and it merges or misnames ``o`` objects (a ground and a box,
each with its ``usemtl``, came out as ``ground`` with the box's 12 triangles and
``ground_1`` with the ground's 2). This reader keeps the labels:

* objects are the file's ``o`` statements; a file without any takes its ``g`` statements;
  triangles before the first such statement, or in a file with neither, belong to an
  object named after the file. Statements with the same name are one object;
* each face carries the name of the last ``usemtl`` before it (or none);
* a face of four or more vertices becomes a fan from its first vertex, as trimesh and
  Mitsuba 3 make it, unless the fan would leave it (a concave face) or have a flat
  triangle: it is then split by ear clipping in its plane
  (:func:`wavepaths.scene.obj_faces.triangulate_polygon`). Faces farther than
  ``plane_distance`` (of the file's diagonal) from their mean plane, and faces that are not
  simple polygons, are named in a warning (their line and statement);
* vertex references follow the OBJ specification: ``v/vt/vn`` uses ``v``; a negative
  index counts back from the last vertex read so far.

Only the vertices the faces use are kept.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from .model import WavepathsWarning, external_stacklevel
from .ply_off_reader import PolygonFile
from .obj_faces import fan_doubled_areas, fan_is_valid, polygon_planes, triangulate_polygon
from .tolerances import SceneTolerances


@dataclass(frozen=True)
class ObjMesh:
    """The triangles of an OBJ file with their labels.

    Attributes
    ----------
    vertices : (v, 3) float64
        Positions [file units] of the vertices the faces use.
    triangles : (f, 3) int64
        Vertex indices, in the file's face order.
    triangle_object : (f,) int64
        Index into ``object_names``.
    object_names : tuple of str
    triangle_material : (f,) int64
        Index into ``material_names``; -1 for a face with no ``usemtl`` before it.
    material_names : tuple of str
        The ``usemtl`` names, in order of first use.
    concave : tuple of ConcaveFace
        The faces whose fan from the first vertex leaves them, in file order.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    triangle_object: np.ndarray
    object_names: tuple[str, ...]
    triangle_material: np.ndarray
    material_names: tuple[str, ...]
    concave: tuple["ConcaveFace", ...] = ()


@dataclass(frozen=True)
class ConcaveFace:
    """An OBJ face whose fan from its first vertex leaves it.

    Attributes
    ----------
    line : int
        Line number (1-based) of its ``f`` statement.
    statement : str
        The statement (shortened).
    area : float
        Area of the face [m^2].
    fan_area : float
        Total area of its fan triangles [m^2], each counted positive, as a mesh counts them.
    """

    line: int
    statement: str
    area: float
    fan_area: float


def read_obj_text(path: str) -> str:
    """The text of an OBJ file: UTF-8 (a byte-order mark dropped), else Latin-1.

    Exports from Windows CAD and GIS tools often carry cp1252 comments or names; Latin-1 reads
    every byte, and the geometry is ASCII either way. (trimesh's own guess needed the optional
    ``charset_normalizer`` and failed without it.)
    """
    with open(path, "rb") as fh:
        data = fh.read()
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    return text.replace("\r\n", "\n")


def _index(token: str, count: int, path: str, line: int) -> int:
    """The 0-based vertex index of a face's reference ``token`` (``v``, ``v/vt``, ``v//vn``...)."""
    head = token.split("/", 1)[0]
    try:
        i = int(head)
    except ValueError:
        raise SceneError(f"{path}, line {line}: face reference {token!r} is not an integer vertex index") from None
    j = i - 1 if i > 0 else count + i
    if i == 0 or not 0 <= j < count:
        raise SceneError(f"{path}, line {line}: face reference {token!r} names vertex {i}; "
                         f"{count} vertices are defined before it")
    return j


def _statements(lines: list[str]):
    """``(line number, statement)`` of every non-empty statement, comments removed and lines
    ending in a backslash joined to the next (numbered by their first line)."""
    carry, first = "", 0
    for number, raw in enumerate(lines, start=1):
        body = raw.rstrip("\r")
        if body.endswith("\\"):
            carry, first = carry + body[:-1] + " ", first or number
            continue
        s = (carry + body).split("#", 1)[0].strip()
        if s:
            yield (first or number), s
        carry, first = "", 0


def _split_faces(path: str, verts: np.ndarray, faces: list[list[int]], lines: list[int], statements,
                 tolerances: SceneTolerances, warn: bool, unit: str = "line") -> tuple[list[np.ndarray], list[ConcaveFace]]:
    """Triangles ``(t_i, 3)`` of vertex indices for each face (see the module docstring), and
    the concave faces (whose fan leaves them). ``lines[f]``: where face ``f`` is in the file
    (a ``unit``: line or face number); ``statements(f)``: its text, for messages."""
    out: list[np.ndarray] = [np.zeros((0, 3), np.int64)] * len(faces)
    concave: list[tuple[int, ConcaveFace]] = []
    by_count: dict[int, list[int]] = {}
    for f, refs in enumerate(faces):
        if len(refs) == 3:
            out[f] = np.asarray([refs], np.int64)
        else:
            by_count.setdefault(len(refs), []).append(f)
    if not by_count:
        return out, []
    finite_verts = verts[np.isfinite(verts).all(axis=1)]
    diagonal = float(np.linalg.norm(finite_verts.max(axis=0) - finite_verts.min(axis=0))) if len(finite_verts) else 0.0
    eps, flat = tolerances.weld * diagonal, tolerances.plane_distance * diagonal
    bent: list[tuple[float, int]] = []
    tangled: list[int] = []
    for k, fs in by_count.items():
        index = np.asarray([faces[f] for f in fs], np.int64)  # (m, k)
        fan = np.stack([index[:, :1].repeat(k - 2, axis=1), index[:, 1:-1], index[:, 2:]], axis=2)
        points = verts[index]
        finite = np.isfinite(points).all(axis=(1, 2))
        planes = polygon_planes(np.where(finite[:, None, None], points, 0.0), eps)
        valid = planes.valid & finite
        good = ~valid | fan_is_valid(planes.uv, eps)  # no area: the fan (the scene drops flat triangles)
        bent += [(float(planes.deviation[r]), fs[r]) for r in np.flatnonzero(valid & (planes.deviation > flat))]
        for r in np.flatnonzero(good):
            out[fs[r]] = fan[r]
        doubled, longest = fan_doubled_areas(planes.uv)
        for r in np.flatnonzero(valid & np.any(doubled < -eps * longest, axis=1)):  # the fan leaves the face
            concave.append((fs[r], ConcaveFace(lines[fs[r]], _short(statements(fs[r])), float(planes.area[r]),
                                               float(np.abs(doubled[r]).sum() / 2))))
        for r in np.flatnonzero(~good):
            f = fs[r]
            tris, clean = triangulate_polygon(planes.uv[r], eps)
            out[f] = index[r][tris]
            if not clean:
                tangled.append(f)
    if warn:
        _warn_bent_and_tangled(path, bent, tangled, flat, lines, statements, unit)
    return out, [c for _, c in sorted(concave, key=lambda fc: fc[0])]


def _short(statement: str, limit: int = 60) -> str:
    return statement if len(statement) <= limit else statement[: limit - 3] + "..."


def _warn_bent_and_tangled(path: str, bent: list[tuple[float, int]], tangled: list[int], flat: float,
                           lines: list[int], statements, unit: str = "line") -> None:
    if bent:
        dev, f = max(bent)
        warnings.warn(
            f"{path}: {len(bent)} face(s) of four or more vertices are not planar (up to {dev:.3g} m from their "
            f"mean plane, more than {flat:.3g} m, at {unit} {lines[f]}: {statements(f)[:60]!r}); wavepaths splits "
            "each into triangles (a fan from its first vertex, or ear clipping in its mean plane when the fan "
            "would leave the face), one of several surfaces these vertices bound: split such faces in the file",
            WavepathsWarning, stacklevel=external_stacklevel(),
        )
    if tangled:
        f = tangled[0]
        warnings.warn(
            f"{path}: {len(tangled)} face(s) are not simple polygons (edges crossing, e.g. {unit} {lines[f]}: "
            f"{statements(f)[:60]!r}); their triangles cover another region than intended",
            WavepathsWarning, stacklevel=external_stacklevel(),
        )


def read_obj(path: str, tolerances: SceneTolerances | None = None, warn: bool = True) -> ObjMesh:
    """The triangles, objects and material names of the OBJ file ``path``; ``warn``: about
    bent and self-intersecting faces.

    Raises
    ------
    SceneError
        A malformed vertex or face (its line named), or a file without faces.
    """
    text = read_obj_text(path)
    numbered = list(_statements(text.split("\n")))
    has_o = any(s == "o" or s.startswith(("o ", "o\t")) for _, s in numbered)
    label = "o" if has_o else "g"
    stem = os.path.splitext(os.path.basename(path))[0]
    verts: list[tuple[float, float, float]] = []
    objects: dict[str, int] = {}
    materials: dict[str, int] = {}
    current_object = stem
    current_material = -1
    faces: list[list[int]] = []
    face_object: list[int] = []
    face_material: list[int] = []
    face_line: list[int] = []
    face_text: list[str] = []
    for number, s in numbered:
        key, _, rest = s.replace("\t", " ").partition(" ")
        if key == "v":
            parts = rest.split()
            try:
                verts.append((float(parts[0]), float(parts[1]), float(parts[2])))
            except (ValueError, IndexError):
                raise SceneError(f"{path}, line {number}: malformed vertex {s!r}") from None
        elif key == "f":
            refs = [_index(t, len(verts), path, number) for t in rest.split()]
            if len(refs) < 3:
                raise SceneError(f"{path}, line {number}: a face needs at least 3 vertices, got {s!r}")
            faces.append(refs)
            face_object.append(objects.setdefault(current_object, len(objects)))
            face_material.append(current_material)
            face_line.append(number)
            face_text.append(s)
        elif key == label:
            current_object = rest.strip() or stem
        elif key == "usemtl":
            name = rest.strip()
            current_material = materials.setdefault(name, len(materials)) if name else -1
    if not faces:
        raise SceneError(f"{path}: the mesh has no faces")
    vertices = np.asarray(verts, dtype=np.float64).reshape(-1, 3)
    split, concave = _split_faces(path, vertices, faces, face_line, face_text.__getitem__,
                                  tolerances or SceneTolerances(), warn)
    counts = np.array([len(t) for t in split])
    t = np.concatenate(split)
    used, inverse = np.unique(t, return_inverse=True)
    return ObjMesh(vertices[used], inverse.reshape(-1, 3).astype(np.int64),
                   np.repeat(np.asarray(face_object, np.int64), counts), tuple(objects),
                   np.repeat(np.asarray(face_material, np.int64), counts), tuple(materials), tuple(concave))


def polygon_triangles(path: str, polygons: "PolygonFile", tolerances: SceneTolerances | None = None,
                      warn: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices, triangles)`` of the faces of a PLY or OFF file
    (:class:`~wavepaths.scene.ply_off_reader.PolygonFile`), split as OBJ faces are (a fan
    where it stays inside the face, ear clipping where it would not; bent and tangled faces
    named in a warning). Only the vertices the faces use are kept, in index order.
    """
    if np.all(polygons.counts == 3):
        t = polygons.indices.reshape(-1, 3)
    else:
        faces = polygons.faces()

        def describe(f: int) -> str:
            return f"{len(faces[f])} vertices: " + " ".join(map(str, faces[f]))

        split, _ = _split_faces(path, polygons.vertices, faces, polygons.places.tolist(), describe,
                                tolerances or SceneTolerances(), warn, polygons.unit)
        t = np.concatenate(split)
    used, inverse = np.unique(t, return_inverse=True)
    return polygons.vertices[used], inverse.reshape(-1, 3).astype(np.int64)


def concave_obj_faces(path: str, tolerances: SceneTolerances | None = None) -> list[ConcaveFace]:
    """The faces of an OBJ file that a fan from their first vertex triangulates wrongly.

    Mitsuba 3 splits every OBJ face so (``src/shapes/obj.cpp``), and so does trimesh: the
    fan triangles of these faces cover area outside them (concave faces), in file order.
    Read by :func:`read_obj` (no warnings of its own); a file it refuses has none listed
    (the caller reads the geometry and reports such a file).
    """
    try:
        return list(read_obj(path, tolerances, warn=False).concave)
    except SceneError:
        return []
