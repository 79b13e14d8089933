"""Run NVIDIA Sionna RT 2.x and return its results as plain numpy arrays.

This module is wavepaths' bridge to the reference implementation it is
checked against. It drives Sionna RT's public API only (``load_scene``,
``Transmitter``, ``Receiver``, ``PlanarArray``, ``PathSolver``,
``RadioMapSolver``) on the CPU (Mitsuba variant ``llvm_ad_mono_polarized``, set
up by :func:`wavepaths.validation.sionna_env.ensure_sionna`) and flattens the
result into arrays that do not depend on Sionna, Mitsuba or Dr.Jit.

Conventions of the returned data (see ``docs/sionna-notes.md``):

* ``a`` is Sionna's ``Paths.a``: the passband coefficient **without** the
  propagation phase. For free-space line of sight with isotropic antennas of
  the same linear polarisation ``a = lambda / (4 pi d)`` (real, positive). The
  phase is carried by the delay: the baseband coefficient is
  ``a * exp(-2j pi f tau)``, so the LOS field is ``lambda/(4 pi d) exp(-j k d)``.
* ``interactions`` uses wavepaths' codes (:class:`wavepaths.search.paths.InteractionType`):
  :data:`NONE` (0), :data:`REFLECTION` (1, Sionna's specular reflection) and
  :data:`DIFFRACTION` (2). Paths that
  contain anything else (refraction, diffuse reflection, sensing) are dropped
  and counted in ``SionnaPaths.excluded``; refraction and diffuse reflection
  are off by default.
* ``vertices[i]`` is the polyline of path ``i``: transmitter, interaction
  points in order, receiver, then NaN rows up to ``max_depth + 2``.

Functions
---------
run_sionna_paths
    Exact paths between transmitters and receivers (``PathSolver``).
run_sionna_radio_map
    Path gain on a planar grid of cells (``RadioMapSolver``).
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wavepaths.errors import SceneError
from wavepaths.search.paths import InteractionType
from wavepaths.validation.sionna_env import ensure_sionna, sionna_version

__all__ = [
    "DIFFRACTION",
    "NONE",
    "REFLECTION",
    "SionnaPaths",
    "SionnaRadioMap",
    "builtin_scene_path",
    "run_sionna_paths",
    "run_sionna_radio_map",
]

#: No interaction (padding after the last interaction of a path).
NONE: int = int(InteractionType.NONE)
#: Specular reflection on a face.
REFLECTION: int = int(InteractionType.REFLECTION)
#: Diffraction on an edge (wedge or free edge).
DIFFRACTION: int = int(InteractionType.DIFFRACTION)

# Sionna RT 2.2's sionna.rt.constants.InteractionType (bit flags).
_SIONNA_NONE = 0
_SIONNA_SPECULAR = 1
_SIONNA_DIFFUSE = 2
_SIONNA_REFRACTION = 4
_SIONNA_DIFFRACTION = 8
_SIONNA_INVALID = 0xFFFFFFFF


@dataclass(frozen=True, eq=False)
class SionnaPaths:
    """Paths found by Sionna's ``PathSolver``, one row per path.

    Attributes
    ----------
    tx_index, rx_index : ndarray of int64, shape (N,)
        Index of the path's transmitter / receiver in the ``tx`` / ``rx`` input.
    interactions : ndarray of int8, shape (N, max_depth)
        :data:`NONE`, :data:`REFLECTION` or :data:`DIFFRACTION` per bounce.
    num_interactions : ndarray of int64, shape (N,)
        Number of interactions of each path (0 for line of sight).
    vertices : ndarray of float64, shape (N, max_depth + 2, 3)
        Transmitter, interaction points, receiver, then NaN rows.
    a : ndarray of complex128, shape (N,)
        Sionna's ``Paths.a`` (no propagation phase, see the module docstring).
    tau : ndarray of float64, shape (N,)
        Delay in seconds (path length / c, from float32 data).
    objects : ndarray of int64, shape (N, max_depth)
        Index into ``object_names`` of the object at each interaction, -1 where
        there is none (or where Sionna records none, see the notes).
    primitives : ndarray of int64, shape (N, max_depth)
        Triangle index within that object's mesh, -1 where there is none.
    object_names : tuple of str
        Scene object names (Sionna strips the ``mesh-`` prefix of the XML id).
    frequency_hz : float
        Carrier frequency used.
    max_depth : int
        ``max_depth`` given to the solver.
    excluded : int
        Number of valid Sionna paths dropped because they contain an
        interaction other than reflection or diffraction.
    elapsed_s : float
        Wall time of the timed solver call (after a warm-up call, so Dr.Jit's
        kernel compilation is excluded), including evaluation of ``a`` and
        ``tau`` but not the conversion to numpy.
    warmup_s : float
        Wall time of the warm-up call (includes JIT compilation unless Dr.Jit's
        on-disk kernel cache already held the kernels).
    sionna_version : str
        Version of sionna-rt that produced the data.
    """

    tx_index: NDArray[np.int64]
    rx_index: NDArray[np.int64]
    interactions: NDArray[np.int8]
    num_interactions: NDArray[np.int64]
    vertices: NDArray[np.float64]
    a: NDArray[np.complex128]
    tau: NDArray[np.float64]
    objects: NDArray[np.int64]
    primitives: NDArray[np.int64]
    object_names: tuple[str, ...]
    frequency_hz: float
    max_depth: int
    excluded: int
    elapsed_s: float
    warmup_s: float
    sionna_version: str

    @property
    def num_paths(self) -> int:
        """Number of paths ``N``."""
        return int(self.tau.shape[0])

    def select(self, tx: int, rx: int) -> NDArray[np.int64]:
        """Row indices of the paths from transmitter ``tx`` to receiver ``rx``."""
        return np.flatnonzero((self.tx_index == tx) & (self.rx_index == rx))


@dataclass(frozen=True, eq=False)
class SionnaRadioMap:
    """Path gain map computed by Sionna's ``RadioMapSolver``.

    Attributes
    ----------
    path_gain : ndarray of float64, shape (ny, nx) or (m, ny, nx)
        Linear path gain per cell (per transmitter when ``m > 1``).
    path_gain_db : ndarray of float64, same shape
        ``10 log10(path_gain)``; ``-inf`` where no ray reached the cell.
    cell_centers : ndarray of float64, shape (ny, nx, 3)
        Cell centres in world coordinates.
    elapsed_s, warmup_s : float
        Timed call (after warm-up) and warm-up call wall times.
    frequency_hz : float
        Carrier frequency used.
    sionna_version : str
        Version of sionna-rt that produced the data.
    """

    path_gain: NDArray[np.float64]
    path_gain_db: NDArray[np.float64]
    cell_centers: NDArray[np.float64]
    elapsed_s: float
    warmup_s: float
    frequency_hz: float
    sionna_version: str


def builtin_scene_path(name: str) -> str:
    """Return the XML path of one of Sionna's built-in scenes.

    Parameters
    ----------
    name : str
        Attribute name in ``sionna.rt.scene``, e.g. ``"simple_wedge"``.

    Raises
    ------
    SceneError
        If Sionna has no such built-in scene.
    """
    rt = ensure_sionna()
    path = getattr(rt.scene, name, None)
    if not isinstance(path, str) or not path.endswith(".xml"):
        raise SceneError(f"Sionna RT has no built-in scene named {name!r}")
    return path


def _resolve_scene(rt: ModuleType, scene_xml: str) -> str:
    if os.path.isfile(scene_xml):
        return scene_xml
    path = getattr(rt.scene, scene_xml, None)
    if isinstance(path, str) and path.endswith(".xml") and os.path.isfile(path):
        return path
    raise SceneError(
        f"scene {scene_xml!r} is neither an existing Mitsuba XML file nor the "
        "name of a Sionna built-in scene (e.g. 'simple_wedge')"
    )


def _positions(value: ArrayLike, what: str) -> NDArray[np.float64]:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] == 0:
        raise ValueError(f"{what} must have shape (n, 3) with n >= 1, got {np.shape(value)}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} contains non-finite coordinates")
    return arr


def _build_scene(rt: ModuleType, scene_xml: str, tx: NDArray[np.float64],
                 rx: NDArray[np.float64] | None, frequency_hz: float,
                 tx_antenna: tuple[str, str], rx_antenna: tuple[str, str],
                 merge_shapes: bool, remove_duplicate_vertices: bool) -> Any:
    import mitsuba as mi

    path = _resolve_scene(rt, scene_xml)
    try:
        scene = rt.load_scene(path, merge_shapes=merge_shapes,
                              remove_duplicate_vertices=remove_duplicate_vertices)
    except Exception as exc:  # Mitsuba raises RuntimeError on bad files
        raise SceneError(f"Sionna could not load {path!r}: {exc}") from exc
    scene.frequency = float(frequency_hz)
    scene.tx_array = rt.PlanarArray(num_rows=1, num_cols=1, pattern=tx_antenna[0],
                                    polarization=tx_antenna[1])
    scene.rx_array = rt.PlanarArray(num_rows=1, num_cols=1, pattern=rx_antenna[0],
                                    polarization=rx_antenna[1])
    for i, p in enumerate(tx):
        scene.add(rt.Transmitter(name=f"tx{i}", position=mi.Point3f(*map(float, p))))
    if rx is not None:
        for j, p in enumerate(rx):
            scene.add(rt.Receiver(name=f"rx{j}", position=mi.Point3f(*map(float, p))))
    return scene


def run_sionna_paths(
    scene_xml: str,
    tx: ArrayLike,
    rx: ArrayLike,
    *,
    frequency_hz: float,
    max_depth: int,
    los: bool = True,
    specular_reflection: bool = True,
    diffraction: bool = True,
    edge_diffraction: bool = False,
    diffraction_lit_region: bool = True,
    refraction: bool = False,
    diffuse_reflection: bool = False,
    samples_per_src: int = 1_000_000,
    max_num_paths_per_src: int = 1_000_000,
    synthetic_array: bool = True,
    tx_antenna: tuple[str, str] = ("iso", "V"),
    rx_antenna: tuple[str, str] = ("iso", "V"),
    seed: int = 1,
    merge_shapes: bool = False,
    remove_duplicate_vertices: bool = False,
    deterministic: bool = False,
    warmup: bool = True,
) -> SionnaPaths:
    """Compute paths with Sionna RT's ``PathSolver`` and flatten them.

    Parameters
    ----------
    scene_xml : str
        Mitsuba XML scene file, or the name of a Sionna built-in scene
        (``"simple_wedge"``, ``"munich"``, ...).
    tx, rx : array_like, shape (m, 3) and (n, 3)
        Transmitter and receiver positions in metres.
    frequency_hz : float
        Carrier frequency (sets ``scene.frequency``, hence the ITU materials).
    max_depth : int
        Maximum number of interactions per path.
    los, specular_reflection, diffraction : bool
        Enable line of sight, specular reflections, and (first-order) diffraction.
    edge_diffraction : bool, default False
        Also diffract on free edges (edges with a single face, e.g. the rim of
        a screen); Sionna's default. Wedges between two faces of one mesh
        diffract whenever ``diffraction`` is on.
    diffraction_lit_region : bool, default True
        Keep diffracted paths whose receiver is in the lit region too (False
        keeps only shadow-region diffraction).
    refraction, diffuse_reflection : bool, default False
        Sionna's other mechanisms; paths using them are excluded from the
        result anyway (counted in ``excluded``).
    samples_per_src, max_num_paths_per_src : int
        Shooting-and-bouncing samples per source and path cap, as in Sionna.
    synthetic_array : bool, default True
        Sionna's synthetic-array switch (irrelevant for one antenna).
    tx_antenna, rx_antenna : (pattern, polarization)
        Single-port antenna: pattern in ``iso``, ``dipole``, ``hw_dipole``,
        ``tr38901``; polarization ``V`` or ``H``.
    seed : int, default 1
        Sampling seed (results are reproducible only with ``deterministic``).
    merge_shapes : bool, default False
        Let Sionna merge shapes that share a material (names then become
        ``no-name-N``); off so that object names match the XML ids.
    remove_duplicate_vertices : bool, default False
        Weld duplicated mesh vertices on load (needed for Sionna to find the
        wedges of meshes stored with split vertices).
    deterministic : bool, default False
        Use Sionna's deterministic candidate generator.
    warmup : bool, default True
        Run the solver once untimed before the timed call.

    Returns
    -------
    SionnaPaths

    Raises
    ------
    wavepaths.errors.DependencyError
        If Sionna RT or a suitable libLLVM is missing.
    wavepaths.errors.SceneError
        If the scene cannot be found or loaded.
    ValueError
        For bad positions or multi-port antennas.
    """
    rt = ensure_sionna()
    import drjit as dr

    tx_pos = _positions(tx, "tx")
    rx_pos = _positions(rx, "rx")
    if max_depth < 0:
        raise ValueError("max_depth must be >= 0")
    for ant in (tx_antenna, rx_antenna):
        if len(ant) != 2 or ant[1] not in ("V", "H"):
            raise ValueError(f"single-port antenna (pattern, 'V' | 'H') expected, got {ant!r}")

    scene = _build_scene(rt, scene_xml, tx_pos, rx_pos, frequency_hz, tx_antenna,
                         rx_antenna, merge_shapes, remove_duplicate_vertices)
    solver = rt.PathSolver(deterministic=deterministic)
    kwargs = dict(max_depth=int(max_depth), max_num_paths_per_src=int(max_num_paths_per_src),
                  samples_per_src=int(samples_per_src), synthetic_array=bool(synthetic_array),
                  los=bool(los), specular_reflection=bool(specular_reflection),
                  diffuse_reflection=bool(diffuse_reflection), refraction=bool(refraction),
                  diffraction=bool(diffraction), edge_diffraction=bool(edge_diffraction),
                  diffraction_lit_region=bool(diffraction_lit_region), seed=int(seed))

    def solve() -> Any:
        paths = solver(scene, **kwargs)
        a_re, a_im = paths.a
        dr.eval(a_re, a_im, paths.tau, paths.valid)
        return paths

    warmup_s = 0.0
    if warmup:
        t0 = time.perf_counter()
        solve()
        warmup_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    paths = solve()
    elapsed_s = time.perf_counter() - t0

    return _flatten_paths(scene, paths, tx_pos, rx_pos, frequency_hz, int(max_depth),
                          synthetic_array, elapsed_s, warmup_s)


def _flatten_paths(scene: Any, paths: Any, tx_pos: NDArray[np.float64],
                   rx_pos: NDArray[np.float64], frequency_hz: float, max_depth: int,
                   synthetic_array: bool, elapsed_s: float,
                   warmup_s: float) -> SionnaPaths:
    n_rx, n_tx = rx_pos.shape[0], tx_pos.shape[0]
    a = np.asarray(paths.a[0].numpy(), dtype=np.float64) \
        + 1j * np.asarray(paths.a[1].numpy(), dtype=np.float64)
    if a.ndim != 5 or a.shape[1] != 1 or a.shape[3] != 1:
        raise ValueError(f"expected single-port antennas, got Paths.a of shape {a.shape}")
    a = a[:, 0, :, 0, :]  # (rx, tx, paths)

    def per_link(x: Any) -> NDArray[Any]:
        arr = np.asarray(x.numpy())
        if not synthetic_array:  # [rx, rx_ant, tx, tx_ant, ...] -> [rx, tx, ...]
            arr = arr[:, 0, :, 0]
        return arr

    def per_depth(x: Any) -> NDArray[Any]:
        arr = np.asarray(x.numpy())
        if not synthetic_array:  # [depth, rx, rx_ant, tx, tx_ant, ...]
            arr = arr[:, :, 0, :, 0]
        return np.moveaxis(arr, 0, -1) if arr.ndim == 4 else np.moveaxis(arr, 0, -2)

    valid = per_link(paths.valid).astype(bool)  # (rx, tx, P)
    tau = per_link(paths.tau).astype(np.float64)
    n_paths_max = valid.shape[-1]
    if n_paths_max == 0:
        inter = np.zeros((n_rx, n_tx, 0, max(1, max_depth)), dtype=np.uint32)
        objs = np.full_like(inter, _SIONNA_INVALID)
        prims = np.full_like(inter, _SIONNA_INVALID)
        verts = np.zeros((n_rx, n_tx, 0, max(1, max_depth), 3), dtype=np.float32)
    else:
        inter = per_depth(paths.interactions).astype(np.uint32)   # (rx, tx, P, D)
        objs = per_depth(paths.objects).astype(np.uint32)
        prims = per_depth(paths.primitives).astype(np.uint32)
        verts = per_depth(paths.vertices)                          # (rx, tx, P, D, 3)
    depth_dim = inter.shape[-1]

    rx_i, tx_i, p_i = np.nonzero(valid)
    inter_f = inter[rx_i, tx_i, p_i][:, :max_depth] if depth_dim else inter[rx_i, tx_i, p_i]
    known = (inter_f == _SIONNA_NONE) | (inter_f == _SIONNA_SPECULAR) \
        | (inter_f == _SIONNA_DIFFRACTION)
    keep = np.all(known, axis=1)
    excluded = int(np.count_nonzero(~keep))
    rx_i, tx_i, p_i = rx_i[keep], tx_i[keep], p_i[keep]
    n = rx_i.shape[0]

    sionna_codes = inter[rx_i, tx_i, p_i][:, :max_depth]
    codes = np.zeros((n, max_depth), dtype=np.int8)
    codes[sionna_codes == _SIONNA_SPECULAR] = REFLECTION
    codes[sionna_codes == _SIONNA_DIFFRACTION] = DIFFRACTION
    num_inter = np.count_nonzero(codes != NONE, axis=1).astype(np.int64)

    # Object ids (Mitsuba shape pointers reinterpreted as uint32) -> names.
    names = tuple(scene.objects.keys())
    id_to_index = {int(obj.object_id): k for k, obj in enumerate(scene.objects.values())}
    raw_objs = objs[rx_i, tx_i, p_i][:, :max_depth]
    obj_index = np.full((n, max_depth), -1, dtype=np.int64)
    for raw, k in id_to_index.items():
        obj_index[raw_objs == raw] = k
    raw_prims = prims[rx_i, tx_i, p_i][:, :max_depth].astype(np.int64)
    prim_index = np.where(raw_prims == _SIONNA_INVALID, -1, raw_prims)
    prim_index[obj_index < 0] = -1

    vertices = np.full((n, max_depth + 2, 3), np.nan, dtype=np.float64)
    vertices[:, 0] = tx_pos[tx_i]
    inter_pts = np.asarray(verts[rx_i, tx_i, p_i][:, :max_depth], dtype=np.float64)
    for k in range(max_depth):
        has = codes[:, k] != NONE
        vertices[has, k + 1] = inter_pts[has, k]
    vertices[np.arange(n), num_inter + 1] = rx_pos[rx_i]

    return SionnaPaths(
        tx_index=tx_i.astype(np.int64),
        rx_index=rx_i.astype(np.int64),
        interactions=codes,
        num_interactions=num_inter,
        vertices=vertices,
        a=a[rx_i, tx_i, p_i].astype(np.complex128),
        tau=tau[rx_i, tx_i, p_i],
        objects=obj_index,
        primitives=prim_index,
        object_names=names,
        frequency_hz=float(frequency_hz),
        max_depth=max_depth,
        excluded=excluded,
        elapsed_s=float(elapsed_s),
        warmup_s=float(warmup_s),
        sionna_version=sionna_version() or "",
    )


def run_sionna_radio_map(
    scene_xml: str,
    tx: ArrayLike,
    center: Sequence[float],
    size: Sequence[float],
    cell_size: Sequence[float],
    orientation: Sequence[float],
    frequency_hz: float,
    max_depth: int,
    diffraction: bool = True,
    samples_per_tx: int = 1_000_000,
    *,
    los: bool = True,
    specular_reflection: bool = True,
    edge_diffraction: bool = False,
    diffraction_lit_region: bool = True,
    refraction: bool = False,
    diffuse_reflection: bool = False,
    tx_antenna: tuple[str, str] = ("iso", "V"),
    rx_antenna: tuple[str, str] = ("iso", "V"),
    seed: int = 1,
    merge_shapes: bool = False,
    remove_duplicate_vertices: bool = False,
    warmup: bool = True,
) -> SionnaRadioMap:
    """Compute a planar path-gain map with Sionna RT's ``RadioMapSolver``.

    Parameters
    ----------
    scene_xml : str
        Mitsuba XML scene file or Sionna built-in scene name.
    tx : array_like, shape (3,) or (m, 3)
        Transmitter position(s) in metres.
    center : (x, y, z)
        Centre of the measurement plane.
    size : (sx, sy)
        Size of the plane in metres (Sionna rounds it up to whole cells).
    cell_size : (cx, cy)
        Cell size in metres.
    orientation : (alpha, beta, gamma)
        Rotation of the plane in radians (z, y, x Euler angles as in Sionna);
        ``(0, 0, 0)`` gives a horizontal plane.
    frequency_hz, max_depth, diffraction, samples_per_tx
        As in Sionna; ``samples_per_tx`` rays are shot per transmitter.
    los, specular_reflection, edge_diffraction, diffraction_lit_region,
    refraction, diffuse_reflection, tx_antenna, rx_antenna, seed, merge_shapes,
    remove_duplicate_vertices, warmup
        As in :func:`run_sionna_paths`.

    Returns
    -------
    SionnaRadioMap
        ``path_gain`` has shape (ny, nx) for one transmitter, (m, ny, nx) for
        several. It is Sionna's cell-averaged, incoherent (power-summed) gain.
    """
    rt = ensure_sionna()
    import drjit as dr
    import mitsuba as mi

    tx_arr = np.asarray(tx, dtype=np.float64)
    single = tx_arr.ndim == 1
    tx_pos = _positions(tx_arr, "tx")
    scene = _build_scene(rt, scene_xml, tx_pos, None, frequency_hz, tx_antenna,
                         rx_antenna, merge_shapes, remove_duplicate_vertices)
    solver = rt.RadioMapSolver()
    kwargs = dict(center=mi.Point3f(*map(float, center)),
                  orientation=mi.Point3f(*map(float, orientation)),
                  size=mi.Point2f(*map(float, size)),
                  cell_size=mi.Point2f(*map(float, cell_size)),
                  samples_per_tx=int(samples_per_tx), max_depth=int(max_depth),
                  los=bool(los), specular_reflection=bool(specular_reflection),
                  diffuse_reflection=bool(diffuse_reflection), refraction=bool(refraction),
                  diffraction=bool(diffraction), edge_diffraction=bool(edge_diffraction),
                  diffraction_lit_region=bool(diffraction_lit_region), seed=int(seed))

    def solve() -> Any:
        rm = solver(scene, **kwargs)
        dr.eval(rm.path_gain)
        return rm

    warmup_s = 0.0
    if warmup:
        t0 = time.perf_counter()
        solve()
        warmup_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    rm = solve()
    elapsed_s = time.perf_counter() - t0

    gain = np.asarray(rm.path_gain.numpy(), dtype=np.float64)  # (m, ny, nx)
    if single:
        gain = gain[0]
    with np.errstate(divide="ignore"):
        gain_db = 10.0 * np.log10(gain)
    centers = np.asarray(rm.cell_centers.numpy(), dtype=np.float64)
    return SionnaRadioMap(path_gain=gain, path_gain_db=gain_db, cell_centers=centers,
                          elapsed_s=float(elapsed_s), warmup_s=float(warmup_s),
                          frequency_hz=float(frequency_hz),
                          sionna_version=sionna_version() or "")
