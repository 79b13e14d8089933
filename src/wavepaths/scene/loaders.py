"""Loading scenes: built-in names, Mitsuba XML, and meshes through trimesh."""

from __future__ import annotations

import os

import numpy as np
import trimesh

from ..em.materials import PEC, Material
from ..errors import SceneError
from .builtin import BUILTIN_SCENES, builtin_arrays
from .mitsuba import read_mitsuba_xml
from .model import Scene, build_scene
from .tolerances import SceneTolerances

MESH_FORMATS = (".obj", ".ply", ".stl", ".gltf", ".glb", ".off")


def _read_mesh_file(path: str, material: Material):
    try:
        loaded = trimesh.load(path, process=False)
    except Exception as exc:
        raise SceneError(f"{path}: cannot read mesh ({exc})") from None
    if isinstance(loaded, trimesh.Trimesh):
        parts = [(os.path.splitext(os.path.basename(path))[0], loaded)]
    elif isinstance(loaded, trimesh.Scene):
        parts = []
        for node in loaded.graph.nodes_geometry:
            transform, geom_name = loaded.graph[node]
            geom = loaded.geometry[geom_name]
            if not isinstance(geom, trimesh.Trimesh):
                continue
            g = geom.copy()
            g.apply_transform(transform)
            parts.append((str(node), g))
    else:
        raise SceneError(f"{path}: the mesh has no faces (no triangle mesh found)")
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
    return (np.concatenate(verts), tri, np.concatenate(tobj), np.zeros(len(tri), np.int64), tuple(n for n, _ in parts), (material,))


def load_scene(
    source: str,
    *,
    material: Material = PEC,
    tolerances: SceneTolerances | None = None,
) -> Scene:
    """Load a scene from a built-in name or a file.

    Parameters
    ----------
    source : str
        A built-in name (see :mod:`wavepaths.scene.builtin`), a Mitsuba XML file (as
        Sionna RT reads them), or a mesh file trimesh reads (OBJ, PLY, STL, glTF/GLB).
    material : Material
        Material of every triangle of a plain mesh file (default: perfect conductor);
        XML files carry their own materials.
    tolerances : SceneTolerances, optional

    Raises
    ------
    SceneError
        A missing file, an unknown format, a mesh with no faces, non-finite
        coordinates; in an XML file also a missing mesh or included file, an unknown
        material or element, a malformed number, an undefined ``$parameter``, an include
        cycle, two shapes with the same name (see docs/scenes.md).
    """
    if source in BUILTIN_SCENES:
        arrays = builtin_arrays(source)
    else:
        if not os.path.exists(source):
            names = ", ".join(BUILTIN_SCENES)
            raise SceneError(f"{source}: no such file (and not a built-in scene: {names})")
        ext = os.path.splitext(source)[1].lower()
        if ext == ".xml":
            arrays = read_mitsuba_xml(source)
        elif ext in MESH_FORMATS:
            arrays = _read_mesh_file(source, material)
        else:
            raise SceneError(f"{source}: unknown format '{ext}' (expected .xml or one of {', '.join(MESH_FORMATS)})")
    v, t, o, m, names, mats = arrays
    return build_scene(v, t, o, m, names, mats, source=source, tolerances=tolerances)
