"""Loading scenes: built-in names, Mitsuba XML, and meshes through trimesh.

Two corrections to what trimesh returns for plain mesh files (docs/scenes.md):

* OBJ, PLY and OFF faces of four or more vertices: trimesh splits every face into a fan
  from its first vertex, which covers area outside a concave face (an L-shaped roof gains
  the square that closes the L). These files are read here (:mod:`~wavepaths.scene.obj_reader`,
  :mod:`~wavepaths.scene.ply_off_reader`), and faces whose fan would leave the face are
  split by ear clipping in the face's plane instead (:mod:`wavepaths.scene.obj_faces`);
  faces that are not planar are split too, with a warning. The XML reader keeps the fans, since Mitsuba 3 (and so
  Sionna RT) makes them, and warns about concave faces.
* glTF/GLB files are +Y up (glTF 2.0 specification); wavepaths, like Mitsuba and Sionna
  RT scenes, is +Z up: their geometry is rotated on load (``up_axis``).
"""

from __future__ import annotations

import os
import re
import warnings
from collections.abc import Mapping
from typing import Literal

import numpy as np
import trimesh

from ..em.materials import PEC, Material, as_material, material_by_name
from ..errors import SceneError, WavepathsError
from .builtin import BUILTIN_SCENES, builtin_arrays
from .mitsuba import read_mitsuba_xml
from .model import Scene, WavepathsWarning, build_scene, external_stacklevel, scene_size
from .obj_reader import polygon_triangles, read_obj
from .ply_off_reader import read_off, read_ply
from .precision import float32_reach, warn_float32_coordinates
from .tolerances import SceneTolerances

MESH_FORMATS = (".obj", ".ply", ".stl", ".gltf", ".glb", ".off")
LARGE_SCENE_M = 100e3
"""A scene file whose extent (:func:`~wavepaths.scene.model.scene_size`) exceeds this [m]
is warned about: most likely in millimetres or centimetres (a 220 m street model in mm
spans 220 km), as wavepaths reads metres."""
# Formats whose files are +Y up by their specification (glTF 2.0, section "Coordinate System and Units").
Y_UP_FORMATS = (".gltf", ".glb")
UP_AXES = ("auto", "y", "z")
# The rotation taking a +Y-up file to +Z up: (x, y, z) -> (x, -z, y) (+Y -> +Z, +Z -> -Y).
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])

UpAxis = Literal["auto", "y", "z"]


# ----------------------------------------------------------------------------- mesh files


def _trimesh_parts(loaded, path: str) -> list[tuple[str, trimesh.Trimesh]]:
    """``(name, mesh in world coordinates)`` of every triangle mesh trimesh read."""
    if isinstance(loaded, trimesh.Trimesh):
        return [(os.path.splitext(os.path.basename(path))[0], loaded)]
    if not isinstance(loaded, trimesh.Scene):
        raise SceneError(f"{path}: the mesh has no faces (no triangle mesh found)")
    parts = []
    seen: dict[str, int] = {}
    for node in loaded.graph.nodes_geometry:
        transform, geom_name = loaded.graph[node]
        geom = loaded.geometry[geom_name]
        if not isinstance(geom, trimesh.Trimesh):
            continue
        g = geom.copy()
        g.apply_transform(transform)
        # trimesh names the nodes it makes for a mesh's primitives with a random hex suffix
        # ("house_1_ae99c6"): without it, and numbered in order where names repeat, object
        # names are the same from run to run
        name = re.sub(r"_[0-9a-f]{6}$", "", str(node))
        seen[name] = seen.get(name, 0) + 1
        parts.append((name if seen[name] == 1 else f"{name}_{seen[name]}", g))
    return parts


def _rotates_to_z_up(ext: str, up_axis: str) -> bool:
    """Whether a mesh file of extension ``ext`` is rotated from +Y up to +Z up."""
    return up_axis == "y" or (up_axis == "auto" and ext in Y_UP_FORMATS)


def _part_material_name(geom: trimesh.Trimesh) -> str | None:
    """The material name trimesh kept for a part (glTF materials, OBJ with its ``.mtl``), or None."""
    name = getattr(getattr(getattr(geom, "visual", None), "material", None), "name", None)
    return str(name) if name else None


def _resolve_materials(names: tuple[str, ...], default: Material,
                       materials: Mapping[str, Material | str] | None) -> tuple[list[Material], list[str]]:
    """The material of each of a file's material ``names``, and the names left to ``default``.

    ``materials`` (name -> Material or material name) first, then the names
    :func:`~wavepaths.em.materials.material_by_name` knows (``itu_concrete``, ``glass``, ``pec``...).
    """
    mapping = {str(k): as_material(v, f"materials[{k!r}]") for k, v in (materials or {}).items()}
    out, unknown = [], []
    for name in names:
        found = mapping.get(name) or material_by_name(name)
        if found is None:
            unknown.append(name)
        out.append(found or default)
    return out, unknown


