"""The scene: welded triangles with their objects and materials, grouped into polygons.

A :class:`Scene` is built once per scene file and shared, read-only, by every later
stage: the dihedra (:mod:`wavepaths.topology`), the ray caster
(:mod:`wavepaths.raycast`) and the path search. Geometry is float64 throughout.
"""

from __future__ import annotations

import functools
import threading
import warnings
from dataclasses import dataclass, field
from dataclasses import fields as dataclass_fields
from typing import TYPE_CHECKING, Callable, Hashable, TypeVar

import numpy as np

from ..em.materials import Material
from ..errors import SceneError, WavepathsError
from .mesh_topology import (EdgeIncidence, area_order, coplanar_components, edge_incidence, largest_per_label,
                            triangle_normals)
from .tolerances import SceneTolerances
from .weld import degenerate_triangles, weld_vertices

if TYPE_CHECKING:  # pragma: no cover
    from collections.abc import Mapping

    from ..raycast import RayCaster
    from .polygon_shapes import PolygonHulls
    from ..topology.dihedra import Dihedra


T = TypeVar("T")


class _ValueLocks:
    """One re-entrant lock per cached value of one scene, made on first use.

    A lock per value, not one per scene: a value's computation may run threads that need
    another value (never the same one, which would recurse). Pickled and deep-copied as a
    fresh set of locks (a shallow ``copy.copy`` of a scene shares them, and its values).
    """

    __slots__ = ("_guard", "_locks")

    def __init__(self) -> None:
        self._guard = threading.Lock()
        self._locks: dict = {}

    def __call__(self, key: Hashable) -> threading.RLock:
        with self._guard:
            lock = self._locks.get(key)
            if lock is None:
                lock = self._locks[key] = threading.RLock()
            return lock

    def __reduce__(self):
        return (_ValueLocks, ())


class scene_cached_property(functools.cached_property):
    """:func:`functools.cached_property` computed once per scene whatever the threads.

    Python 3.12 dropped ``cached_property``'s lock, so two tiles of a coverage map asking a
    fresh scene for its ray caster at once would each build one. Here the first computes it
    under the value's lock (:class:`_ValueLocks`) and the others wait for it; once kept, the
    value is read from the instance's ``__dict__`` without a lock, as ``cached_property``'s is.
    """

    def __get__(self, instance, owner=None):
        if instance is None:
            return self
        cache = instance.__dict__
        name = self.attrname
        try:
            return cache[name]
        except KeyError:
            pass
        with instance._value_locks(name):
            if name not in cache:
                cache[name] = self.func(instance)
            return cache[name]


class WavepathsWarning(UserWarning):
    """Something was dropped or adjusted, and the user should know (counted in the text)."""


def external_stacklevel() -> int:
    """The ``stacklevel`` that makes a warning raised by the caller of this function point at
    the first frame outside the ``wavepaths`` package (the user's call), however deep the
    loaders nest (a Sionna scene loaded by name adds a level)."""
    import os
    import sys

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # .../wavepaths
    frame, level = sys._getframe(1), 1  # the function that warns: level 1 for warnings.warn
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(root + os.sep):
        frame, level = frame.f_back, level + 1
    return level


