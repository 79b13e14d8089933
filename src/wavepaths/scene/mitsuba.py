"""Mitsuba 3 XML scene files, as Sionna RT writes and reads them.

Reading follows Mitsuba 3.9's parser (``src/core/parser.cpp``) and Sionna RT 2.2's
preprocessing (``sionna/rt/scene_utils.py``, ``scene.py``) for what carries geometry and
materials; docs/scenes.md lists what is read:

* ``<shape type="ply|obj|stl">`` with a ``filename``, ``rectangle`` and ``cube``, with a
  ``<transform name="to_world">`` of ``matrix``, ``translate``, ``rotate``, ``scale``
  applied in document order (``rotate`` with Mitsuba's formula, see :func:`_rotation`);
* ``<include filename=...>`` (the included file's shapes, materials and defaults join the
  scene; ids are shared, cycles are refused), ``<path value=...>`` (an extra folder to
  look for files in) and ``<alias id=... as=...>``;
* ``<default name=... value=...>`` parameters, substituted wherever ``$name`` occurs in an
  attribute (longest name first, ``\\$`` escapes a dollar, an undefined ``$name`` is an
  error), as Mitsuba does;
* radio materials: ``itu-radio-material``, ``radio-material``, ``absorber-radio-material``,
  and any bsdf of the main file whose id is ``mat-itu_<type>`` / ``itu_<type>`` (Sionna's
  legacy naming), referenced by ``<ref>`` or nested, possibly inside a ``twosided`` bsdf.

Elements that carry no geometry for a radio scene (sensors, emitters, integrators, ...)
are skipped; any other element is an error, so that no geometry is dropped silently.
Object names are shape ids without a leading ``mesh-``, as in Sionna RT; two shapes with
the same name are refused, as Sionna RT refuses them.

Writing: :mod:`wavepaths.scene.mitsuba_writer` (one binary PLY per object and material and
an XML file that both engines load).
"""

from __future__ import annotations

import dataclasses
import os
import re
import warnings
import xml.etree.ElementTree as ET
from typing import Iterable

import numpy as np
import trimesh

from ..em.materials import ITU_MATERIALS, Material, material_from_sionna
from ..errors import SceneError, WavepathsError
from .model import WavepathsWarning
from .obj_reader import concave_obj_faces
from .precision import float32_reach

_RADIO_BSDFS = ("itu-radio-material", "radio-material", "absorber-radio-material")
# Mitsuba objects that carry no geometry or radio material: read past, not an error.
_SKIPPED_OBJECTS = frozenset(
    {"integrator", "sensor", "emitter", "film", "sampler", "rfilter", "texture", "medium",
     "phase", "volume", "field"}
)
# Properties of the <scene> object itself (Mitsuba accepts them; none is geometry).
_SCENE_PROPERTIES = frozenset(
    {"boolean", "integer", "float", "string", "point", "vector", "spectrum", "rgb", "transform"}
)
_OBJECT_TAGS = _SKIPPED_OBJECTS | {"shape", "bsdf", "spectrum"}
# Guard against absurd nesting (cycles are caught exactly); Mitsuba has such a limit too.
_MAX_INCLUDE_DEPTH = 15


def _desc(elem: ET.Element) -> str:
    """``<shape type="ply" id="mesh-a">``: an element, for messages."""
    attrs = "".join(f' {k}="{elem.get(k)}"' for k in ("type", "id", "name") if elem.get(k) is not None)
    return f"<{elem.tag}{attrs}>"


@dataclasses.dataclass
class _Source:
    """One XML file being read: its path and the folders its relative file names search."""

    path: str
    dirs: list[str]
    main: bool  # the file passed to load_scene (Sionna's legacy material ids apply only there)


@dataclasses.dataclass
class _Reader:
    """What the files read so far define: parameters, ids, shapes (in document order)."""

    params: list[tuple[str, str]] = dataclasses.field(default_factory=list)  # ("$name", value), longest first
    ids: dict[str, tuple[ET.Element, _Source]] = dataclasses.field(default_factory=dict)
    shapes: list[tuple[ET.Element, _Source]] = dataclasses.field(default_factory=list)
    top_bsdfs: set[int] = dataclasses.field(default_factory=set)  # id() of the bsdfs directly in <scene>
    chain: list[str] = dataclasses.field(default_factory=list)  # files being read, outermost first


