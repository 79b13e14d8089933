"""Loading scenes: built-in names, Mitsuba XML, and meshes through trimesh.

Two corrections to what trimesh returns for plain mesh files (docs/scenes.md):

* OBJ faces of four or more vertices: trimesh splits every face into a fan from its first
  vertex, which covers area outside a concave face (an L-shaped roof gains the square
  that closes the L). Faces whose fan would leave the face are split by ear clipping in
  the face's plane instead (:mod:`wavepaths.scene.obj_faces`); faces that are not planar
  are split too, with a warning. The XML reader keeps the fans, since Mitsuba 3 (and so
  Sionna RT) makes them, and warns about concave faces.
* glTF/GLB files are +Y up (glTF 2.0 specification); wavepaths, like Mitsuba and Sionna
  RT scenes, is +Z up: their geometry is rotated on load (``up_axis``).
"""

from __future__ import annotations

import io
import os
from typing import Literal

import numpy as np
import trimesh

from ..em.materials import PEC, Material
from ..errors import SceneError, WavepathsError
from .builtin import BUILTIN_SCENES, builtin_arrays
from .mitsuba import read_mitsuba_xml
from .model import Scene, build_scene
from .obj_faces import fixed_obj_text, read_obj_text
from .tolerances import SceneTolerances

MESH_FORMATS = (".obj", ".ply", ".stl", ".gltf", ".glb", ".off")
# Formats whose files are +Y up by their specification (glTF 2.0, section "Coordinate System and Units").
Y_UP_FORMATS = (".gltf", ".glb")
UP_AXES = ("auto", "y", "z")
# The rotation taking a +Y-up file to +Z up: (x, y, z) -> (x, -z, y) (+Y -> +Z, +Z -> -Y).
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])

UpAxis = Literal["auto", "y", "z"]


# ----------------------------------------------------------------------------- mesh files


def _trimesh_load(path: str, tolerances: SceneTolerances):
    """``trimesh.load(path, process=False)``, with the concave faces of an OBJ file fixed."""
    if os.path.splitext(path)[1].lower() == ".obj":
        fixed = fixed_obj_text(read_obj_text(path), path, tolerances)
        if fixed is not None:
            resolver = trimesh.resolvers.FilePathResolver(os.path.abspath(path))  # finds the .mtl as before
            return trimesh.load(io.StringIO(fixed), file_type="obj", resolver=resolver, process=False)
    return trimesh.load(path, process=False)




def _trimesh_parts(loaded, path: str) -> list[tuple[str, trimesh.Trimesh]]:
    """``(name, mesh in world coordinates)`` of every triangle mesh trimesh read."""
    if isinstance(loaded, trimesh.Trimesh):
        return [(os.path.splitext(os.path.basename(path))[0], loaded)]
    if not isinstance(loaded, trimesh.Scene):
        raise SceneError(f"{path}: the mesh has no faces (no triangle mesh found)")
    parts = []
    for node in loaded.graph.nodes_geometry:
        transform, geom_name = loaded.graph[node]
        geom = loaded.geometry[geom_name]
        if not isinstance(geom, trimesh.Trimesh):
            continue
        g = geom.copy()
        g.apply_transform(transform)
        parts.append((str(node), g))
    return parts


def _rotates_to_z_up(ext: str, up_axis: str) -> bool:
    """Whether a mesh file of extension ``ext`` is rotated from +Y up to +Z up."""
    return up_axis == "y" or (up_axis == "auto" and ext in Y_UP_FORMATS)


def _read_mesh_file(path: str, material: Material, tolerances: SceneTolerances | None = None,
                    up_axis: str = "auto"):
    try:
        loaded = _trimesh_load(path, tolerances or SceneTolerances())
    except Exception as exc:
        raise SceneError(f"{path}: cannot read mesh ({exc})") from None
    parts = _trimesh_parts(loaded, path)
    if not parts:
        raise SceneError(f"{path}: the mesh has no faces")
    verts, tris, tobj = [], [], []
    offset = 0
    for i, (_, g) in enumerate(parts):
        v = np.asarray(g.vertices, np.float64)
        f = np.asarray(g.faces, np.int64).reshape(-1, 3)
        verts.append(v)
        tris.append(f + offset)
        tobj.append(np.full(len(f), i))
        offset += len(v)
    tri = np.concatenate(tris)
    vertices = np.concatenate(verts)
    if _rotates_to_z_up(os.path.splitext(path)[1].lower(), up_axis):
        vertices = vertices @ Y_UP_TO_Z_UP.T
    return (vertices, tri, np.concatenate(tobj), np.zeros(len(tri), np.int64), tuple(n for n, _ in parts), (material,))


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


def load_scene(
    source: str,
    *,
    material: Material = PEC,
    tolerances: SceneTolerances | None = None,
    up_axis: UpAxis = "auto",
) -> Scene:
    """Load a scene from a built-in name or a file.

    Scenes are +Z up, in metres, as Mitsuba and Sionna RT scenes are.

    Parameters
    ----------
    source : str
        A built-in name (see :mod:`wavepaths.scene.builtin`), a Mitsuba XML file (as
        Sionna RT reads them), or a mesh file trimesh reads (OBJ, PLY, STL, glTF/GLB, OFF).
        OBJ faces of four or more vertices are split into triangles that cover exactly
        the face, concave faces included (ear clipping; trimesh alone fans them); a face
        that is not planar is split too, with a :class:`WavepathsWarning`. In XML files
        they are split as Mitsuba 3 splits them (a fan from the first vertex), with a
        warning for a concave face.
    material : Material
        Material of every triangle of a plain mesh file (default: perfect conductor);
        XML files carry their own materials.
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
    if source in BUILTIN_SCENES:
        _refuse_y_up(axis, source)
        arrays = builtin_arrays(source)
    else:
        if not os.path.exists(source):
            names = ", ".join(BUILTIN_SCENES)
            raise SceneError(f"{source}: no such file (and not a built-in scene: {names})")
        ext = os.path.splitext(source)[1].lower()
        if ext == ".xml":
            _refuse_y_up(axis, source)
            arrays = read_mitsuba_xml(source)
        elif ext in MESH_FORMATS:
            arrays = _read_mesh_file(source, material, tolerances, axis)
        else:
            raise SceneError(f"{source}: unknown format '{ext}' (expected .xml or one of {', '.join(MESH_FORMATS)})")
    v, t, o, m, names, mats = arrays
    return build_scene(v, t, o, m, names, mats, source=source, tolerances=tolerances)
