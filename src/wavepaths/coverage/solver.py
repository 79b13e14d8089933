"""``coverage()``: a deterministic coverage map on the exact path engine.

How the work splits (the architecture's three costs):

1. once per scene: the scene, its dihedra and ray caster (built by the caller's
   :func:`~wavepaths.scene.load_scene`, rebuilt per process where it cannot pickle);
2. once per transmitter set: :func:`~wavepaths.search.build_tx_context` (image trees,
   diffraction sources) and the inside-object test of the cells;
3. per tile of ``tile_size`` cells: :func:`solve_tile` runs
   :func:`~wavepaths.search.tile.trace_tile` on the cell centres, the field chain on the
   paths found, and sums the coefficients per cell with ``bincount``: the tile returns
   fixed-size arrays (``~100 bytes`` per cell and transmitter), never its paths.

Tiles are independent, so :mod:`wavepaths.coverage.parallel` runs them in this process,
in a local process pool, or on a Dask cluster, with the same numbers: a cell's value is
exactly what :func:`wavepaths.trace` and :func:`wavepaths.fields.compute_fields` give for
a receiver at the cell centre.
"""

from __future__ import annotations

import hashlib

import dataclasses
import os
import sys
import time
from collections import Counter
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
from numpy.typing import ArrayLike

from ..errors import WavepathsError
from ..fields import FieldConfig, compute_fields
from ..scene.model import Scene
from ..search.context import TxContext, build_tx_context
from ..search.options import TraceOptions
from ..search.paths import InteractionType, Paths, assemble, coincident_paths, concatenate, path_order
from ..search.diffraction import finish_diffraction
from ..search.launched import prepare_launched, shipped_context
from ..search.tile import trace_tile
from ..search.through_vertices import drop_crossed
from ..search.on_faces import points_near_edges
from ..search.trace import _warn_on_faces, check_positions, points_on_faces
from .grid import Grid, MeshGrid, PlanarGrid
from ..scene.solids import inside_solid_objects, solid_objects
from .result import MECHANISMS, CoverageMap
from .surfaces import cells_on_faces, outside_solids, warn_cells_near_edges, warn_cells_on_faces
from .tolerance import tolerance_keep, warn_unbounded

# result bytes per cell and transmitter: a_total (16) + a_sum (3 x 16) + power_sum (3 x 8)
# + num_paths (3 x 4) + field_total (3 x 16) + field_power_sum (8), plus the derived dB maps
# written by save() (~3 x 8)
RESULT_BYTES_PER_CELL_TX = 180
RESULT_BYTES_PER_CELL = 24 + 1 + 8 * 4  # centres, inside mask, best-server maps