# ----------------------------------------------------------------------------- parameters


def _substitute(value: str, params: list[tuple[str, str]], where: str, elem: ET.Element) -> str:
    """Replace every ``$name`` in ``value`` (Mitsuba's ``substitute_parameters``)."""
    if "$" not in value:
        return value
    for key, repl in params:  # longest key first, so that $ab is not read as $a + "b"
        pos = value.find(key)
        while pos != -1:
            if pos > 0 and value[pos - 1] == "\\":
                pos = value.find(key, pos + len(key))
                continue
            value = value[:pos] + repl + value[pos + len(key):]
            pos = value.find(key, pos + len(repl))
    undefined = re.search(r"(?<!\\)\$(\w*)", value)
    if undefined:
        raise SceneError(f"{where}: {_desc(elem)}: undefined parameter ${undefined.group(1)} (no <default> defines it)")
    return value.replace("\\$", "$")


def _add_default(elem: ET.Element, reader: _Reader, where: str) -> None:
    name, value = elem.get("name"), elem.get("value")
    if not name or value is None:
        raise SceneError(f"{where}: {_desc(elem)} needs a non-empty name and a value")
    key = "$" + name
    if any(k == key for k, _ in reader.params):
        return  # the first definition wins (Mitsuba: parameters given to the loader, then the first <default>)
    at = next((i for i, (k, _) in enumerate(reader.params) if len(k) < len(key)), len(reader.params))
    reader.params.insert(at, (key, value))


def _prepare(elem: ET.Element, reader: _Reader, src: _Source) -> None:
    """Substitute parameters into ``elem`` and its descendants in document order, register
    their ``<default>``s and object ids."""
    for k, v in elem.attrib.items():
        elem.set(k, _substitute(v, reader.params, src.path, elem))
    if elem.tag == "default":
        _add_default(elem, reader, src.path)
    elif elem.tag in ("include", "path", "alias"):
        raise SceneError(f"{src.path}: {_desc(elem)} is only read directly inside <scene>")
    elif elem.tag in _OBJECT_TAGS and elem.get("id"):
        ident = elem.get("id")
        if ident in reader.ids:
            first = reader.ids[ident][1].path
            raise SceneError(f"{src.path}: {_desc(elem)}: duplicate id '{ident}' (first defined in {first})")
        reader.ids[ident] = (elem, src)
    for child in elem:
        _prepare(child, reader, src)


# ----------------------------------------------------------------------------- numbers


def _number(text: str, where: str, elem: ET.Element) -> float:
    try:
        return float(text)
    except ValueError:
        raise SceneError(f"{where}: {_desc(elem)}: cannot read '{text}' as a number") from None


def _numbers(text: str, where: str, elem: ET.Element) -> list[float]:
    return [_number(x, where, elem) for x in text.replace(",", " ").split()]


def _xyz(attr: dict[str, str], default: float, where: str, elem: ET.Element) -> np.ndarray:
    """The vector of a translate/scale/rotate: ``value`` (1 or 3 numbers) or ``x``, ``y``, ``z``."""
    if "value" in attr:
        if any(c in attr for c in "xyz"):
            raise SceneError(f"{where}: {_desc(elem)}: give either value or x/y/z, not both")
        v = _numbers(attr["value"], where, elem)
        if len(v) not in (1, 3):
            raise SceneError(f"{where}: {_desc(elem)}: value must hold 1 or 3 numbers, got {len(v)}")
        return np.array(v * 3 if len(v) == 1 else v, dtype=float)
    return np.array([_number(attr[c], where, elem) if c in attr else default for c in "xyz"], dtype=float)