def _warn_unknown_materials(path: str, unknown: list[str], default: Material) -> None:
    if unknown:
        warnings.warn(
            f"{path}: material name(s) {', '.join(repr(n) for n in unknown[:8])}{' ...' if len(unknown) > 8 else ''} "
            f"are no ITU-R P.2040 name, 'pec' or 'absorber': their triangles get the default material "
            f"{default.name!r}; map them with load_scene(..., materials={{name: material}})",
            WavepathsWarning, stacklevel=external_stacklevel(),
        )


def _used_materials(tmat: np.ndarray, table: list[Material]) -> tuple[np.ndarray, tuple[Material, ...]]:
    """``tmat`` re-indexed into the materials it uses, equal materials merged, in table order."""
    distinct: list[Material] = []
    remap = np.zeros(len(table), np.int64)
    present = set(np.unique(tmat).tolist())
    for i, m in enumerate(table):
        if i in present:
            if m not in distinct:
                distinct.append(m)
            remap[i] = distinct.index(m)
    return remap[tmat], tuple(distinct)


def _read_obj_file(path: str, material: Material, tolerances: SceneTolerances | None,
                   materials: Mapping[str, Material | str] | None):
    """Scene arrays of an OBJ file read by :func:`~wavepaths.scene.obj_reader.read_obj`:
    objects from its ``o`` (or ``g``) statements, materials from its ``usemtl`` names."""
    mesh = read_obj(path, tolerances)
    mats, unknown = _resolve_materials(mesh.material_names, material, materials)
    _warn_unknown_materials(path, unknown, material)
    tmat, table = _used_materials(mesh.triangle_material + 1, [material, *mats])  # index 0: no usemtl
    return mesh.vertices, mesh.triangles, mesh.triangle_object, tmat, mesh.object_names, table


def _read_polygon_file(path: str, ext: str, material: Material, tolerances: SceneTolerances | None):
    """Scene arrays of a PLY or OFF file (:mod:`wavepaths.scene.ply_off_reader`): one object
    named after the file, in ``material``."""
    polygons = read_ply(path) if ext == ".ply" else read_off(path)
    v, t = polygon_triangles(path, polygons, tolerances)
    stem = os.path.splitext(os.path.basename(path))[0]
    return v, t, np.zeros(len(t), np.int64), np.zeros(len(t), np.int64), (stem,), (material,)


def _read_mesh_file(path: str, material: Material, tolerances: SceneTolerances | None = None,
                    up_axis: str = "auto", materials: Mapping[str, Material | str] | None = None,
                    reaches: list | None = None):
    """Scene arrays of a mesh file; ``reaches`` (optional) gets ``(path, largest coordinate)``
    if the file stores float32 positions (:func:`~wavepaths.scene.precision.float32_reach`)."""
    ext = os.path.splitext(path)[1].lower()
    # the formats read here (their polygons split exactly), the others through trimesh below
    own = {".obj": lambda: _read_obj_file(path, material, tolerances, materials),
           ".ply": lambda: _read_polygon_file(path, ext, material, tolerances),
           ".off": lambda: _read_polygon_file(path, ext, material, tolerances)}
    if ext in own:
        try:
            v, t, o, m, names, table = own[ext]()
        except (SceneError, WavepathsError):
            raise
        except Exception as exc:
            raise SceneError(f"{path}: cannot read mesh ({exc})") from None
        if reaches is not None:
            reaches.append((path, float32_reach(path, v)))
        if _rotates_to_z_up(ext, up_axis):
            v = v @ Y_UP_TO_Z_UP.T
        return v, t, o, m, names, table
    try:
        loaded = trimesh.load(path, process=False)  # (OBJ files are read by obj_reader)
    except Exception as exc:
        raise SceneError(f"{path}: cannot read mesh ({exc})") from None
    parts = _trimesh_parts(loaded, path)
    if not parts:
        raise SceneError(f"{path}: the mesh has no faces")
    part_names = [_part_material_name(g) for _, g in parts]
    used = tuple(dict.fromkeys(n for n in part_names if n is not None))
    mats, unknown = _resolve_materials(used, material, materials)
    _warn_unknown_materials(path, unknown, material)
    index = {n: i + 1 for i, n in enumerate(used)}
    verts, tris, tobj, tmat = [], [], [], []
    offset = 0
    for i, (_, g) in enumerate(parts):
        v = np.asarray(g.vertices, np.float64)
        f = np.asarray(g.faces, np.int64).reshape(-1, 3)
        verts.append(v)
        tris.append(f + offset)
        tobj.append(np.full(len(f), i))
        tmat.append(np.full(len(f), index.get(part_names[i], 0)))
        offset += len(v)
    tri = np.concatenate(tris)
    vertices = np.concatenate(verts)
    if reaches is not None:
        reaches.append((path, float32_reach(path, vertices)))
    if _rotates_to_z_up(ext, up_axis):
        vertices = vertices @ Y_UP_TO_Z_UP.T
    tmat_all, table = _used_materials(np.concatenate(tmat), [material, *mats])
    return vertices, tri, np.concatenate(tobj), tmat_all, tuple(n for n, _ in parts), table


