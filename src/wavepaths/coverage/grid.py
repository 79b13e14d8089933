"""Where a coverage map is evaluated: a planar grid of cells, or the faces of a mesh.

Both kinds answer the same three questions: the map's ``shape``, the receiver position of
every cell (``cell_centers()``, shape ``shape + (3,)``, metres), and a JSON-ready
``describe()`` that is stored with the map. Neither allocates anything until
``cell_centers()`` is called, so the solver can refuse a grid too large for memory from
``num_cells`` alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Union

import numpy as np

from ..em.antennas import rotation_matrix
from ..errors import WavepathsError

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene


def _finite_vector(name: str, value, sizes: tuple[int, ...]) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.shape[0] not in sizes:
        want = " or ".join(f"({s},)" for s in sizes)
        raise WavepathsError(f"`{name}` must have shape {want}, got {np.shape(value)}")
    if not np.isfinite(arr).all():
        raise WavepathsError(f"`{name}` has NaN or infinite values: {arr.tolist()}")
    return arr


def _pair(value):
    """A scalar repeated twice, or the value itself."""
    return [value, value] if np.ndim(value) == 0 else value


MAX_CELLS_PER_AXIS = 1 << 31
"""Cells along one axis of a planar grid at most (a smaller cell is refused: ``size / cell_size``
would overflow the cell count, which once turned a 1e-20 m cell into a 1 x 1 map)."""


@dataclass(frozen=True, eq=False)
class PlanarGrid:
    """A rectangle of ``ny x nx`` equal cells; receivers at the cell centres.

    Parameters
    ----------
    center : (2,) or (3,) array_like [m]
        Centre of the rectangle. With two coordinates, ``height`` gives ``z``.
    size : float or (2,) array_like [m]
        Extent along the grid's local ``u`` and ``v`` axes. Rounded up to whole cells,
        ``nx = ceil(size_u / cell_u)``, the rectangle staying centred on ``center``.
    cell_size : float or (2,) array_like [m]
        Cell extent along ``u`` and ``v``.
    height : float, optional [m]
        ``z`` of the centre, when ``center`` has two coordinates.
    orientation : (3,) array_like [rad]
        ``(yaw, pitch, roll)`` rotating the local frame, ``R = Rz(yaw) Ry(pitch) Rx(roll)``
        (:func:`wavepaths.em.antennas.rotation_matrix`, as Sionna RT orients its radio
        maps). The columns of ``R`` are ``u`` (along a row), ``v`` (along a column) and
        the plane's normal. ``(0, 0, 0)``: horizontal, ``u = x``, ``v = y``.
        ``(0, 0, pi/2)``: a vertical plane with ``u = x``, ``v = z``, facing ``-y``.

    Attributes
    ----------
    center : (3,) float64 [m]
    size : (2,) float64 [m]
        As given (the covered extent is ``shape[::-1] * cell_size``).
    cell_size : (2,) float64 [m]
    orientation : (3,) float64 [rad]
    """

    center: np.ndarray
    size: np.ndarray
    cell_size: np.ndarray
    height: float | None = None
    orientation: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        c = _finite_vector("center", self.center, (2, 3))
        if c.shape[0] == 2:
            if self.height is None:
                raise WavepathsError("`center` has two coordinates: give the grid's `height` too")
            h = float(self.height)
            if not math.isfinite(h):
                raise WavepathsError(f"`height` must be finite, got {self.height}")
            c = np.array([c[0], c[1], h])
        elif self.height is not None and float(self.height) != c[2]:
            raise WavepathsError(f"`center` has z = {c[2]} and `height` = {self.height}: give one of them")
        size = _finite_vector("size", _pair(self.size), (2,))
        cell = _finite_vector("cell_size", _pair(self.cell_size), (2,))
        if (size <= 0).any():
            raise WavepathsError(
                f"`size` must be positive in both directions (an empty grid otherwise), got {size.tolist()}"
            )
        if (cell <= 0).any():
            raise WavepathsError(f"`cell_size` must be positive, got {cell.tolist()}")
        with np.errstate(over="ignore"):
            per_axis = size / cell
        if not (np.isfinite(per_axis).all() and (per_axis <= MAX_CELLS_PER_AXIS).all()):
            raise WavepathsError(f"`cell_size` {cell.tolist()} is too small for `size` {size.tolist()}: "
                                 f"more than {MAX_CELLS_PER_AXIS:,} cells along an axis")
        ori = _finite_vector("orientation", self.orientation, (3,))
        object.__setattr__(self, "center", c)
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "cell_size", cell)
        object.__setattr__(self, "height", float(c[2]))
        object.__setattr__(self, "orientation", ori)

    @classmethod
    def footprint(cls, scene: "Scene", cell_size, height: float, margin: float = 0.0) -> "PlanarGrid":
        """A horizontal grid over the scene's bounding box in ``x, y`` (plus ``margin`` [m])."""
        lo, hi = scene.bounds
        size = (hi[:2] - lo[:2]) + 2 * margin
        if (size <= 0).any():
            raise WavepathsError(f"the scene {scene.source!r} has no extent in x or y: give the grid's `size`")
        return cls(center=0.5 * (lo[:2] + hi[:2]), size=size, cell_size=cell_size, height=height)

    # ---- shape -------------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nx)``: rows along ``v``, columns along ``u``."""
        n = np.ceil(self.size / self.cell_size - 1e-9).astype(np.int64)
        nx, ny = (max(1, int(k)) for k in n)
        return (ny, nx)

    @property
    def num_cells(self) -> int:
        ny, nx = self.shape
        return ny * nx

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) float64: columns ``u``, ``v``, normal."""
        return rotation_matrix(self.orientation)

    def local_coordinates(self) -> tuple[np.ndarray, np.ndarray]:
        """Cell-centre offsets from ``center`` along ``u`` (nx,) and ``v`` (ny,) [m]."""
        ny, nx = self.shape
        u = (np.arange(nx) + 0.5 - 0.5 * nx) * self.cell_size[0]
        v = (np.arange(ny) + 0.5 - 0.5 * ny) * self.cell_size[1]
        return u, v

    def cell_centers(self) -> np.ndarray:
        """(ny, nx, 3) float64: receiver position of every cell [m]."""
        u, v = self.local_coordinates()
        r = self.rotation
        return self.center + u[None, :, None] * r[:, 0] + v[:, None, None] * r[:, 1]

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """(k, 3) global points -> (k, 3) local ``(u, v, distance along the normal)`` [m]."""
        return (np.asarray(points, dtype=np.float64) - self.center) @ self.rotation

    def describe(self) -> dict:
        return {
            "kind": "planar",
            "center": self.center.tolist(),
            "size": self.size.tolist(),
            "cell_size": self.cell_size.tolist(),
            "orientation": self.orientation.tolist(),
            "shape": list(self.shape),
        }


@dataclass(frozen=True, eq=False)
class MeshGrid:
    """The faces of a measurement mesh as cells; receivers at the face centroids.

    Parameters
    ----------
    vertices : (v, 3) array_like [m]
    faces : (f, 3) array_like of int
        Triangles (vertex indices).
    offset : float [m]
        Receivers sit ``offset`` along each face's normal (right-hand rule) from its
        centroid (0: on the face).

    Attributes
    ----------
    vertices : (v, 3) float64
    faces : (f, 3) int64
    offset : float
    """

    vertices: np.ndarray
    faces: np.ndarray
    offset: float = 0.0

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices, dtype=np.float64)
        f = np.asarray(self.faces)
        if v.ndim != 2 or v.shape[1] != 3:
            raise WavepathsError(f"`vertices` must have shape (v, 3), got {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3:
            raise WavepathsError(f"`faces` must have shape (f, 3), got {f.shape}")
        if len(f) == 0:
            raise WavepathsError("`faces` is empty: the measurement mesh has no cells")
        if not np.issubdtype(f.dtype, np.integer):
            raise WavepathsError(f"`faces` must hold integer vertex indices, got {f.dtype}")
        if f.min() < 0 or f.max() >= len(v):
            raise WavepathsError(f"`faces` refers to vertices outside 0..{len(v) - 1}")
        if not np.isfinite(v[np.unique(f)]).all():
            raise WavepathsError("`vertices` has NaN or infinite coordinates")
        if not math.isfinite(float(self.offset)):
            raise WavepathsError(f"`offset` must be finite, got {self.offset}")
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f.astype(np.int64))
        object.__setattr__(self, "offset", float(self.offset))

    @classmethod
    def from_file(cls, path: str, offset: float = 0.0, up_axis: str = "auto") -> "MeshGrid":
        """A measurement mesh from a mesh file (OBJ, PLY, STL, glTF/GLB, OFF), read and turned
        to +Z up as :func:`wavepaths.scene.load_scene` reads a scene (``up_axis``: glTF is
        +Y up; OBJ, PLY and OFF faces split exactly), so that it lies where the scene does."""
        import os

        import trimesh

        from ..errors import SceneError
        from ..scene.loaders import Y_UP_TO_Z_UP, _check_up_axis, _rotates_to_z_up

        axis = _check_up_axis(up_axis)
        ext = os.path.splitext(path)[1].lower()
        try:
            if ext == ".obj":
                from ..scene.obj_reader import read_obj

                obj = read_obj(path)
                vertices, faces = obj.vertices, obj.triangles
            elif ext in (".ply", ".off"):
                from ..scene.obj_reader import polygon_triangles
                from ..scene.ply_off_reader import read_off, read_ply

                vertices, faces = polygon_triangles(path, read_ply(path) if ext == ".ply" else read_off(path))
            else:
                mesh = trimesh.load(path, process=False, force="mesh")
                vertices, faces = np.asarray(mesh.vertices, np.float64), np.asarray(getattr(mesh, "faces", []))
        except SceneError as exc:
            raise WavepathsError(f"cannot read the measurement mesh: {exc}") from None
        except Exception as exc:  # trimesh raises many kinds
            raise WavepathsError(f"{path}: cannot read the measurement mesh ({exc})") from None
        if len(faces) == 0:
            raise WavepathsError(f"{path}: the measurement mesh has no faces")
        if _rotates_to_z_up(ext, axis):
            vertices = vertices @ Y_UP_TO_Z_UP.T
        return cls(vertices, np.asarray(faces, np.int64).reshape(-1, 3), offset)

    @property
    def shape(self) -> tuple[int]:
        return (len(self.faces),)

    @property
    def num_cells(self) -> int:
        return len(self.faces)

    def face_normals(self) -> np.ndarray:
        """(f, 3) float64 unit normals (zero for degenerate faces)."""
        a, b, c = (self.vertices[self.faces[:, i]] for i in range(3))
        n = np.cross(b - a, c - a)
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        return n / np.where(norm > 0, norm, 1.0)

    def cell_centers(self) -> np.ndarray:
        """(f, 3) float64: face centroids, moved ``offset`` along the normals [m]."""
        centre = self.vertices[self.faces].mean(axis=1)
        if self.offset:
            centre = centre + self.offset * self.face_normals()
        return centre

    def describe(self) -> dict:
        return {"kind": "mesh", "faces": int(len(self.faces)), "offset": self.offset, "shape": list(self.shape)}


Grid = Union[PlanarGrid, MeshGrid]