def _props(elem: ET.Element, where: str) -> dict:
    """The named properties (``<float name=... value=...>`` ...) directly inside ``elem``."""
    out: dict = {}
    for child in elem:
        name = child.get("name")
        if name is None or "value" not in child.attrib:
            continue
        raw = child.get("value", "")
        if child.tag == "float":
            out[name] = _number(raw, where, child)
        elif child.tag == "integer":
            try:
                out[name] = int(raw)
            except ValueError:
                raise SceneError(f"{where}: {_desc(child)}: cannot read '{raw}' as an integer") from None
        elif child.tag == "boolean":
            if raw.lower() not in ("true", "false"):
                raise SceneError(f"{where}: {_desc(child)}: a boolean is 'true' or 'false', got '{raw}'")
            out[name] = raw.lower() == "true"
        else:
            out[name] = raw
    return out


# ----------------------------------------------------------------------------- transforms


def _rotation(axis: np.ndarray, angle_deg: float) -> np.ndarray:
    """Mitsuba's ``Transform4f::rotate`` (drjit ``rotate``): ``cos a I + sin a [u]_x +
    (1 - cos a) u u^T`` with the axis ``u`` as given, *not* normalised.

    For a unit axis this is Rodrigues' rotation; for another axis it is what Mitsuba 3.9
    builds (a rotation only up to scaling and shear), checked against
    ``mi.ScalarTransform4f().rotate([1, 1, 0], 45)``.
    """
    a = np.deg2rad(angle_deg)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    r = np.eye(4)
    r[:3, :3] = np.cos(a) * np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * np.outer(axis, axis)
    return r


def _transform(elem: ET.Element | None, where: str) -> np.ndarray:
    """The 4x4 matrix of a ``<transform>``, operations applied in document order."""
    m = np.eye(4)
    if elem is None:
        return m
    for op in elem:
        attr = dict(op.attrib)
        if op.tag == "matrix":
            vals = _numbers(attr.get("value", ""), where, op)
            if len(vals) not in (9, 16):
                raise SceneError(f"{where}: {_desc(op)}: a matrix has 9 or 16 values, got {len(vals)}")
            t = np.eye(4)
            n = 4 if len(vals) == 16 else 3
            t[:n, :n] = np.array(vals).reshape(n, n)
        elif op.tag == "translate":
            t = np.eye(4)
            t[:3, 3] = _xyz(attr, 0.0, where, op)
        elif op.tag == "scale":
            t = np.diag([*_xyz(attr, 1.0, where, op), 1.0])
        elif op.tag == "rotate":
            axis = _xyz(attr, 0.0, where, op)
            if "angle" not in attr:
                raise SceneError(f"{where}: {_desc(op)}: a rotation needs an angle (degrees)")
            if not np.any(axis):
                raise SceneError(f"{where}: {_desc(op)}: rotation axis cannot be zero")
            length = float(np.linalg.norm(axis))
            # Reported above 1e-4: the distortion of an axis typed to 4-5 digits is negligible.
            if abs(length - 1.0) > 1e-4:
                warnings.warn(
                    f"{where}: {_desc(op)}: the rotation axis {axis.tolist()} has length {length:.6g}, "
                    "not 1; like Mitsuba 3 (and so Sionna RT), wavepaths uses it as given, which "
                    "scales and shears the shape: normalise the axis for a pure rotation",
                    WavepathsWarning, stacklevel=4,
                )
            t = _rotation(axis, _number(attr["angle"], where, op))
        else:
            raise SceneError(f"{where}: {_desc(op)}: unsupported transform operation <{op.tag}> (matrix, translate, rotate, scale)")
        m = t @ m
    return m


# ----------------------------------------------------------------------------- materials


def _legacy_id(bsdf_id: str | None) -> bool:
    """True for Sionna's legacy ITU naming, an id ``mat-itu_<type>`` / ``itu_<type>``
    (``scene_utils.process_xml``), whatever the bsdf's type."""
    name = (bsdf_id or "").removeprefix("mat-")
    return name.startswith(("itu_", "itu-"))


def _bsdf_child(node: ET.Element, reader: _Reader) -> ET.Element | None:
    """The bsdf nested in ``node``: a ``<bsdf>`` child or a ``<ref>`` to one."""
    for child in node:
        if child.tag == "bsdf":
            return child
        if child.tag == "ref" and child.get("id") in reader.ids and reader.ids[child.get("id")][0].tag == "bsdf":
            return reader.ids[child.get("id")][0]
    return None


