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
  Mitsuba 3 make it, unless :func:`wavepaths.scene.obj_faces.fixed_obj_text` replaced it
  by its ear-clipping triangles first (a concave or bent face);
* vertex references follow the OBJ specification: ``v/vt/vn`` uses ``v``; a negative
  index counts back from the last vertex read so far.

Only the vertices the faces use are kept.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from .obj_faces import fixed_obj_text, read_obj_text
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
    """

    vertices: np.ndarray
    triangles: np.ndarray
    triangle_object: np.ndarray
    object_names: tuple[str, ...]
    triangle_material: np.ndarray
    material_names: tuple[str, ...]


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


def read_obj(path: str, tolerances: SceneTolerances | None = None) -> ObjMesh:
    """The triangles, objects and material names of the OBJ file ``path``.

    Raises
    ------
    SceneError
        A malformed vertex or face (its line named), or a file without faces.
    """
    text = read_obj_text(path)
    fixed = fixed_obj_text(text, path, tolerances or SceneTolerances())
    # a fixed face's triangles take several lines: line numbers then count the rewritten text's
    numbered = list(_statements((fixed if fixed is not None else text).split("\n")))
    has_o = any(s == "o" or s.startswith(("o ", "o\t")) for _, s in numbered)
    label = "o" if has_o else "g"
    stem = os.path.splitext(os.path.basename(path))[0]
    verts: list[tuple[float, float, float]] = []
    objects: dict[str, int] = {}
    materials: dict[str, int] = {}
    current_object = stem
    current_material = -1
    tris: list[tuple[int, int, int]] = []
    tri_object: list[int] = []
    tri_material: list[int] = []
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
            obj = objects.setdefault(current_object, len(objects))
            for k in range(1, len(refs) - 1):  # a fan from the first vertex (trimesh's, Mitsuba's)
                tris.append((refs[0], refs[k], refs[k + 1]))
                tri_object.append(obj)
                tri_material.append(current_material)
        elif key == label:
            current_object = rest.strip() or stem
        elif key == "usemtl":
            name = rest.strip()
            current_material = materials.setdefault(name, len(materials)) if name else -1
    if not tris:
        raise SceneError(f"{path}: the mesh has no faces")
    t = np.asarray(tris, dtype=np.int64)
    used, inverse = np.unique(t, return_inverse=True)
    v = np.asarray(verts, dtype=np.float64)[used]
    return ObjMesh(v, inverse.reshape(-1, 3).astype(np.int64), np.asarray(tri_object, np.int64),
                   tuple(objects), np.asarray(tri_material, np.int64), tuple(materials))
