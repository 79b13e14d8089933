"""Writing a scene as Mitsuba 3 XML + PLY meshes that Sionna RT and wavepaths both load.

The reader is :mod:`wavepaths.scene.mitsuba`; a written scene reads back with the same
objects, names and materials (a PEC as ITU metal, Sionna RT having no perfect conductor).
"""

from __future__ import annotations

import collections
import os
import re
import warnings
import xml.etree.ElementTree as ET
from typing import TYPE_CHECKING

import numpy as np
import trimesh

from ..em.materials import ITU_MATERIALS, Material
from .mitsuba import _legacy_id
from .model import WavepathsWarning

if TYPE_CHECKING:  # pragma: no cover
    from .model import Scene


def _material_id(mat: Material, index: int, taken: set[str]) -> str:
    """A bsdf id for ``mat``: its name when Sionna RT reads that back as the same material
    (custom and absorber materials, whose name comes from the id), else ``mat-<i>-<name>``."""
    name = mat.name
    plain = (
        mat.kind in ("custom", "absorber")
        and name
        and name not in taken
        and not name.startswith("mesh-")  # shape ids
        and not _legacy_id(name)  # Sionna would read an ITU material
        and name.removeprefix("mat-") not in ITU_MATERIALS  # Sionna refuses these
    )
    ident = name if plain else f"mat-{index}-{name}"
    while ident in taken:
        ident = f"mat-{index}-{len(taken)}-{name}"
    taken.add(ident)
    return ident


def _bsdf_xml(mat: Material, ident: str) -> ET.Element:
    if mat.kind == "absorber":
        return ET.Element("bsdf", type="absorber-radio-material", id=ident)  # no properties in Sionna RT 2.2
    if mat.kind == "itu":
        b = ET.Element("bsdf", type="itu-radio-material", id=ident)
        ET.SubElement(b, "string", name="type", value=mat.name)
    elif mat.kind == "pec":
        # Sionna RT has no perfect conductor: ITU metal (sigma = 1e7 S/m) is the closest
        b = ET.Element("bsdf", type="itu-radio-material", id=ident)
        ET.SubElement(b, "string", name="type", value="metal")
    else:
        b = ET.Element("bsdf", type="radio-material", id=ident)
        ET.SubElement(b, "float", name="relative_permittivity", value=repr(float(mat.a)))
        ET.SubElement(b, "float", name="conductivity", value=repr(float(mat.c)))
    ET.SubElement(b, "float", name="thickness", value=repr(float(mat.thickness_m)))
    return b


def _local_origin(scene) -> np.ndarray | None:
    """Where to put the meshes' origin: ``None`` (the world's) when float32 keeps the scene's
    coordinates within a tenth of its weld tolerance, else the centre of its bounding box to
    the metre, which each shape's ``to_world`` translate then adds back in float64
    (:mod:`wavepaths.scene.precision`: a city in UTM coordinates would lose 0.3 m)."""
    from .precision import FLOAT32_ROUNDING, WARN_FRACTION

    weld = scene.length_tolerance(scene.tolerances.weld)
    if np.abs(scene.vertices).max() * FLOAT32_ROUNDING < WARN_FRACTION * weld:
        return None
    return np.round(0.5 * (scene.vertices.min(axis=0) + scene.vertices.max(axis=0)))


def _file_stem(name: str) -> str:
    """A portable file name part for an object name: no separators, no odd characters."""
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._")
    return stem[:60] or "object"


def _unique(name: str, taken: set[str]) -> str:
    out, j = name, 2
    while out in taken:
        out, j = f"{name}-{j}", j + 1
    taken.add(out)
    return out