def _material_of(bsdf: ET.Element, src: _Source, reader: _Reader, outermost: bool) -> Material:
    """The radio material of a shape's bsdf (``src``: the file that defines it).

    ``outermost``: a bsdf directly inside <scene> or <shape>, the ones Sionna's preprocessing
    renames (``./bsdf`` and ``.//shape/bsdf``).
    """
    where = src.path
    outer_id = bsdf.get("id")
    stripped = (outer_id or "").removeprefix("mat-")
    if outermost and _legacy_id(outer_id):
        if not src.main:
            raise SceneError(
                f"{where}: {_desc(bsdf)}: Sionna RT turns 'mat-itu_<type>' ids into ITU materials only "
                "in the main scene file, not in an included one: use <bsdf type=\"itu-radio-material\">"
            )
        node = bsdf  # Sionna replaces the whole element: type and thickness of this element only
    else:
        if outermost and src.main and bsdf.get("type") != "itu-radio-material" and stripped in ITU_MATERIALS:
            raise SceneError(
                f"{where}: {_desc(bsdf)}: Sionna RT refuses an ITU material name as the id of a "
                f"non-ITU bsdf; name it 'mat-itu_{stripped}' or use <bsdf type=\"itu-radio-material\">"
            )
        node = bsdf
        while node.get("type") not in _RADIO_BSDFS:
            inner = _bsdf_child(node, reader)
            if inner is None:
                raise SceneError(
                    f"{where}: material '{outer_id or bsdf.get('type')}' is not a radio material (expected "
                    "<bsdf type=\"itu-radio-material\">, \"radio-material\" or \"absorber-radio-material\", "
                    "or an id 'mat-itu_<type>')"
                )
            node = inner
    try:
        return material_from_sionna(node.get("type"), _props(node, where), bsdf_id=node.get("id") or outer_id)
    except WavepathsError as exc:  # unknown ITU name, bad numbers
        raise SceneError(f"{where}: material '{outer_id or '?'}': {exc}") from None


def _shape_material(shape: ET.Element, src: _Source, reader: _Reader) -> tuple[ET.Element, _Source, bool]:
    """The bsdf of a shape: ``(element, its file, outermost)``."""
    found = []
    for child in shape:
        if child.tag == "ref":
            rid = child.get("id")
            if rid not in reader.ids:
                raise SceneError(f"{src.path}: shape '{shape.get('id')}' references an unknown material '{rid}'")
            target, tsrc = reader.ids[rid]
            if target.tag == "bsdf":
                found.append((target, tsrc, id(target) in reader.top_bsdfs))
        elif child.tag == "bsdf":
            found.append((child, src, True))
    if not found:
        raise SceneError(f"{src.path}: shape '{shape.get('id')}' has no material")
    if len(found) > 1:
        raise SceneError(f"{src.path}: shape '{shape.get('id')}' has {len(found)} materials (one bsdf per shape)")
    return found[0]


# ----------------------------------------------------------------------------- files


def _resolve(name: str, dirs: list[str]) -> str | None:
    """``name`` in the first of ``dirs`` that holds it (Mitsuba's FileResolver)."""
    if os.path.isabs(name):
        return name if os.path.exists(name) else None
    for d in dirs:
        p = os.path.join(d, name)
        if os.path.exists(p):
            return p
    return None