@dataclass(frozen=True)
class CoverageOptions:
    """Settings of a coverage map that path search and fields do not have.

    Attributes
    ----------
    tile_size : int or None
        Cells traced together in one vectorised call (memory vs. per-call overhead; the
        working set grows about linearly with it, see ``docs/coverage.md``). ``None``
        (default): :func:`auto_tile_size`, from the transmitter's image counts.
    coherent : bool
        Add the paths of a cell coherently, ``|sum a e^{-j 2 pi f tau}|^2`` (default), or
        by power, ``sum |a|^2`` (smoother maps). Both are kept in the map; this picks
        which one its quantities report by default.
    workers : int or None
        Local processes. ``1``: in this process. ``None`` (default): the first tiles are
        traced in this process, and the second one's time predicts the rest's; a map whose
        other tiles would take less than :data:`wavepaths.coverage.parallel.POOL_MIN_SECONDS` at
        that pace stays in this process (a pool's start-up, 2-3 s, would cost more than it
        saves), a larger one goes to a pool of one process per core. Ignored when a Dask
        ``client`` is given.
    threads : int or None
        Tiles traced at once on threads of this process, when the tiles run in it
        (``workers=1``, or a small map with ``workers=None``): the compiled kernels and
        Embree release the GIL. ``None`` (default): the cores numba uses (1 without
        numba); ``1``: one tile at a time on the calling thread. Threads share the tiles
        the tile size gives (a map of one tile runs on the calling thread, whose compiled
        kernels may use numba's threads), and the map is the same bit for bit whatever
        the threads. Maps with launched candidates run one tile at a time (their tube
        kernels use numba's threads themselves).
    mask_inside : bool
        Mark cells inside solid objects NaN and do not trace them
        (:mod:`wavepaths.scene.solids`). Turn off for scenes whose closed objects are
        rooms to be covered from inside.
    max_memory_bytes : int
        Refuse maps whose result arrays would exceed this [bytes] (the tiles bound the
        working memory separately).
    """

    tile_size: int | None = None
    coherent: bool = True
    workers: int | None = None
    threads: int | None = None
    mask_inside: bool = True
    max_memory_bytes: int = 4 << 30

    def __post_init__(self) -> None:
        if self.tile_size is not None and (not isinstance(self.tile_size, (int, np.integer)) or self.tile_size < 1):
            raise WavepathsError(f"`tile_size` must be None or a positive integer, got {self.tile_size!r}")
        if self.workers is not None and (not isinstance(self.workers, (int, np.integer)) or self.workers < 1):
            raise WavepathsError(f"`workers` must be None or a positive integer, got {self.workers!r}")
        if self.threads is not None and (not isinstance(self.threads, (int, np.integer)) or self.threads < 1):
            raise WavepathsError(f"`threads` must be None or a positive integer, got {self.threads!r}")
        if self.max_memory_bytes <= 0:
            raise WavepathsError(f"`max_memory_bytes` must be positive, got {self.max_memory_bytes!r}")


TILE_IMAGE_BUDGET = 1 << 22  # receiver images held by one tile, for the automatic tile size


LAUNCHED_TILE_MAX = 2048
"""Cells per tile at most with launched candidates: every tile scans all the fan segments
traced for the map (munich: 6.26 M, about 0.75 s per tile), so tiles are large; a 2,048-cell
munich square holds about 150,000 launched candidates (docs/benchmarks-history.md,
seventeenth session), and since the twenty-seventh session about 700,000 more from the enumerated E-D-R
paths (:mod:`wavepaths.search.launched`)."""