def write_mitsuba_xml(scene: "Scene", path: str, mesh_dir: str = "meshes") -> list[str]:
    """Write ``scene`` as Mitsuba XML + one PLY per object, loadable by Sionna RT and wavepaths.

    Each object becomes a shape ``id="mesh-<name>"``, so that both engines read back its
    name; an object with several materials becomes one shape per material,
    ``<name>_<material index>``. Names that would repeat (two objects of the same name) get a
    suffix ``-2``, ``-3``, ... with a :class:`WavepathsWarning`, since Sionna RT refuses
    duplicate names. Mesh files are numbered and keep only portable characters of the name.
    The PLY files store float32 vertices: a scene far from the origin (projected
    coordinates) is written around the centre of its box instead, and each shape's
    ``to_world`` translate puts it back (wavepaths applies it in float64; Sionna RT, which
    computes in float32, rounds the sum as it would the coordinates).

    Parameters
    ----------
    scene : Scene
    path : str
        The XML file to write; meshes go to ``<dirname(path)>/<mesh_dir>/<k>-<name>.ply``.
    mesh_dir : str
        Folder of the meshes, relative to the XML file.

    Returns
    -------
    list of str
        The files written (the XML file first). Writing over an XML file of a scene removes
        the mesh files in ``mesh_dir`` that it used and this scene does not (no others).
    """
    out_dir = os.path.dirname(os.path.abspath(path))
    os.makedirs(os.path.join(out_dir, mesh_dir), exist_ok=True)
    before = _meshes_of(path, os.path.join(out_dir, mesh_dir))
    root = ET.Element("scene", version="2.1.0")
    taken_ids: set[str] = set()
    ids = []
    for i, mat in enumerate(scene.materials):
        ids.append(_material_id(mat, i, taken_ids))
        root.append(_bsdf_xml(mat, ids[-1]))
    parts = []  # (object, material)
    wanted = []  # shape name of each part
    for o, name in enumerate(scene.object_names):
        mats = np.unique(scene.triangle_material[scene.triangle_object == o])
        for m in mats:
            parts.append((o, int(m)))
            wanted.append(name if len(mats) == 1 else f"{name}_{m}")
    counts = collections.Counter(wanted)
    taken = {w for w, c in counts.items() if c == 1}
    names = [w if counts[w] == 1 else _unique(w, taken) for w in wanted]
    renamed = [(w, n) for w, n in zip(wanted, names) if w != n]
    if renamed:
        shown = ", ".join(f"{w!r} -> {n!r}" for w, n in renamed[:5])
        warnings.warn(
            f"{path}: {len(renamed)} object name(s) repeat and were made unique ({shown}"
            f"{', ...' if len(renamed) > 5 else ''}): Sionna RT refuses two objects of the same name",
            WavepathsWarning, stacklevel=2,
        )
    width = len(str(len(parts)))
    written = []
    origin = _local_origin(scene)
    for k, ((o, m), name) in enumerate(zip(parts, names)):
        sel = (scene.triangle_object == o) & (scene.triangle_material == m)
        used, faces = np.unique(scene.triangles[sel], return_inverse=True)
        local = scene.vertices[used] if origin is None else scene.vertices[used] - origin
        mesh = trimesh.Trimesh(local, faces.reshape(-1, 3), process=False)
        rel = f"{mesh_dir}/{k:0{width}d}-{_file_stem(name)}.ply"
        mesh.export(os.path.join(out_dir, rel), file_type="ply", encoding="binary")  # float32 vertices
        written.append(os.path.join(out_dir, rel))
        shape = ET.SubElement(root, "shape", type="ply", id=f"mesh-{name}")
        ET.SubElement(shape, "string", name="filename", value=rel)
        ET.SubElement(shape, "boolean", name="face_normals", value="true")
        if origin is not None:
            to_world = ET.SubElement(shape, "transform", name="to_world")
            ET.SubElement(to_world, "translate", **{a: repr(float(c)) for a, c in zip("xyz", origin)})
        ET.SubElement(shape, "ref", id=ids[m], name="bsdf")
    ET.indent(root)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
    for stale in before - {os.path.realpath(w) for w in written}:
        os.remove(stale)  # a mesh of the file this one replaces, which no shape uses now
    written.insert(0, path)
    return written


def _meshes_of(path: str, mesh_folder: str) -> set[str]:
    """The mesh files in ``mesh_folder`` that the XML file at ``path`` uses, when it exists and
    is a scene: :func:`write_mitsuba_xml` removes those it does not write again, so that a
    folder written twice holds only the second scene's meshes. Files outside the folder, and
    any file the old XML does not name, are never touched."""
    if not os.path.isfile(path):
        return set()
    try:
        old = ET.parse(path).getroot()
    except (ET.ParseError, OSError, UnicodeDecodeError):
        return set()
    if old.tag != "scene":
        return set()
    folder = os.path.realpath(mesh_folder)
    base = os.path.dirname(os.path.abspath(path))
    found = set()
    for shape in old.iter("shape"):
        for item in shape.findall("string"):
            if item.get("name") == "filename" and item.get("value"):
                f = os.path.realpath(os.path.join(base, item.get("value")))
                if os.path.dirname(f) == folder and f.endswith(".ply") and os.path.isfile(f):
                    found.add(f)
    return found