def _read_file(path: str, reader: _Reader, outer_dirs: list[str], main: bool) -> None:
    """Read the elements of one XML file (and the files it includes) into ``reader``."""
    real = os.path.realpath(path)
    if real in reader.chain:
        cycle = " -> ".join([*reader.chain[reader.chain.index(real):], real])
        raise SceneError(f"{path}: include cycle ({cycle})")
    if len(reader.chain) >= _MAX_INCLUDE_DEPTH:
        raise SceneError(f"{path}: includes nested deeper than {_MAX_INCLUDE_DEPTH} files")
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise SceneError(f"{path}: not a valid XML file ({exc})") from None
    except OSError as exc:
        raise SceneError(f"{path}: cannot read the file ({exc})") from None
    if root.tag != "scene" and (main or root.tag not in ("shape", "bsdf")):
        raise SceneError(f"{path}: the root element is <{root.tag}>, expected <scene>")
    src = _Source(path, [os.path.dirname(os.path.abspath(path)), *outer_dirs], main)
    reader.chain.append(real)
    for child in list(root) if root.tag == "scene" else [root]:
        tag = child.tag
        if not isinstance(tag, str):  # comments, processing instructions
            continue
        if tag in ("include", "path", "alias"):
            for k, v in child.attrib.items():
                child.set(k, _substitute(v, reader.params, path, child))
        if tag == "include":
            fname = child.get("filename")
            found = _resolve(fname, src.dirs) if fname else None
            if found is None:
                raise SceneError(f"{path}: {_desc(child)}: included file '{fname}' not found")
            _read_file(found, reader, src.dirs, main=False)
        elif tag == "path":
            folder = _resolve(child.get("value") or "", src.dirs)
            if folder is None or not os.path.isdir(folder):
                raise SceneError(f"{path}: <path value=\"{child.get('value')}\">: folder not found")
            src.dirs.insert(0, folder)
        elif tag == "alias":
            source, alias = child.get("id"), child.get("as")
            if source not in reader.ids or not alias or alias in reader.ids:
                raise SceneError(f"{path}: <alias id=\"{source}\" as=\"{alias}\">: the id must exist and the alias must not")
            reader.ids[alias] = reader.ids[source]
        elif tag in ("shape", "bsdf", "default") or tag in _SKIPPED_OBJECTS or tag in _SCENE_PROPERTIES:
            _prepare(child, reader, src)
            if tag == "shape":
                reader.shapes.append((child, src))
            elif tag == "bsdf":
                reader.top_bsdfs.add(id(child))
        else:
            raise SceneError(
                f"{path}: unsupported element {_desc(child)} in <scene> (wavepaths reads shape, bsdf, "
                "include, default, path, alias and skips sensors, emitters and other non-geometry objects)"
            )
    reader.chain.pop()


def _unit_rectangle() -> tuple[np.ndarray, np.ndarray]:
    return np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float), np.array([[0, 1, 2], [0, 2, 3]])


def _unit_cube() -> tuple[np.ndarray, np.ndarray]:
    box = trimesh.creation.box(extents=(2, 2, 2))
    return np.asarray(box.vertices, float), np.asarray(box.faces, np.int64)


def _warn_concave_faces(mesh_path: str, where: str, sid: str) -> None:
    """Warn (naming the file and a face) when an OBJ file of a shape has concave faces,
    whose fan triangles, in Mitsuba 3 as in wavepaths' XML reader, cover area outside them."""
    faces = concave_obj_faces(mesh_path)
    if not faces:
        return
    first = faces[0]
    warnings.warn(
        f"{where}: shape '{sid}': {mesh_path} has {len(faces)} concave face(s), e.g. line "
        f"{first.line}: '{first.statement}'. Mitsuba 3 (and so Sionna RT) splits every "
        "OBJ face into a fan from its first vertex and wavepaths keeps the same triangles in XML scenes, "
        f"so both engines see fan triangles covering {first.fan_area:.6g} m^2 where that face has "
        f"{first.area:.6g} m^2: split concave faces into triangles in the file",
        WavepathsWarning, stacklevel=5,
    )