def block_tiles(shape: tuple[int, ...], active: np.ndarray, size: int) -> list[np.ndarray]:
    """Tiles of at most ``size`` cells that are compact blocks of a 2-D grid.

    The grid ``shape`` (ny, nx) is cut into squares of ``floor(sqrt(size))`` cells a side;
    each square's active cells (``active``: flat indices, row-major) go to one tile, and
    consecutive squares of a row of squares share a tile while they fit in ``size``. With
    launched candidates a tile's work grows with the rays that cross it, so a square
    meets fewer rays than a strip of whole rows of the same area. A grid that is not 2-D
    is cut into runs of consecutive cells.
    """
    active = np.asarray(active, dtype=np.int64)
    if len(shape) != 2 or len(active) == 0:
        return [active[s : s + size] for s in range(0, len(active), size)]
    ny, nx = shape
    side = max(1, int(np.sqrt(size)))
    row, col = np.divmod(active, nx)
    block = (row // side) * (-(-nx // side)) + col // side
    order = np.argsort(block, kind="stable")
    block, cells = block[order], active[order]
    bounds = np.flatnonzero(np.diff(block)) + 1
    groups = np.split(cells, bounds)
    tiles: list[np.ndarray] = []
    run: list[np.ndarray] = []
    count, run_row = 0, -1
    for g in groups:
        r = int(g[0] // nx) // side  # the row of squares
        if run and (count + len(g) > size or r != run_row):
            tiles.append(np.concatenate(run))
            run, count = [], 0
        run.append(g)
        run_row = r
        count += len(g)
    if run:
        tiles.append(np.concatenate(run))
    return tiles


def auto_tile_size(ctx: TxContext, cells: int, workers: int | None = None) -> int:
    """Cells per tile when :attr:`CoverageOptions.tile_size` is ``None``.

    Large tiles amortise the per-call overhead (on ``simple_street_canyon`` at 4 m cells,
    tiles of 1024 instead of 256 made R1 and R1+D maps 1.4-2.5x faster), but a tile holds
    every receiver's image tree up to ``diffraction_reflections``. Estimating a receiver's
    tree by the transmitter's (``ctx.stats``), the tile holds at most
    :data:`TILE_IMAGE_BUDGET` images: ``clamp(budget / images per receiver, 16, 1024)``.
    With several worker processes (``workers > 1``), tiles are also small enough to give
    each of them two. Threads of this process share the tiles this gives and never shrink
    them: a tile's fixed cost holds the GIL (a 1,000-cell map in four tiles on two threads
    took 1.5-1.7x longer than in one tile on one thread). With ``workers=None`` the map
    may stay in this process, so the tiles are shrunk for the workers only down to
    :data:`THREAD_TILE_MIN` cells.
    """
    if ctx.options.launched:
        # launched candidates: no receiver image trees, and every tile scans all the rays
        # traced for the map, so the tiles are as large as the workers allow
        w = 1 if workers == 1 else (workers or default_workers())
        return int(np.clip(-(-cells // w), 16, LAUNCHED_TILE_MAX))
    per_rx = 1
    if ctx.options.diffraction:
        per_rx += sum(int(ctx.stats.get(f"images_order_{b}", 0)) for b in range(1, ctx.options.diffraction_reflections + 1))
    size = int(np.clip(TILE_IMAGE_BUDGET // per_rx, 16, 1024))
    if workers is None or workers > 1:
        w = workers or default_workers()
        floor = 16 if workers else THREAD_TILE_MIN
        size = min(size, max(floor, -(-cells // (2 * w))))
    return size


THREAD_TILE_MIN = 1024
"""With ``workers=None``, the smallest tiles the automatic size gives for the workers (the
map may stay in this process, on threads, where small tiles cost more than they save)."""


@dataclass
class TileSums:
    """Per-cell sums of one tile (m transmitters, k cells); see :class:`CoverageMap`.

    Attributes
    ----------
    a_total : (m, k) complex128
    a_sum : (3, m, k) complex128
    power_sum : (3, m, k) float64
    num_paths : (3, m, k) int32
    stats : dict
    field_total : (m, k, 3) complex128
        ``sum e e^{-j 2 pi f tau}``: the paths' field vectors at the cell (transmit port 0,
        before the receive antenna, normalised like ``a``).
    field_power_sum : (m, k) float64
        ``sum |e|^2``.
    """

    a_total: np.ndarray
    a_sum: np.ndarray
    power_sum: np.ndarray
    num_paths: np.ndarray
    stats: dict
    field_total: np.ndarray | None = None
    field_power_sum: np.ndarray | None = None


def path_mechanism(paths: Paths) -> np.ndarray:
    """(N,) int64: index into :data:`MECHANISMS` of each path (LOS 0, reflection 1, diffraction 2)."""
    diffracted = (paths.interactions == InteractionType.DIFFRACTION).any(axis=1)
    return np.where(paths.depth == 0, 0, np.where(diffracted, 2, 1))


def _fields_sums(scene: Scene, config: FieldConfig, paths: Paths, m: int, k: int):
    """(pair, key, a_phased, power) of ``paths``: indices for the per-cell sums and the values,
    in the canonical order of :func:`wavepaths.search.paths.path_order`, whatever order
    ``paths`` come in (``assemble(..., sort=False)``): a path's field does not depend on the
    others' order, and the sums, added in this order, are those of the sorted paths to the
    last bit, without gathering every path's vertices into that order first."""
    if not len(paths):
        z = np.zeros(0, np.int64)
        return z, z, np.zeros(0, complex), np.zeros(0), np.zeros((0, 3), complex)
    order = path_order(paths.tx_index, paths.rx_index, paths.depth, paths.lengths, paths.interactions, paths.primitive,
                       k)
    # a path found once per primitive at a seam counts once, as in trace() (search.paths.coincident_paths)
    drop = coincident_paths(paths.tx_index, paths.rx_index, paths.depth, paths.interactions, paths.lengths,
                            paths.vertices, order, scene.length_tolerance(scene.tolerances.weld))
    if drop.any():
        order = order[~drop[order]]
    pair = paths.tx_index * k + paths.rx_index
    key = path_mechanism(paths) * (m * k) + pair
    result = compute_fields(scene, paths, config)
    phase = np.exp(-2j * np.pi * result.frequency_hz * paths.delays[order])
    field = result.incident_field[order, 0, :] * phase[:, None]  # transmit port 0, as a
    return pair[order], key[order], result.a[order] * phase, (np.abs(result.a) ** 2)[order], field


def solve_tile(scene: Scene, ctx: TxContext, config: FieldConfig, rx: np.ndarray) -> TileSums:
    """Trace one tile of cell centres ``rx`` (k, 3) [m] and sum their path coefficients.

    ``rx`` must be finite and off the transmitters (checked by :func:`coverage`). With
    ``TraceOptions.tolerance_db``, the diffracted candidates are held back until the fields of
    the other paths are known, and the weakest are dropped (:func:`~wavepaths.coverage.tolerance.tolerance_keep`).
    """
    m, k = len(ctx.tx), len(rx)
    pending = [] if ctx.options.tolerance_db is not None else None
    batches, stats = trace_tile(scene, ctx, rx, 0, pending)
    compiled = None if ctx.options.compiled else False

    def kept(found: list) -> Paths:
        # the paths of batches ``found``, without those entering a solid from a transmitter on its
        # surface or crossing a face at a reflection point
        return drop_crossed(scene, outside_solids(scene, ctx, assemble(ctx.tx, rx, found, dict(stats), sort=False),
                                                  stats), stats, compiled)

    paths = kept(batches)
    pair, key, ap, power, field = _fields_sums(scene, config, paths, m, k)
    if pending:
        go_power = np.bincount(pair, power, m * k)
        keeps = tolerance_keep(ctx, config, pending, go_power, k, stats)
        dropped = {name: stats.get(name, 0) for name in ("paths_dropped_into_solid", "paths_dropped_through_a_face")}
        # the diffracted paths kept are checked alone (the others were above, once), then added
        more = kept([finish_diffraction(scene, ctx, p, 0, stats, keep) for p, keep in zip(pending, keeps)])
        for name, count in dropped.items():  # (set by the checks for the paths they see)
            if name in stats:
                stats[name] += count
        # the fields again, with every path: a diffraction term next to a shadow or reflection
        # boundary takes the side its geometrical-optics path is on (fields.chain), so the
        # diffracted paths' fields need the others beside them
        paths = concatenate(paths, more)
        pair, key, ap, power, field = _fields_sums(scene, config, paths, m, k)
    n3 = 3 * m * k
    # bincount adds in path order, like FieldResult.path_gain's np.add.at
    a_total = np.bincount(pair, ap.real, m * k) + 1j * np.bincount(pair, ap.imag, m * k)
    a_sum = np.bincount(key, ap.real, n3) + 1j * np.bincount(key, ap.imag, n3)
    field_total = np.stack([np.bincount(pair, field[:, c].real, m * k) + 1j * np.bincount(pair, field[:, c].imag, m * k)
                            for c in range(3)], axis=-1)
    field_power = np.bincount(pair, (np.abs(field) ** 2).sum(axis=1), m * k)
    return TileSums(
        a_total=a_total.reshape(m, k),
        a_sum=a_sum.reshape(3, m, k),
        power_sum=np.bincount(key, power, n3).reshape(3, m, k),
        num_paths=np.bincount(key, minlength=n3).astype(np.int32).reshape(3, m, k),
        stats=dict(stats),
        field_total=field_total.reshape(m, k, 3),
        field_power_sum=field_power.reshape(m, k),
    )


INSIDE_CACHE_SIZE = 8
"""Cell masks kept per scene (:func:`_cached`); the oldest goes first."""


def _cached(scene: "Scene", key: str, make):
    """A value kept on the scene object (:meth:`~wavepaths.scene.model.Scene.memo`), like its
    dihedra: the solids, and the inside mask of a set of cell centres and the faces they lie on
    (keyed ``"inside:<digest of their bytes>"``), which do not depend on the transmitters or the
    options, so a second map on the same grid skips the ray-parity and on-face tests. At most
    :data:`INSIDE_CACHE_SIZE` masks of each kind are kept."""
    kind, _, grid = key.partition(":")  # "inside:" masks, "onface:" faces: per grid, a few kept

    def frozen():
        value = make()
        if isinstance(value, np.ndarray):
            value.setflags(write=False)
        return value

    if not grid:
        return scene.memo(("coverage", kind), frozen)
    return scene.memo((kind, grid), frozen, keep=INSIDE_CACHE_SIZE)


def coverage(
    scene: Scene,
    tx: ArrayLike,
    grid: Grid,
    options: TraceOptions | None = None,
    *,
    fields: FieldConfig | None = None,
    settings: CoverageOptions | None = None,
    client: Any = None,
    progress: bool | Callable[[int], None] | None = None,
) -> CoverageMap:
    """A coverage map: path gain, received power and field strength on every cell of ``grid``.

    Parameters
    ----------
    scene : Scene
    tx : (m, 3) array_like
        Transmitter positions [m]; with several, the map also gives the best server.
    grid : PlanarGrid or MeshGrid
        Where to evaluate: cell centres are the receivers.
    options : TraceOptions, optional
        What to trace (default: line of sight, reflections to order 2, first-order
        diffraction with one reflection). With ``tolerance_db``, ``prune_frequency_hz`` is
        set to ``fields.frequency_hz`` (the bound it uses needs the frequency).
    fields : FieldConfig, optional
        Frequency, diffraction model, antennas, transmit power.
    settings : CoverageOptions, optional
        Tile size, coherent or power sum, local workers, inside-object mask.
    client : dask.distributed.Client, optional
        Run the tiles on this cluster; the scene and the transmitter context are sent to
        every worker once.
    progress : bool or callable, optional
        ``True``: a tqdm bar on standard error (shown only on a terminal). A callable is
        called with the number of cells finished so far.

    Returns
    -------
    CoverageMap

    Raises
    ------
    WavepathsError
        A transmitter that is NaN, inside a solid object (one exactly on a face is warned
        about instead, as :func:`~wavepaths.search.trace.trace` does) or at a cell centre; a grid
        whose result would not fit ``settings.max_memory_bytes``; a material without
        values at the frequency; options of the wrong type.
    """
    from .parallel import run_tiles

    t_start = time.perf_counter()
    opts = options or TraceOptions()
    cfg = fields or FieldConfig()
    cov = settings or CoverageOptions()
    _check_types(scene, grid, opts, cfg, cov)
    if opts.tolerance_db is not None:
        if cfg.model != "utd":
            raise WavepathsError(f"`tolerance_db` needs the UTD model (its bound does not hold for {cfg.model!r})")
        # the diffraction bound needs the frequency, which the map knows (so does prune_db then)
        opts = opts.with_(prune_frequency_hz=cfg.frequency_hz)
    warn_unbounded(opts, cfg, cov.coherent)
    tx = check_positions("tx", tx)
    cfg.check_materials(scene)  # fail before tracing, not in a worker
    m = len(tx)
    n = grid.num_cells
    need = n * (RESULT_BYTES_PER_CELL + m * RESULT_BYTES_PER_CELL_TX)
    if need > cov.max_memory_bytes:
        raise WavepathsError(
            f"the grid has {n:,} cells ({' x '.join(map(str, grid.shape))}) for {m} transmitter(s): its map needs "
            f"about {need / 2**30:.1f} GiB, above the limit of {cov.max_memory_bytes / 2**30:.1f} GiB "
            f"(`CoverageOptions.max_memory_bytes`); use larger cells or a smaller area, or split the area"
        )
    centres = grid.cell_centers()
    flat = check_positions("grid cell centres", centres.reshape(-1, 3))
    bad = ~np.isfinite(flat).all(axis=1)
    if bad.any():
        raise WavepathsError(f"the grid has NaN or infinite cell centres at cell(s) {np.nonzero(bad)[0][:10].tolist()}")

    timings: dict[str, float] = {}
    t = time.perf_counter()
    grid_key = hashlib.sha1(flat.tobytes()).hexdigest()
    # the faces cell centres lie on, and whether on a solid's surface (cached per grid), with the
    # solids of the inside mask below (found once)
    solids = _cached(scene, "solids", lambda: solid_objects(scene)) if cov.mask_inside else None
    faces, on_solid = _cached(scene, "onface:" + grid_key, lambda: cells_on_faces(scene, flat, solids))
    if cov.mask_inside:
        inside = _cached(scene, "inside:" + grid_key, lambda: inside_solid_objects(scene, flat, solids))
        # a centre on a solid's surface is masked like those inside it, whatever the ray-parity
        # test (either answer on a surface) says: a rule, not a coin flip
        inside = inside | on_solid
        tx_in = inside_solid_objects(scene, tx, solids)
        tx_in &= points_on_faces(scene, tx) < 0  # on a face the parity rule answers either way: warned below
        if tx_in.any():
            i = int(np.nonzero(tx_in)[0][0])
            raise WavepathsError(
                f"transmitter {i} at {tx[i].tolist()} lies inside a solid object: move it, or set "
                f"`CoverageOptions(mask_inside=False)` (`--keep-inside` on the command line) if the object is a "
                f"room to cover from inside"
            )
    else:
        inside = np.zeros(len(flat), bool)
    timings["inside_s"] = time.perf_counter() - t
    active = np.nonzero(~inside)[0]
    # as trace() does: such a transmitter is on no side of its face
    _warn_on_faces(scene, tx, np.empty((0, 3)), edges=opts.diffraction)
    warn_cells_on_faces(scene, flat, active, faces[active], int((on_solid & inside).sum()))
    if opts.diffraction:
        near_edge = _cached(scene, "nearedge:" + grid_key, lambda: points_near_edges(scene, flat)[0] >= 0)
        warn_cells_near_edges(scene, flat, active[near_edge[active] & (faces[active] < 0)])
    _check_off_transmitters(scene, tx, flat, active, grid)

    t = time.perf_counter()
    ctx = build_tx_context(scene, tx, opts)
    timings["context_s"] = time.perf_counter() - t
    if opts.launched:
        # the Keller fans traced once here for every cell, then shipped with the context
        t = time.perf_counter()
        prepare_launched(scene, ctx, flat[active])
        timings["launch_s"] = time.perf_counter() - t
    # what the tiles receive: with launched fans, only the sources they name
    tile_ctx = shipped_context(ctx) if opts.launched else ctx

    a_total = np.full((m, n), np.nan + 0j)
    a_sum = np.full((3, m, n), np.nan + 0j)
    power_sum = np.full((3, m, n), np.nan)
    num_paths = np.zeros((3, m, n), np.int32)
    field_total = np.full((m, n, 3), np.nan + 0j)
    field_power_sum = np.full((m, n), np.nan)
    stats: Counter = Counter(ctx.stats)
    size = cov.tile_size or auto_tile_size(ctx, len(active), cov.workers)
    timings["tile_size"] = size
    if opts.launched and isinstance(grid, PlanarGrid):
        tiles = block_tiles(grid.shape, active, size)
    else:
        tiles = [active[s : s + size] for s in range(0, len(active), size)]
    bar, report = _progress(progress, len(active))

    def on_done(i: int, sums: TileSums) -> None:
        cells = tiles[i]
        a_total[:, cells] = sums.a_total
        a_sum[:, :, cells] = sums.a_sum
        power_sum[:, :, cells] = sums.power_sum
        num_paths[:, :, cells] = sums.num_paths
        field_total[:, cells] = sums.field_total
        field_power_sum[:, cells] = sums.field_power_sum
        stats.update(sums.stats)
        report(len(cells))

    t = time.perf_counter()
    try:
        workers = run_tiles(scene, tile_ctx, cfg, [flat[c] for c in tiles], on_done, workers=cov.workers,
                            threads=cov.threads, client=client)
    finally:
        if bar is not None:
            bar.close()
    timings["tiles_s"] = time.perf_counter() - t
    elapsed = time.perf_counter() - t_start
    shape = grid.shape
    metadata = {
        "scene": scene.source,
        "trace_options": opts.to_dict(),
        "field_config": dataclasses.asdict(cfg),
        "coverage_options": dataclasses.asdict(cov),
        "workers": workers,
        "tiles": len(tiles),
        "cells_traced": int(len(active)),
    }
    return CoverageMap(
        grid=grid,
        cell_centers=centres,
        inside=inside.reshape(shape),
        tx_positions=tx,
        a_total=a_total.reshape((m,) + shape),
        a_sum=a_sum.reshape((3, m) + shape),
        power_sum=power_sum.reshape((3, m) + shape),
        num_paths=num_paths.reshape((3, m) + shape),
        field_total=field_total.reshape((m,) + shape + (3,)),
        field_power_sum=field_power_sum.reshape((m,) + shape),
        frequency_hz=cfg.frequency_hz,
        tx_power_dbm=cfg.tx_power_dbm,
        coherent=cov.coherent,
        elapsed_s=elapsed,
        timings=timings,
        stats=dict(stats),
        metadata=metadata,
    )


def _check_types(scene, grid, opts, cfg, cov) -> None:
    for name, value, kind in (("scene", scene, Scene), ("grid", grid, (PlanarGrid, MeshGrid)),
                              ("options", opts, TraceOptions), ("fields", cfg, FieldConfig),
                              ("settings", cov, CoverageOptions)):
        if not isinstance(value, kind):
            want = " or ".join(k.__name__ for k in (kind if isinstance(kind, tuple) else (kind,)))
            raise WavepathsError(f"`{name}` must be a {want}, got {type(value).__name__}")


def _check_off_transmitters(scene: Scene, tx: np.ndarray, flat: np.ndarray, active: np.ndarray, grid: Grid) -> None:
    """A cell centre on a transmitter has no defined field: say which, and how to avoid it."""
    tol = scene.length_tolerance(scene.tolerances.weld)
    pts = flat[active]
    for i, t in enumerate(tx):
        hit = np.nonzero(np.linalg.norm(pts - t, axis=1) <= tol)[0]
        if len(hit):
            cell = np.unravel_index(int(active[hit[0]]), grid.shape)
            raise WavepathsError(
                f"cell {tuple(int(c) for c in cell)} has its centre on transmitter {i} at {t.tolist()}: "
                f"move the grid (e.g. its height) or the transmitter by a fraction of a cell"
            )


def _progress(progress, total: int):
    """(tqdm bar or None, callable taking the cells just finished)."""
    if callable(progress):
        done = [0]

        def report(k: int) -> None:
            done[0] += k
            progress(done[0])

        return None, report
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=total, unit="cell", file=sys.stderr, disable=not sys.stderr.isatty(), dynamic_ncols=True)
        return bar, bar.update
    return None, lambda k: None


def default_workers() -> int:
    """Cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


__all__ = ["CoverageOptions", "TileSums", "auto_tile_size", "block_tiles", "coverage", "path_mechanism", "solve_tile", "MECHANISMS"]