def _check_up_axis(up_axis: str) -> str:
    """``up_axis`` in lower case, or an error naming the accepted values."""
    axis = str(up_axis).lower()
    if axis not in UP_AXES:
        raise WavepathsError(f"up_axis must be one of {', '.join(repr(a) for a in UP_AXES)}, got {up_axis!r}")
    return axis


def _refuse_y_up(axis: str, source: str) -> None:
    """An XML or built-in scene is +Z up: ``up_axis="y"`` is an error there."""
    if axis == "y":
        raise SceneError(
            f"{source}: up_axis='y' applies to mesh files ({', '.join(MESH_FORMATS)}); Mitsuba XML scenes "
            "(as Sionna RT reads them) and built-in scenes are +Z up"
        )


def sionna_scene_file(name: str) -> str | None:
    """The Mitsuba XML file of Sionna RT's scene ``name`` (``simple_street_canyon``, ``etoile``,
    ``munich``...) when sionna-rt is installed, else None. Found in the package's files
    (``sionna/rt/scenes/<name>/<name>.xml``), without importing Sionna (no Dr.Jit start-up)."""
    import importlib.util

    if not name or os.sep in name or "/" in name or name.startswith("."):
        return None
    try:
        spec = importlib.util.find_spec("sionna")
    except (ImportError, ValueError):
        return None
    for root in (spec.submodule_search_locations or []) if spec else []:
        path = os.path.join(root, "rt", "scenes", name, f"{name}.xml")
        if os.path.isfile(path):
            return path
    return None