def _shape_geometry(shape: ET.Element, src: _Source, sid: str,
                    reaches: list | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(v, 3)`` [m] in world coordinates and faces ``(f, 3)`` of one shape; a mesh
    file's float32 reach appended to ``reaches`` (see :func:`read_mitsuba_xml`)."""
    where = src.path
    stype = shape.get("type")
    if stype in ("ply", "obj", "stl"):
        fname = _props(shape, where).get("filename")
        if not fname:
            raise SceneError(f"{where}: shape '{sid}' has no filename")
        mesh_path = _resolve(fname, src.dirs)
        if mesh_path is None:
            raise SceneError(f"{where}: shape '{sid}' references a missing mesh file '{fname}'")
        try:
            # trimesh splits an OBJ face into a fan from its first vertex, as Mitsuba 3 does
            # (src/shapes/obj.cpp): both engines see the same triangles, even of a concave face.
            mesh = trimesh.load(mesh_path, force="mesh", process=False)
        except Exception as exc:
            raise SceneError(f"{mesh_path}: cannot read mesh ({exc})") from None
        if stype == "obj":
            _warn_concave_faces(mesh_path, where, sid)
        v = np.asarray(mesh.vertices, np.float64).reshape(-1, 3)
        f = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), np.int64).reshape(-1, 3)
        if len(f) == 0:
            raise SceneError(
                f"{where}: shape '{sid}': mesh file '{fname}' has no faces (a point cloud?); "
                "Sionna RT cannot load it either"
            )
        if reaches is not None:
            reaches.append((mesh_path, float32_reach(mesh_path, v)))
    elif stype == "rectangle":
        v, f = _unit_rectangle()
    elif stype == "cube":
        v, f = _unit_cube()
    else:
        raise SceneError(f"{where}: shape '{sid}' has unsupported type '{stype}' (ply, obj, stl, rectangle, cube)")
    m = _transform(shape.find("transform[@name='to_world']"), f"{where}: shape '{sid}'")
    return v @ m[:3, :3].T + m[:3, 3], f


def read_mitsuba_xml(path: str, reaches: list | None = None):
    """Parse a Mitsuba XML scene into raw arrays (see :func:`wavepaths.scene.loaders.load_scene`).

    ``reaches`` (optional) gets, for each mesh file, ``(file, largest coordinate magnitude
    as stored)`` if it stores float32 positions, else ``(file, 0.0)``
    (:func:`~wavepaths.scene.precision.float32_reach`: its own coordinates, before ``to_world``).

    Returns
    -------
    vertices, triangles, triangle_object, triangle_material, object_names, materials

    Raises
    ------
    SceneError
        Naming the file and the element: a missing or unreadable file, an unsupported
        element or shape type, a malformed number, an undefined ``$parameter``, an include
        cycle, duplicate ids or object names, a zero rotation axis, a mesh without faces, a
        material that is not a radio material.
    """
    reader = _Reader()
    _read_file(path, reader, [], main=True)
    if not reader.shapes:
        raise SceneError(f"{path}: the scene has no shapes")
    taken = {s.get("id").removeprefix("mesh-") for s, _ in reader.shapes if s.get("id")}
    owner: dict[str, str] = {}
    mat_cache: dict[int, Material] = {}
    materials: list[Material] = []
    objects: list[str] = []
    verts, tris, tobj, tmat = [], [], [], []
    offset = 0
    for k, (shape, src) in enumerate(reader.shapes):
        sid = shape.get("id")
        if sid:
            name = sid.removeprefix("mesh-")  # Sionna's SceneObject.shape_id_to_name
            if name in owner:
                raise SceneError(
                    f"{src.path}: shape '{sid}': the object name '{name}' is already used by shape "
                    f"'{owner[name]}' (Sionna RT drops a leading 'mesh-' and refuses duplicate names)"
                )
        else:
            name, j = f"shape_{k}", 1
            while name in taken:
                name, j = f"shape_{k}_{j}", j + 1
            taken.add(name)
            sid = name
        owner[name] = sid
        v, f = _shape_geometry(shape, src, sid, reaches)
        bsdf, bsrc, outermost = _shape_material(shape, src, reader)
        if id(bsdf) not in mat_cache:
            mat_cache[id(bsdf)] = _material_of(bsdf, bsrc, reader, outermost)
        mat = mat_cache[id(bsdf)]
        if mat not in materials:
            materials.append(mat)
        objects.append(name)
        verts.append(v)
        tris.append(f + offset)
        tobj.append(np.full(len(f), len(objects) - 1))
        tmat.append(np.full(len(f), materials.index(mat)))
        offset += len(v)
    return (np.concatenate(verts), np.concatenate(tris), np.concatenate(tobj), np.concatenate(tmat), tuple(objects), tuple(materials))


def iter_shape_files(path: str) -> Iterable[str]:
    """Mesh file names referenced by an XML scene (for packaging and checks)."""
    root = ET.parse(path).getroot()
    for shape in root.findall("shape"):
        for s in shape.findall("string"):
            if s.get("name") == "filename":
                yield s.get("value")
