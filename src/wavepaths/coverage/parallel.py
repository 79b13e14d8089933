"""Running coverage tiles: in this process (on threads), in a local process pool, or on Dask.

All three run :func:`wavepaths.coverage.solver.solve_tile` on the same tiles and hand
each result to the same callback, which writes it into the map by cell index: the order
in which tiles finish does not change a single bit of the map.

What a worker holds: the scene (its arrays and dihedra; the Embree BVH is rebuilt on the
worker, since native handles do not pickle), the transmitter context and the field
settings, received once, plus the working set of the tile it is running. See
``docs/coverage.md`` for the numbers.

* In this process: the tiles on ``threads`` Python threads (the compiled kernels, Embree
  and numpy's large operations release the GIL; each tile's kernels then run on its own
  thread), results consumed in tile order.
* Automatic (``workers=None``): the first tile is traced here, then the second, timed
  (the first also pays the one-off costs of a process); if the other tiles would take
  less than :data:`POOL_MIN_SECONDS` at its pace, or fewer than two are left, they are
  traced here on threads, else in a local pool. Launched candidates run one tile at a
  time here (their tube kernels use numba's threads themselves). A pool's processes start in 2-3 s (imports, the
  scene and context unpickled, Embree's BVH rebuilt), which a small map does not win back:
  ``simple_street_canyon``'s 88 x 60-cell R2+D1 map took 2.5-3.6 s through a pool of two
  against 0.32 s on two threads here (0.55 s on one).
* Local pool: ``spawn``-started processes (forking a process that holds Embree's thread
  pool is unsafe) that do not re-run the caller's script (no ``__main__`` guard needed);
  the scene, context and settings travel once per process as the pool's initializer
  arguments, tiles carry only their cell centres.
* Dask: ``client.scatter(..., broadcast=True)`` puts the scene, context and settings on
  every worker once; each tile is one task holding futures to them.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..errors import DependencyError
from ..search import kernels
from .solver import TileSums, default_workers, solve_tile

if TYPE_CHECKING:  # pragma: no cover
    from ..fields import FieldConfig
    from ..scene.model import Scene
    from ..search.context import TxContext

OnDone = Callable[[int, TileSums], None]

POOL_MIN_SECONDS = 20.0
"""With ``workers=None``: the time of the tiles left, at the pace of the second tile (traced
on the calling thread, whose compiled kernels may use numba's threads), from which they go
to a process pool instead of threads of this process (two tiles left at least). Two
processes beat two threads by the threads' GIL contention (R2+D1 tiles ran 1.7x faster on
two threads, GIL-bound R2 tiles not at all) but pay 2-3 s to start: for GIL-bound tiles the
pool wins from about 6 s of work, for diffraction-heavy tiles from about 30 s."""

# the state a pool process receives once, at start-up
_WORKER_STATE: tuple | None = None


def run_tiles(
    scene: "Scene",
    ctx: "TxContext",
    config: "FieldConfig",
    tiles: list[np.ndarray],
    on_done: OnDone,
    *,
    workers: int | None = None,
    threads: int | None = None,
    client=None,
) -> str:
    """Solve every tile of cell centres and pass ``(tile index, TileSums)`` to ``on_done``.

    ``workers``, ``threads``: as in :class:`wavepaths.coverage.CoverageOptions`. Returns a
    short description of where the tiles ran (``"in-process"``, ``"in-process, N
    threads"``, ``"local pool of N processes"``, ``"dask <scheduler address>"``).
    """
    if not tiles:
        return "none"
    if client is not None:
        return _run_dask(client, scene, ctx, config, tiles, on_done)
    n_threads = kernels.threads() if threads is None else int(threads)
    if ctx.options.launched:
        # the launched tiles' tube kernels run on numba's threads themselves and must not be
        # entered from two threads at once (numba's workqueue layer aborts the process)
        n_threads = 1
    if workers is not None:
        n = min(int(workers), len(tiles))
        if n <= 1:
            return _run_here(scene, ctx, config, tiles, range(len(tiles)), on_done, n_threads)
        return _run_pool(n, scene, ctx, config, tiles, range(len(tiles)), on_done)
    n = min(default_workers(), len(tiles))
    if n <= 1:
        return _run_here(scene, ctx, config, tiles, range(len(tiles)), on_done, n_threads)
    # the first tiles here, the last of them timed: it predicts what the others cost (the
    # first one also pays what a process pays once: kernels loaded from numba's cache, the
    # scene's caches built)
    first = 2 if len(tiles) > 2 else 1
    for i in range(first):
        t = time.perf_counter()
        on_done(i, solve_tile(scene, ctx, config, tiles[i]))
    rest = range(first, len(tiles))
    if len(rest) < 2 or (time.perf_counter() - t) * len(rest) < POOL_MIN_SECONDS:
        return _run_here(scene, ctx, config, tiles, rest, on_done, n_threads)
    return _run_pool(min(n, len(rest)), scene, ctx, config, tiles, rest, on_done)


def _run_here(scene, ctx, config, tiles, which: range, on_done: OnDone, threads: int) -> str:
    """The tiles ``which`` in this process, on up to ``threads`` threads (1: the calling thread)."""
    threads = max(1, min(threads, len(which)))
    solved = kernels.in_threads(lambda i: solve_tile(scene, ctx, config, tiles[i]), list(which), threads)
    for i, sums in zip(which, solved):
        on_done(i, sums)
    return "in-process" if threads == 1 else f"in-process, {threads} threads"


# ---- local process pool -------------------------------------------------------------------
def _init_worker(scene, ctx, config) -> None:
    global _WORKER_STATE
    _WORKER_STATE = (scene, ctx, config)
    # the pool's processes share the cores: each runs the compiled kernels on one thread
    from ..search import kernels

    kernels.set_threads(1)


def _pool_tile(i: int, rx: np.ndarray) -> tuple[int, TileSums]:
    scene, ctx, config = _WORKER_STATE
    return i, solve_tile(scene, ctx, config, rx)


@contextlib.contextmanager
def _main_module_hidden():
    """Start pool processes without re-running the caller's script in them.

    A ``spawn``-ed process imports the parent's ``__main__`` (by path or module name) before
    it runs anything, which re-executes a script that lacks an
    ``if __name__ == "__main__":`` guard. The tile workers need only wavepaths, so the
    ``__main__`` module's ``__file__`` and ``__spec__`` are hidden while the pool starts
    its processes (nothing from ``__main__`` is sent to them).
    """
    main = sys.modules.get("__main__")
    missing = object()
    saved = {k: getattr(main, k, missing) for k in ("__file__", "__spec__")} if main is not None else {}
    try:
        if main is not None:
            if saved["__file__"] is not missing:
                del main.__file__
            main.__spec__ = None
        yield
    finally:
        for k, v in saved.items():
            if v is missing:
                if hasattr(main, k):
                    delattr(main, k)
            else:
                setattr(main, k, v)


def _run_pool(n: int, scene, ctx, config, tiles, which: range, on_done: OnDone) -> str:
    mp = multiprocessing.get_context("spawn")
    with _main_module_hidden(), ProcessPoolExecutor(max_workers=n, mp_context=mp, initializer=_init_worker,
                                                    initargs=(scene, ctx, config)) as pool:
        # keep a bounded number of tiles in flight: results are consumed as they come
        pending = set()
        it = iter((i, tiles[i]) for i in which)
        for i, rx in it:
            pending.add(pool.submit(_pool_tile, i, rx))
            if len(pending) >= 4 * n:
                break
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                on_done(*fut.result())
                nxt = next(it, None)
                if nxt is not None:
                    pending.add(pool.submit(_pool_tile, *nxt))
    return f"local pool of {n} processes"


# ---- Dask ---------------------------------------------------------------------------------
def _dask_tile(scene, ctx, config, rx: np.ndarray, i: int) -> tuple[int, TileSums]:
    return i, solve_tile(scene, ctx, config, rx)


def _run_dask(client, scene, ctx, config, tiles, on_done: OnDone) -> str:
    try:
        from distributed import as_completed
    except ImportError:
        raise DependencyError(
            "running on a Dask cluster needs `distributed`: pip install 'wavepaths[dask]'"
        ) from None
    scene_f = client.scatter(scene, broadcast=True, hash=False)
    ctx_f = client.scatter(ctx, broadcast=True, hash=False)
    config_f = client.scatter(config, broadcast=True, hash=False)
    futures = [client.submit(_dask_tile, scene_f, ctx_f, config_f, rx, i, pure=False) for i, rx in enumerate(tiles)]
    try:
        for fut in as_completed(futures):
            on_done(*fut.result())
            fut.release()
    finally:
        client.cancel([f for f in futures if not f.done()])
        for f in (scene_f, ctx_f, config_f):
            f.release()
    address = getattr(getattr(client, "scheduler", None), "address", None) or "cluster"
    return f"dask {address}"