@dataclass(frozen=True, eq=False)
class Scene:
    """A polygonal scene.

    Attributes
    ----------
    vertices : (v, 3) float64
        Welded vertex positions [m], in the coordinates of the file.
    triangles : (f, 3) int64
        Vertex indices of each triangle.
    triangle_object : (f,) int64
        Index into ``object_names`` of each triangle.
    triangle_material : (f,) int64
        Index into ``materials`` of each triangle.
    object_names : tuple of str
    materials : tuple of Material
    normals : (f, 3) float64
        Unit triangle normals (right-hand rule on the vertex order).
    areas : (f,) float64
        Triangle areas [m^2].
    incidence : EdgeIncidence
        Unique edges and the triangles on each.
    triangle_polygon : (f,) int64
        Polygon of each triangle: adjacent coplanar triangles of one object and material.
    polygon_normal : (p, 3) float64
        Unit normal of each polygon (area-weighted, oriented like its first triangle).
    polygon_offset : (p,) float64
        Plane offset: points ``x`` of polygon ``i`` satisfy ``polygon_normal[i] @ x == polygon_offset[i]``.
    polygon_object, polygon_material : (p,) int64
    polygon_tri_ptr : (p + 1,) int64
        CSR pointer into ``polygon_tris``.
    polygon_tris : (f,) int64
        Triangles grouped by polygon.
    tolerances : SceneTolerances
    source : str
        File path or built-in name the scene came from.
    dropped_degenerate : int
        Zero-area triangles dropped on load.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    triangle_object: np.ndarray
    triangle_material: np.ndarray
    object_names: tuple[str, ...]
    materials: tuple[Material, ...]
    normals: np.ndarray
    areas: np.ndarray
    incidence: EdgeIncidence
    triangle_polygon: np.ndarray
    polygon_normal: np.ndarray
    polygon_offset: np.ndarray
    polygon_object: np.ndarray
    polygon_material: np.ndarray
    polygon_tri_ptr: np.ndarray
    polygon_tris: np.ndarray
    tolerances: SceneTolerances = field(default_factory=SceneTolerances)
    source: str = ""
    dropped_degenerate: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "_value_locks", _ValueLocks())
        # the arrays are read-only (the dihedra, the ray caster and the fingerprint are built
        # from them once and kept): held as read-only views, so the caller's arrays keep their flags
        for f in dataclass_fields(self):
            a = getattr(self, f.name)
            if isinstance(a, np.ndarray) and a.flags.writeable:
                v = a.view()
                v.flags.writeable = False
                object.__setattr__(self, f.name, v)

    # ---- sizes ---------------------------------------------------------------------
    @property
    def num_triangles(self) -> int:
        return len(self.triangles)

    @property
    def num_polygons(self) -> int:
        return len(self.polygon_normal)

    @scene_cached_property
    def geometry_fingerprint(self) -> str:
        """A digest of the scene's geometry: the welded triangles, their objects and which
        share a material, and the tolerances (not the materials' parameters). Paths carry it
        (:attr:`wavepaths.search.paths.Paths.scene_fingerprint`): their fields may be computed
        with other materials on the same geometry (:func:`with_materials`), not in another
        scene."""
        import hashlib

        h = hashlib.blake2b(digest_size=16)
        for a in (self.vertices, self.triangles, self.triangle_object, self.triangle_material):
            h.update(np.ascontiguousarray(a).tobytes())
        h.update(repr((self.object_names, len(self.materials), self.tolerances)).encode())
        return h.hexdigest()

    @scene_cached_property
    def fingerprint(self) -> str:
        """A digest of everything the path search reads from the scene: its
        :attr:`geometry_fingerprint` and the materials (absorbers reflect no path). A
        :class:`~wavepaths.search.context.TxContext` carries it, so that :func:`wavepaths.trace`
        refuses one built for another scene."""
        import hashlib

        return hashlib.blake2b((self.geometry_fingerprint + repr(self.materials)).encode(), digest_size=16).hexdigest()

    @scene_cached_property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64: minimum and maximum corner [m]."""
        used = self.vertices[np.unique(self.triangles)]
        return np.stack([used.min(axis=0), used.max(axis=0)])

    @scene_cached_property
    def center(self) -> np.ndarray:
        """(3,) float64: centre of the bounding box [m]; the origin of the float32 ray caster."""
        return self.bounds.mean(axis=0)

    @scene_cached_property
    def diagonal(self) -> float:
        """The scene's size [m], the scale of every tolerance: :func:`scene_size` of its vertices
        (the bounding box's diagonal for a box-shaped scene; unlike that diagonal, unchanged when
        the scene is rotated)."""
        return max(scene_size(self.vertices[np.unique(self.triangles)]), 1e-9)

    @scene_cached_property
    def triangle_dual(self) -> np.ndarray:
        """(f, 2, 3) float64: barycentric maps of the triangles (point-in-polygon tests)."""
        from .polygon_query import triangle_dual_basis

        return triangle_dual_basis(self.vertices, self.triangles)

    def memo(self, key: Hashable, make: Callable[[], T], keep: int | None = None) -> T:
        """``make()``, a value derived from this scene alone, computed once and kept on it.

        Later stages keep here what they derive from the scene and reuse across calls (the
        shells of its solids, the launched beams' polygon adjacency, a grid's inside mask).
        Thread-safe: threads asking for one key while it is computed wait for that one
        computation (:class:`_ValueLocks`).

        Parameters
        ----------
        key : hashable
            Names the value: a string, or a tuple whose first item names its kind.
        make : callable
            Computes the value, from the scene only (not from a transmitter or options).
        keep : int, optional
            With a tuple ``key``: at most this many values of its kind are kept, the oldest
            dropped first (masks of several grids, say).

        Returns
        -------
        The value kept for ``key``.
        """
        if keep is not None and not (isinstance(key, tuple) and key):
            raise WavepathsError(f"`keep` needs a tuple key whose first item names its kind, got {key!r}")
        store = self.__dict__.setdefault("_memo", {})
        try:
            return store[key]
        except KeyError:
            pass
        with self._value_locks(("memo", key)):
            if key in store:
                return store[key]
            value = make()
            if keep is not None:
                kind = key[0]
                same = [k for k in list(store) if isinstance(k, tuple) and k and k[0] == kind]
                for k in same[: max(len(same) - keep + 1, 0)]:
                    store.pop(k, None)
            store[key] = value
            return value

    def length_tolerance(self, relative: float) -> float:
        """A relative tolerance of :class:`SceneTolerances` in metres."""
        return relative * self.diagonal

    # ---- later stages, built on first use and cached ---------------------------------
    @scene_cached_property
    def dihedra(self) -> "Dihedra":
        """The scene's dihedra (seed §3.2), built on first use."""
        from ..topology.dihedra import build_dihedra

        return build_dihedra(self)

    @scene_cached_property
    def polygon_spheres(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounding spheres of the polygons: centres (p, 3) and radii (p,) [m] (beam tests)."""
        from .polygon_shapes import polygon_spheres

        return polygon_spheres(self)

    @scene_cached_property
    def polygon_hulls(self) -> "PolygonHulls":
        """Convex hulls of the polygons, and which can serve as occluders (hidden mirrors)."""
        from .polygon_shapes import polygon_hulls

        return polygon_hulls(self)

    @scene_cached_property
    def raycaster(self) -> "RayCaster":
        """Batched segment-occlusion queries (Embree, float32 on recentred coordinates)."""
        from ..raycast import default_raycaster

        return default_raycaster(self)

    @scene_cached_property
    def polygon_sides(self) -> np.ndarray:
        """(p, 2) bool: a polygon reflects on its normal's side / on the other side (closed objects, coincident faces)."""
        from .closed import polygon_sides

        return polygon_sides(self)

    @scene_cached_property
    def solid_object_mask(self) -> np.ndarray:
        """(objects,) bool, read-only in this process: the closed objects that enclose a volume
        (not a double-sided sheet). :func:`wavepaths.scene.solids.solid_objects` is their
        triangles, for the inside tests."""
        from .closed import compute_solid_objects_mask

        mask = compute_solid_objects_mask(self)
        mask.setflags(write=False)
        return mask

    @scene_cached_property
    def outward_sign(self) -> np.ndarray:
        """(p,) float64: +1/-1 if a polygon reflects only on its normal's side/the other side, 0 if on both."""
        from .closed import outward_polygon_sign

        return outward_polygon_sign(self)

    @scene_cached_property
    def hidden_polygons(self) -> np.ndarray:
        """(p,) bool: polygons reflecting on neither side (contact faces, duplicated coincident faces)."""
        from .closed import hidden_polygons

        return hidden_polygons(self)

    @scene_cached_property
    def object_boxes(self) -> tuple[np.ndarray, np.ndarray]:
        """(objects, 3) float64 twice: each object's bounding box (``+inf`` / ``-inf`` without triangles)."""
        from .closed import object_boxes

        return object_boxes(self)

    @scene_cached_property
    def exact_raycaster(self) -> "RayCaster":
        """Float64 occlusion (numpy), for the few segments that graze an edge."""
        from ..raycast.numpy_caster import NumpyRayCaster

        return NumpyRayCaster(self)

    def __getstate__(self) -> dict:
        # ray casters hold native handles: they are rebuilt on first use after unpickling
        state = dict(self.__dict__)
        state.pop("raycaster", None)
        state.pop("exact_raycaster", None)
        return state

    def polygon_triangles(self, polygon: int) -> np.ndarray:
        """Triangle indices of ``polygon``."""
        return self.polygon_tris[self.polygon_tri_ptr[polygon] : self.polygon_tri_ptr[polygon + 1]]

    def summary(self) -> dict:
        """The numbers ``wavepaths info`` prints (see :func:`wavepaths.scene.info.scene_info`)."""
        from .info import scene_info

        return scene_info(self)


def _array_of(where: str, name: str, value, dtype, shape: tuple) -> np.ndarray:
    """``value`` as an array of ``dtype`` and ``shape`` (-1: any length), or a SceneError naming
    ``name``: a (6, 2) ``vertices`` array is refused, not read as four points, and float
    indices are refused, not truncated."""
    a = np.asarray(value)
    if a.ndim != len(shape) or any(want not in (-1, got) for want, got in zip(shape, a.shape)):
        want = "(" + ", ".join("n" if k == -1 else str(k) for k in shape) + (",)" if len(shape) == 1 else ")")
        raise SceneError(f"{where}`{name}` must have shape {want}, got {a.shape}")
    if np.issubdtype(dtype, np.integer):
        if a.size and not np.issubdtype(a.dtype, np.integer):
            if not (np.issubdtype(a.dtype, np.floating) and np.all(np.isfinite(a)) and np.all(a == np.round(a))):
                raise SceneError(f"{where}`{name}` must hold integer indices, got {a.dtype} values")
    elif not np.issubdtype(a.dtype, np.number) or np.issubdtype(a.dtype, np.complexfloating):
        raise SceneError(f"{where}`{name}` must hold real numbers, got {a.dtype}")
    return a.astype(dtype)


def build_scene(
    vertices: np.ndarray,
    triangles: np.ndarray,
    triangle_object: np.ndarray,
    triangle_material: np.ndarray,
    object_names: tuple[str, ...] | list[str],
    materials: tuple[Material, ...] | list[Material],
    *,
    source: str = "",
    tolerances: SceneTolerances | None = None,
) -> Scene:
    """Weld, clean and group raw triangles into a :class:`Scene`.

    Parameters
    ----------
    vertices : (v, 3) float
        Vertex positions [m]. Must be finite.
    triangles : (f, 3) int
        Vertex indices.
    triangle_object, triangle_material : (f,) int
        Object and material index of each triangle.
    object_names, materials : sequences
        Indexed by the two arrays above.
    source : str
        Where the scene came from, for messages.
    tolerances : SceneTolerances, optional

    Returns
    -------
    Scene

    Raises
    ------
    SceneError
        No triangles, non-finite coordinates, or indices out of range.
    """
    tol = tolerances or SceneTolerances()
    if not isinstance(tol, SceneTolerances):
        raise SceneError(f"`tolerances` must be a SceneTolerances, got {type(tol).__name__}")
    where = f"{source}: " if source else ""
    vertices = _array_of(where, "vertices", vertices, np.float64, (-1, 3))
    triangles = _array_of(where, "triangles", triangles, np.int64, (-1, 3))
    triangle_object = _array_of(where, "triangle_object", triangle_object, np.int64, (-1,))
    triangle_material = _array_of(where, "triangle_material", triangle_material, np.int64, (-1,))
    if len(triangles) == 0:
        raise SceneError(f"{where}the mesh has no faces")
    if not np.isfinite(vertices).all():
        bad = int((~np.isfinite(vertices).all(axis=1)).sum())
        raise SceneError(f"{where}{bad} vertices have NaN or infinite coordinates")
    if triangles.min() < 0 or triangles.max() >= len(vertices):
        raise SceneError(f"{where}a face refers to a vertex that does not exist: `triangles` must index `vertices` "
                         f"(0..{len(vertices) - 1}), got {int(triangles.min())}..{int(triangles.max())}")
    for name, ids, table in (("triangle_object", triangle_object, object_names),
                             ("triangle_material", triangle_material, materials)):
        if len(ids) != len(triangles):
            raise SceneError(f"{where}`{name}` must have one entry per triangle ({len(triangles)}), got {len(ids)}")
        if ids.min() < 0 or ids.max() >= len(table):
            what = "object_names" if name == "triangle_object" else "materials"
            raise SceneError(f"{where}`{name}` must index `{what}` (0..{len(table) - 1}), "
                             f"got {int(ids.min())}..{int(ids.max())}")
    if not all(isinstance(m, Material) for m in materials):
        raise SceneError(f"{where}`materials` must be Material objects")

    used = vertices[np.unique(triangles)]
    diagonal = scene_size(used) or 1.0
    welded, index = weld_vertices(vertices, tol.weld * diagonal)
    triangles = index[triangles]
    bad = degenerate_triangles(welded, triangles, (tol.weld * diagonal) ** 2)
    dropped = int(bad.sum())
    if dropped:
        warnings.warn(f"{where}dropped {dropped} zero-area triangle(s) (after welding the vertices closer than "
                      f"{tol.weld * diagonal:.3g} m, {tol.weld:g} of the scene's diagonal: detail finer than that is "
                      f"below the scene's resolution)", WavepathsWarning, stacklevel=2)
        triangles = triangles[~bad]
        triangle_object = triangle_object[~bad]
        triangle_material = triangle_material[~bad]
    if len(triangles) == 0:
        raise SceneError(f"{where}the mesh has no faces with non-zero area")

    normals, areas = triangle_normals(welded, triangles)
    incidence = edge_incidence(triangles)
    group = triangle_object * (int(triangle_material.max()) + 1) + triangle_material
    labels = coplanar_components(incidence, normals, group, np.cos(tol.coplanar_angle), welded, triangles,
                                 tol.coplanar_distance * diagonal, areas, np.cos(tol.flat_angle))
    p = int(labels.max()) + 1

    order = np.argsort(labels, kind="stable")
    ptr = np.concatenate([[0], np.cumsum(np.bincount(labels, minlength=p))]).astype(np.int64)
    first_tri = order[ptr[:-1]]
    # orient each triangle's normal like its polygon's largest triangle (the first of equal
    # ones), then area-weight. Not the first triangle: a sliver joined by coplanar_distance may
    # stand at any angle to the polygon (a 0.1 mm skirt along a ground's border), and by its
    # normal the ground's triangles of either winding got signs of rounding noise and cancelled
    ref_tri = largest_per_label(labels, p, area_order(areas))
    sign = np.sign(np.einsum("ij,ij->i", normals, normals[ref_tri[labels]]))
    sign[sign == 0] = 1.0
    acc = np.zeros((p, 3))
    np.add.at(acc, labels, normals * (sign * areas)[:, None])
    poly_normal = acc / np.linalg.norm(acc, axis=1, keepdims=True)
    centroid = welded[triangles].mean(axis=1)
    acc_d = np.zeros(p)
    np.add.at(acc_d, labels, areas * np.einsum("ij,ij->i", centroid, poly_normal[labels]))
    poly_offset = acc_d / np.bincount(labels, weights=areas, minlength=p)

    return Scene(
        vertices=welded,
        triangles=triangles,
        triangle_object=triangle_object,
        triangle_material=triangle_material,
        object_names=tuple(object_names),
        materials=tuple(materials),
        normals=normals,
        areas=areas,
        incidence=incidence,
        triangle_polygon=labels,
        polygon_normal=poly_normal,
        polygon_offset=poly_offset,
        polygon_object=triangle_object[first_tri],
        polygon_material=triangle_material[first_tri],
        polygon_tri_ptr=ptr,
        polygon_tris=order.astype(np.int64),
        tolerances=tol,
        source=source,
        dropped_degenerate=dropped,
    )


def scene_size(points: np.ndarray) -> float:
    """Twice the largest distance of ``points`` (n, 3) from their mean [m]: the scale of the
    scene's tolerances. A rigid motion leaves it unchanged (to rounding), so that a scene and
    the same scene rotated have the same tolerances and the same topology; the bounding box's
    diagonal, which it replaces, grows by up to sqrt(3) under a rotation (a square ground
    turned by 45 degrees about z: sqrt(2)), and moved edges across the coplanar and weld
    thresholds (a box's foot 1.7e-4 m above its ground diffracted, or not, as the scene
    turned). For a box-shaped scene with its vertices symmetric about the centre it is the
    box's diagonal."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0:
        return 0.0
    d = p - p.mean(axis=0)
    return float(2.0 * np.sqrt(np.einsum("ij,ij->i", d, d).max()))


def transformed(scene: Scene, rotation: np.ndarray | None = None, translation: np.ndarray | None = None) -> Scene:
    """The same scene moved rigidly: ``x -> rotation @ x + translation``.

    Used by the invariance tests (a scene moved to 1e6 m and rotated must give the same
    paths and fields).
    """
    r = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
    t = np.zeros(3) if translation is None else np.asarray(translation, dtype=np.float64)
    return build_scene(
        scene.vertices @ r.T + t,
        scene.triangles,
        scene.triangle_object,
        scene.triangle_material,
        scene.object_names,
        scene.materials,
        source=scene.source,
        tolerances=scene.tolerances,
    )


def with_materials(scene: Scene, replacements: Mapping[str, Material | str]) -> Scene:
    """The same scene with some of its materials replaced, by name.

    For a scene whose materials are not valid at the frequency wanted (the ITU-R P.2040
    materials of the built-in scenes hold between 1 and 10 GHz, most of them), or to try
    another material, without editing the scene file. The geometry, the objects and which
    triangles share a material are unchanged; only the replaced materials' parameters are.

    Parameters
    ----------
    scene : Scene
    replacements : mapping of str to Material or str
        The name of a material of the scene (``scene.materials[i].name``) to its new
        material: a :class:`~wavepaths.em.materials.Material`, or a name
        (``"pec"``, ``"absorber"``, an ITU-R P.2040 name). A named replacement keeps the
        replaced material's slab thickness; a :class:`Material` brings its own.

    Returns
    -------
    Scene
        A new scene (its dihedra and ray caster are built again when first used).

    Raises
    ------
    WavepathsError
        A name that is no material of the scene (the message lists the scene's), or a value
        that is no material.
    """
    import dataclasses

    from ..em.materials import as_material

    names = [m.name for m in scene.materials]
    unknown = [k for k in replacements if k not in names]
    if unknown:
        raise WavepathsError(f"`replacements` names {unknown}, which are no materials of the scene "
                             f"{scene.source!r}; its materials: {names}")
    new = []
    for m in scene.materials:
        if m.name not in replacements:
            new.append(m)
            continue
        value = replacements[m.name]
        rep = as_material(value, f"the replacement of material {m.name!r}")
        new.append(rep if isinstance(value, Material) else dataclasses.replace(rep, thickness_m=m.thickness_m))
    return dataclasses.replace(scene, materials=tuple(new))