def load_scene(
    source: str,
    *,
    material: Material | str | None = None,
    tolerances: SceneTolerances | None = None,
    up_axis: UpAxis = "auto",
    materials: Mapping[str, Material | str] | None = None,
) -> Scene:
    """Load a scene from a built-in name or a file.

    Scenes are +Z up, in metres, as Mitsuba and Sionna RT scenes are.

    Parameters
    ----------
    source : str
        A built-in name (see :mod:`wavepaths.scene.builtin`), a Mitsuba XML file (as
        Sionna RT reads them), the name of one of Sionna RT's scenes when sionna-rt is
        installed (``simple_street_canyon``, ``etoile``, ``munich``: its XML file), or a
        mesh file (OBJ, PLY, STL, glTF/GLB, OFF).
        OBJ, PLY and OFF faces of four or more vertices are split into triangles that cover exactly
        the face, concave faces included (ear clipping; trimesh alone fans them); a face
        that is not planar is split too, with a :class:`WavepathsWarning`. In XML files
        they are split as Mitsuba 3 splits them (a fan from the first vertex), with a
        warning for a concave face.
    material : Material or str
        Material of the triangles of a plain mesh file that name no known material
        (default: perfect conductor): a :class:`Material` or a name, ``"pec"``,
        ``"absorber"`` or an ITU-R P.2040 name (``"concrete"``). XML files and built-in
        scenes carry their own materials: ``material`` and ``materials`` are ignored there,
        with a :class:`WavepathsWarning`.
    materials : mapping of str to Material or str, optional
        Materials of a mesh file's own material names (OBJ ``usemtl``, glTF materials).
        Names not in it that are ITU-R P.2040 names (bare or as Sionna writes them,
        ``itu_concrete``, ``mat-itu_concrete``), ``pec`` or ``absorber`` get that material;
        the others get ``material``, with a :class:`WavepathsWarning` naming them.
    tolerances : SceneTolerances, optional
    up_axis : {"auto", "y", "z"}
        The up axis of a mesh file. ``"auto"`` (default): +Y for glTF/GLB, whose
        specification is +Y up, +Z for the other formats. A +Y-up file is rotated to +Z up,
        ``(x, y, z) -> (x, -z, y)`` (a rotation: handedness and face orientation are kept).
        ``"z"`` keeps the file's coordinates as they are (a glTF file written +Z up);
        ``"y"`` rotates any mesh file (an OBJ exported +Y up). XML and built-in scenes
        are +Z up and accept ``"auto"`` and ``"z"`` only.

    Raises
    ------
    SceneError
        A missing file, an unknown format, a mesh with no faces, non-finite
        coordinates; in an XML file also a missing mesh or included file, an unknown
        material or element, a malformed number, an undefined ``$parameter``, an include
        cycle, two shapes with the same name (see docs/scenes.md).
    WavepathsError
        An unknown ``up_axis``.
    """
    axis = _check_up_axis(up_axis)
    given = material is not None
    material = PEC if material is None else as_material(material, "load_scene: `material`")
    if materials is not None and not isinstance(materials, Mapping):
        raise WavepathsError(f"load_scene: `materials` must be a mapping of names to materials, got {type(materials).__name__}")
    if (given or materials) and (source in BUILTIN_SCENES or source.lower().endswith(".xml")):
        warnings.warn(f"{source}: `material` and `materials` apply to mesh files; this scene's materials are its own",
                      WavepathsWarning, stacklevel=external_stacklevel())
    reaches: list[tuple[str, float]] = []  # float32 files and their largest coordinate
    if source in BUILTIN_SCENES:
        _refuse_y_up(axis, source)
        arrays = builtin_arrays(source)
    else:
        if not os.path.exists(source):
            sionna = sionna_scene_file(source)
            if sionna is None:
                names = ", ".join(BUILTIN_SCENES)
                raise SceneError(f"{source}: no such file (and not a built-in scene: {names}; nor, with sionna-rt "
                                 "installed, one of Sionna RT's scenes such as simple_street_canyon)")
            return load_scene(sionna, material=material if given else None, tolerances=tolerances,
                              up_axis=up_axis, materials=materials)
        if os.path.isdir(source):
            raise SceneError(f"{source}: is a directory, not a scene file (give an .xml file or one of "
                             f"{', '.join(MESH_FORMATS)})")
        ext = os.path.splitext(source)[1].lower()
        if ext == ".xml":
            _refuse_y_up(axis, source)
            arrays = read_mitsuba_xml(source, reaches)
        elif ext in MESH_FORMATS:
            arrays = _read_mesh_file(source, material, tolerances, axis, materials, reaches)
        else:
            raise SceneError(f"{source}: unknown format '{ext}' (expected .xml or one of {', '.join(MESH_FORMATS)})")
    v, t, o, m, names, mats = arrays
    warn_transparent_materials(source, o, m, names, mats)
    if source not in BUILTIN_SCENES:
        size = scene_size(v[np.unique(t)]) if len(t) else 0.0
        reaches = [r for r in reaches if r[1] > 0]
        if reaches:
            warn_float32_coordinates(source, reaches, (tolerances or SceneTolerances()).weld * (size or 1.0))
        if size > LARGE_SCENE_M:
            warnings.warn(f"{source}: the scene spans {size / 1e3:.4g} km; wavepaths reads coordinates in metres: "
                          "if the file is in millimetres or centimetres, scale it", WavepathsWarning,
                          stacklevel=external_stacklevel())
    return build_scene(v, t, o, m, names, mats, source=source, tolerances=tolerances)


def is_transparent(material: Material) -> bool:
    """Whether ``material`` is free space: relative permittivity 1 and conductivity 0 at
    every frequency (ITU-R P.2040's ``vacuum``, a custom ``air``).

    Parameters
    ----------
    material : Material

    Returns
    -------
    bool
    """
    return material.kind in ("itu", "custom") and material.a == 1.0 and material.b == 0.0 and material.c == 0.0


def warn_transparent_materials(source: str, triangle_object: np.ndarray, triangle_material: np.ndarray,
                               object_names, materials) -> None:
    """Warn about the objects whose faces are of a free-space material.

    wavepaths models no transmission: such a face still blocks every ray that meets it, it
    reflects nothing (its reflection coefficient is 0: no reflection is traced off it while
    ``TraceOptions.skip_absorbers`` is on, the default), and its edges still diffract (the UTD
    terms of the incident field do not depend on the material). The physics is left as it
    is; the warning names the objects.

    Parameters
    ----------
    source : str
        The scene's name or file, for the message.
    triangle_object, triangle_material : (t,) int arrays
        Each triangle's object and material index.
    object_names : sequence of str
    materials : sequence of Material
    """
    clear = [i for i, mat in enumerate(materials) if is_transparent(mat)]
    if not clear:
        return
    hit = np.isin(np.asarray(triangle_material), clear)
    if not hit.any():
        return
    objs = [str(object_names[i]) for i in np.unique(np.asarray(triangle_object)[hit])]
    mats = sorted({materials[i].name for i in clear})
    shown = ", ".join(objs[:8]) + (f" and {len(objs) - 8} more" if len(objs) > 8 else "")
    warnings.warn(
        f"{source}: object(s) {shown} have a free-space material ({', '.join(mats)}: permittivity 1, "
        "conductivity 0); wavepaths models no transmission, so their faces still block rays, reflect "
        "nothing and diffract at their edges. Remove these objects, or give them another material",
        WavepathsWarning, stacklevel=external_stacklevel(),
    )
