"""The same tiles in this process (on one thread or several), in a local process pool and
on a Dask cluster give the same map; the scene and the transmitter context survive
pickling; the automatic choice keeps a small map in this process."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from wavepaths import TraceOptions, build_tx_context, load_scene
from wavepaths.coverage import CoverageOptions, PlanarGrid, coverage, solve_tile
from wavepaths.fields import FieldConfig

OPTIONS = TraceOptions(max_reflections=2, diffraction=True, diffraction_reflections=1)


@pytest.fixture(scope="module")
def canyon():
    return load_scene("street_canyon")


@pytest.fixture(scope="module")
def grid():
    return PlanarGrid(center=[-37.3, 2.2], size=[56, 30], cell_size=[7, 5], height=1.5)


@pytest.fixture(scope="module")
def in_process(canyon, grid):
    return coverage(canyon, [-60, 0, 10], grid, OPTIONS, settings=CoverageOptions(workers=1, threads=1, tile_size=8))


def assert_same_map(a, b):
    np.testing.assert_array_equal(a.inside, b.inside)
    np.testing.assert_array_equal(a.num_paths, b.num_paths)
    # same arithmetic on the same tiles: equal to the last bit, checked with a float tolerance
    np.testing.assert_allclose(a.a_total, b.a_total, rtol=1e-12, atol=0)
    np.testing.assert_allclose(a.power_sum, b.power_sum, rtol=1e-12, atol=0)
    np.testing.assert_allclose(a.path_gain_db(), b.path_gain_db(), rtol=1e-12, atol=0)


def test_scene_and_context_pickle_and_solve_the_same_tile(canyon, grid):
    ctx = build_tx_context(canyon, np.array([[-60.0, 0, 10]]), OPTIONS)
    assert canyon.raycaster is not None  # built here: the Embree handle must not travel
    scene2, ctx2 = pickle.loads(pickle.dumps((canyon, ctx)))
    rx = grid.cell_centers().reshape(-1, 3)[:12]
    rx = rx[(np.abs(rx[:, 1]) < 10)]
    a = solve_tile(canyon, ctx, FieldConfig(), rx)
    b = solve_tile(scene2, ctx2, FieldConfig(), rx)
    np.testing.assert_array_equal(a.a_total, b.a_total)
    np.testing.assert_array_equal(a.num_paths, b.num_paths)


def test_threads_of_this_process_give_the_same_map(canyon, grid, in_process):
    assert in_process.metadata["workers"] == "in-process"
    threaded = coverage(canyon, [-60, 0, 10], grid, OPTIONS, settings=CoverageOptions(workers=1, threads=3, tile_size=8))
    assert threaded.metadata["workers"] == "in-process, 3 threads"
    for name in ("num_paths", "a_total", "a_sum", "power_sum"):  # bit for bit
        np.testing.assert_array_equal(getattr(threaded, name), getattr(in_process, name), err_msg=name)


def test_launched_maps_run_one_tile_at_a_time(canyon, grid):
    """Launched candidates' tube kernels use numba's threads themselves: their tiles are not
    run on threads (entering those kernels from two threads aborts numba's workqueue layer)."""
    opts = OPTIONS.with_(diffraction_candidates="launched", reflection_candidates="launched", launch_rays=1 << 14)
    m = coverage(canyon, [-60, 0, 10], grid, opts, settings=CoverageOptions(workers=1, threads=4, tile_size=8))
    assert m.metadata["tiles"] > 1 and m.metadata["workers"] == "in-process"


def test_a_small_map_stays_in_this_process_a_large_one_goes_to_the_pool(canyon, grid, in_process, monkeypatch):
    """``workers=None``: the second tile, traced here after the first, predicts the rest; this
    map's tiles take milliseconds, far below ``POOL_MIN_SECONDS``, so no pool is started. With the threshold
    at zero the other tiles go to a pool of the machine's cores: the same map either way."""
    import importlib

    from wavepaths.coverage.solver import default_workers

    parallel = importlib.import_module("wavepaths.coverage.parallel")
    auto = coverage(canyon, [-60, 0, 10], grid, OPTIONS, settings=CoverageOptions(tile_size=8, threads=2))
    assert auto.metadata["workers"] == ("in-process, 2 threads" if default_workers() > 1 else "in-process")
    assert_same_map(auto, in_process)
    if default_workers() < 2:
        pytest.skip("one core: the automatic choice never starts a pool")
    monkeypatch.setattr(parallel, "POOL_MIN_SECONDS", 0.0)
    pooled = coverage(canyon, [-60, 0, 10], grid, OPTIONS, settings=CoverageOptions(tile_size=8))
    assert pooled.metadata["workers"].startswith("local pool of ")
    assert_same_map(pooled, in_process)


def test_threads_must_be_positive():
    from wavepaths.errors import WavepathsError

    for bad in (0, -1, 1.5):
        with pytest.raises(WavepathsError, match="threads"):
            CoverageOptions(threads=bad)


def test_local_process_pool_gives_the_same_map(canyon, grid, in_process):
    pooled = coverage(canyon, [-60, 0, 10], grid, OPTIONS, settings=CoverageOptions(workers=2, tile_size=8))
    assert pooled.metadata["workers"] == "local pool of 2 processes"
    assert pooled.metadata["tiles"] > 2
    assert_same_map(pooled, in_process)


def test_tolerance_travels_to_the_pool_and_gives_the_same_map(canyon, grid):
    """tolerance_db rides on the transmitter context's options: a pool of two processes drops
    the same diffracted contributions as this process does, tile for tile."""
    opts = OPTIONS.with_(tolerance_db=0.5)
    here = coverage(canyon, [-60, 0, 10], grid, opts, settings=CoverageOptions(workers=1, tile_size=8, coherent=False))
    pooled = coverage(canyon, [-60, 0, 10], grid, opts, settings=CoverageOptions(workers=2, tile_size=8, coherent=False))
    assert pooled.metadata["workers"] == "local pool of 2 processes"
    assert here.stats["tolerance_dropped_candidates"] == pooled.stats["tolerance_dropped_candidates"] > 0
    assert_same_map(pooled, here)


def test_dask_cluster_gives_the_same_map(canyon, grid, in_process):
    distributed = pytest.importorskip("distributed")
    # two small worker processes: the scene and the context really travel (pickled, Embree rebuilt there)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client:
            on_dask = coverage(canyon, [-60, 0, 10], grid, OPTIONS, settings=CoverageOptions(tile_size=8),
                               client=client)
    assert on_dask.metadata["workers"].startswith("dask ")
    assert_same_map(on_dask, in_process)


def test_a_finished_map_holds_no_tiles_paths(canyon, grid):
    """Each tile's paths are summed and let go: a map keeps no tile's Paths alive (a review found
    a cache that never hit, keyed by each tile's new Paths, holding the last 16 tiles: 270 MB of a
    500 MB street-canyon map at R3+D2)."""
    import gc

    from wavepaths.search.paths import Paths

    def alive() -> int:
        gc.collect()
        return sum(isinstance(o, Paths) for o in gc.get_objects())

    before = alive()
    m = coverage(canyon, [-60, 0, 10], grid, OPTIONS, settings=CoverageOptions(workers=1, threads=1, tile_size=8))
    assert m.stats["rays_cast"] > 0 and np.nansum(m.num_paths) > 0
    assert alive() == before
