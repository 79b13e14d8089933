"""Mitsuba 3 XML scene files, as Sionna RT writes and reads them.

Reading: ``<shape type="ply">`` / ``"obj"`` / ``"stl"`` with a ``filename`` (relative to
the XML file), ``rectangle`` and ``cube`` shapes, ``<transform name="to_world">`` made of
``matrix``, ``translate``, ``rotate``, ``scale`` (applied in document order),
``<default>`` parameters substituted into ``$name`` values, and radio materials:
``<bsdf type="itu-radio-material">`` (string ``type``, float ``thickness``) or
``<bsdf type="radio-material">`` (floats ``relative_permittivity``, ``conductivity``,
``thickness``), referenced by ``<ref>`` or nested, possibly inside a ``twosided`` bsdf.

Writing: one binary PLY per object and an XML file that both engines load.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from typing import Iterable

import numpy as np
import trimesh

from ..em.materials import Material, material_from_sionna
from ..errors import SceneError

_RADIO_BSDFS = ("itu-radio-material", "radio-material")


def _floats(text: str) -> list[float]:
    return [float(x) for x in text.replace(",", " ").split()]


def _substitute(value: str, defaults: dict[str, str]) -> str:
    if value.startswith("$"):
        return defaults.get(value[1:], value)
    return value


def _props(elem: ET.Element, defaults: dict[str, str]) -> dict:
    out: dict = {}
    for child in elem:
        name = child.get("name")
        if name is None or "value" not in child.attrib:
            continue
        raw = _substitute(child.get("value", ""), defaults)
        if child.tag in ("float", "integer"):
            out[name] = float(raw)
        elif child.tag == "boolean":
            out[name] = raw.lower() == "true"
        else:
            out[name] = raw
    return out


def _rotation(axis: np.ndarray, angle_deg: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    a = np.deg2rad(angle_deg)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    r = np.eye(4)
    r[:3, :3] = np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * (k @ k)
    return r


def _transform(elem: ET.Element | None, defaults: dict[str, str], where: str) -> np.ndarray:
    m = np.eye(4)
    if elem is None:
        return m
    for op in elem:
        attr = {k: _substitute(v, defaults) for k, v in op.attrib.items()}
        if op.tag == "matrix":
            vals = _floats(attr["value"])
            t = np.array(vals).reshape(4, 4) if len(vals) == 16 else np.pad(np.array(vals).reshape(3, 3), ((0, 1), (0, 1)))
            if len(vals) == 9:
                t[3, 3] = 1.0
        elif op.tag == "translate":
            v = _floats(attr["value"]) if "value" in attr else [float(attr.get(c, 0)) for c in "xyz"]
            t = np.eye(4)
            t[:3, 3] = v
        elif op.tag == "scale":
            if "value" in attr:
                v = _floats(attr["value"])
                v = v * 3 if len(v) == 1 else v
            else:
                v = [float(attr.get(c, 1)) for c in "xyz"]
            t = np.diag([*v, 1.0])
        elif op.tag == "rotate":
            axis = _floats(attr["value"]) if "value" in attr else [float(attr.get(c, 0)) for c in "xyz"]
            t = _rotation(np.array(axis, dtype=float), float(attr.get("angle", 0)))
        else:
            raise SceneError(f"{where}: unsupported transform operation <{op.tag}>")
        m = t @ m
    return m


def _material_of(bsdf: ET.Element, defaults: dict[str, str], where: str) -> Material:
    node = bsdf
    while node.get("type") not in _RADIO_BSDFS:
        inner = node.find("bsdf")
        if inner is None:
            raise SceneError(
                f"{where}: material '{bsdf.get('id', bsdf.get('type'))}' is not a radio material "
                f"(expected <bsdf type=\"itu-radio-material\"> or \"radio-material\")"
            )
        node = inner
    try:
        mat = material_from_sionna(node.get("type"), _props(node, defaults))
    except Exception as exc:  # unknown ITU name, bad numbers
        raise SceneError(f"{where}: material '{bsdf.get('id', '?')}': {exc}") from None
    name = bsdf.get("id") or mat.name
    return mat if mat.name else Material(name=name, kind=mat.kind)


def _unit_rectangle() -> tuple[np.ndarray, np.ndarray]:
    return np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float), np.array([[0, 1, 2], [0, 2, 3]])


def _unit_cube() -> tuple[np.ndarray, np.ndarray]:
    box = trimesh.creation.box(extents=(2, 2, 2))
    return np.asarray(box.vertices, float), np.asarray(box.faces, np.int64)


def read_mitsuba_xml(path: str):
    """Parse a Mitsuba XML scene into raw arrays (see :func:`wavepaths.scene.loaders.load_scene`).

    Returns
    -------
    vertices, triangles, triangle_object, triangle_material, object_names, materials
    """
    where = path
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise SceneError(f"{where}: not a valid XML file ({exc})") from None
    if root.tag != "scene":
        raise SceneError(f"{where}: the root element is <{root.tag}>, expected <scene>")
    base = os.path.dirname(os.path.abspath(path))
    defaults = {d.get("name"): d.get("value") for d in root.findall("default")}
    named_bsdfs = {b.get("id"): b for b in root.findall("bsdf") if b.get("id")}
    mat_cache: dict[str, Material] = {}
    materials: list[Material] = []
    objects: list[str] = []
    verts, tris, tobj, tmat = [], [], [], []
    offset = 0
    for k, shape in enumerate(root.findall("shape")):
        stype = shape.get("type")
        sid = shape.get("id") or f"shape_{k}"
        props = _props(shape, defaults)
        if stype in ("ply", "obj", "stl"):
            fname = props.get("filename")
            if not fname:
                raise SceneError(f"{where}: shape '{sid}' has no filename")
            mesh_path = os.path.join(base, fname)
            if not os.path.exists(mesh_path):
                raise SceneError(f"{where}: shape '{sid}' references a missing mesh file '{fname}'")
            try:
                mesh = trimesh.load(mesh_path, force="mesh", process=False)
            except Exception as exc:
                raise SceneError(f"{mesh_path}: cannot read mesh ({exc})") from None
            v, f = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)
        elif stype == "rectangle":
            v, f = _unit_rectangle()
        elif stype == "cube":
            v, f = _unit_cube()
        else:
            raise SceneError(f"{where}: shape '{sid}' has unsupported type '{stype}' (ply, obj, stl, rectangle, cube)")
        m = _transform(shape.find("transform[@name='to_world']"), defaults, where)
        v = v @ m[:3, :3].T + m[:3, 3]
        # material: a <ref> to a named bsdf, or a nested <bsdf>
        ref = shape.find("ref")
        if ref is not None:
            rid = ref.get("id")
            if rid not in named_bsdfs:
                raise SceneError(f"{where}: shape '{sid}' references an unknown material '{rid}'")
            key = rid
            bsdf = named_bsdfs[rid]
        else:
            bsdf = shape.find("bsdf")
            if bsdf is None:
                raise SceneError(f"{where}: shape '{sid}' has no material")
            key = f"{sid}::inline"
        if key not in mat_cache:
            mat_cache[key] = _material_of(bsdf, defaults, where)
        mat = mat_cache[key]
        if mat not in materials:
            materials.append(mat)
        objects.append(sid.removeprefix("mesh-"))
        verts.append(v)
        tris.append(f + offset)
        tobj.append(np.full(len(f), len(objects) - 1))
        tmat.append(np.full(len(f), materials.index(mat)))
        offset += len(v)
    if not verts:
        raise SceneError(f"{where}: the scene has no shapes")
    return (np.concatenate(verts), np.concatenate(tris), np.concatenate(tobj), np.concatenate(tmat), tuple(objects), tuple(materials))


def _bsdf_xml(mat: Material, ident: str) -> ET.Element:
    if mat.kind == "itu":
        b = ET.Element("bsdf", type="itu-radio-material", id=ident)
        ET.SubElement(b, "string", name="type", value=mat.name)
    elif mat.kind == "pec":
        # Sionna RT has no perfect conductor: ITU metal (sigma = 1e7 S/m) is the closest
        b = ET.Element("bsdf", type="itu-radio-material", id=ident)
        ET.SubElement(b, "string", name="type", value="metal")
    else:
        b = ET.Element("bsdf", type="radio-material", id=ident)
        eps = mat.a if mat.kind == "custom" else 1.0
        sigma = mat.c if mat.kind == "custom" else 0.0
        ET.SubElement(b, "float", name="relative_permittivity", value=repr(float(eps)))
        ET.SubElement(b, "float", name="conductivity", value=repr(float(sigma)))
    ET.SubElement(b, "float", name="thickness", value=repr(float(mat.thickness_m)))
    return b


def write_mitsuba_xml(scene, path: str, mesh_dir: str = "meshes") -> list[str]:
    """Write ``scene`` as Mitsuba XML + one PLY per object, loadable by Sionna RT and wavepaths.

    Parameters
    ----------
    scene : Scene
    path : str
        The XML file to write; meshes go to ``<dirname(path)>/<mesh_dir>/<object>.ply``.

    Returns
    -------
    list of str
        The files written.
    """
    out_dir = os.path.dirname(os.path.abspath(path))
    os.makedirs(os.path.join(out_dir, mesh_dir), exist_ok=True)
    root = ET.Element("scene", version="2.1.0")
    ids = []
    for i, mat in enumerate(scene.materials):
        ident = f"mat-{i}-{mat.name}"
        ids.append(ident)
        root.append(_bsdf_xml(mat, ident))
    written = []
    for o, name in enumerate(scene.object_names):
        for m in np.unique(scene.triangle_material[scene.triangle_object == o]):
            sel = (scene.triangle_object == o) & (scene.triangle_material == m)
            used, faces = np.unique(scene.triangles[sel], return_inverse=True)
            mesh = trimesh.Trimesh(scene.vertices[used], faces.reshape(-1, 3), process=False)
            stem = name if (scene.triangle_material[scene.triangle_object == o] == m).all() else f"{name}_{m}"
            rel = f"{mesh_dir}/{stem}.ply"
            mesh.export(os.path.join(out_dir, rel), file_type="ply", encoding="binary")
            written.append(os.path.join(out_dir, rel))
            shape = ET.SubElement(root, "shape", type="ply", id=f"mesh-{stem}")
            ET.SubElement(shape, "string", name="filename", value=rel)
            ET.SubElement(shape, "boolean", name="face_normals", value="true")
            ET.SubElement(shape, "ref", id=ids[int(m)], name="bsdf")
    ET.indent(root)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
    written.insert(0, path)
    return written


def iter_shape_files(path: str) -> Iterable[str]:
    """Mesh file names referenced by an XML scene (for packaging and checks)."""
    root = ET.parse(path).getroot()
    for shape in root.findall("shape"):
        for s in shape.findall("string"):
            if s.get("name") == "filename":
                yield s.get("value")
