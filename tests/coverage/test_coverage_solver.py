"""The coverage solver's per-scene caches."""

from __future__ import annotations

import numpy as np


def test_inside_mask_is_cached_per_scene_and_grid_and_bounded():
    """The inside-object mask depends only on the scene and the cell centres: a second map on
    the same grid reuses it (same mask), another grid gets its own, and at most
    INSIDE_CACHE_SIZE masks are kept."""
    from wavepaths.coverage import CoverageOptions, PlanarGrid, coverage
    from wavepaths.coverage.inside import inside_solid_objects
    from wavepaths.coverage.solver import INSIDE_CACHE_SIZE
    from wavepaths.scene import load_scene
    from wavepaths.search import TraceOptions

    scene = load_scene("street_canyon")
    opts = TraceOptions(max_reflections=0, diffraction=False)
    settings = CoverageOptions(workers=1)
    grid = PlanarGrid(center=[0.25, 0.25], height=1.5, size=[60.0, 60.0], cell_size=4.0)  # no centre on a wall
    first = coverage(scene, [[-60.0, 0.0, 10.0]], grid, opts, settings=settings)
    again = coverage(scene, [[-30.0, 0.0, 10.0]], grid, opts, settings=settings)
    fresh = inside_solid_objects(scene, grid.cell_centers().reshape(-1, 3)).reshape(first.inside.shape)
    assert first.inside.any() and np.array_equal(first.inside, fresh) and np.array_equal(again.inside, fresh)
    cache = scene.__dict__["_memo"]
    assert sum(k[0] == "inside" for k in cache if isinstance(k, tuple)) == 1
    for i in range(INSIDE_CACHE_SIZE + 2):
        # (a quarter metre off the integers: no cell centre on a wall, which would warn)
        g = PlanarGrid(center=[float(i) + 0.25, 0.25], height=1.5, size=[20.0, 20.0], cell_size=4.0)
        m = coverage(scene, [[-60.0, 0.0, 10.0]], g, opts, settings=settings)
        assert np.array_equal(m.inside, inside_solid_objects(scene, g.cell_centers().reshape(-1, 3)).reshape(m.inside.shape))
    assert sum(k[0] == "inside" for k in cache if isinstance(k, tuple)) == INSIDE_CACHE_SIZE


def test_a_tiles_sums_in_path_order_equal_the_sums_of_the_sorted_paths():
    """``solve_tile`` computes the fields of its paths unsorted and sorts only the per-path
    values before adding them per cell: every sum equals, to the last bit, the sum over
    the sorted paths (``assemble`` sorted, ``compute_fields``, ``np.bincount``)."""
    import numpy as np

    from wavepaths import TraceOptions, build_tx_context, load_scene
    from wavepaths.coverage import solve_tile
    from wavepaths.fields import FieldConfig, compute_fields
    from wavepaths.search.paths import assemble
    from wavepaths.search.tile import trace_tile

    scene = load_scene("street_canyon")
    tx = np.array([[-60.0, 0.0, 10.0]])
    rx = np.array([[40.0, 0.0, 1.5], [10.0, 0.0, 1.5], [-20.0, 3.0, 1.5], [25.0, -6.0, 1.5]])
    ctx = build_tx_context(scene, tx, TraceOptions(max_reflections=2, diffraction=True, diffraction_reflections=1))
    cfg = FieldConfig(3.5e9)
    sums = solve_tile(scene, ctx, cfg, rx)
    batches, stats = trace_tile(scene, ctx, rx)
    res = compute_fields(scene, assemble(tx, rx, batches, dict(stats)), cfg)
    ap = res.a_phased
    ref = np.bincount(res.paths.rx_index, ap.real, len(rx)) + 1j * np.bincount(res.paths.rx_index, ap.imag, len(rx))
    assert len(res.paths) > 40
    np.testing.assert_array_equal(sums.a_total[0], ref)
    np.testing.assert_array_equal(sums.num_paths.sum(axis=0)[0], np.bincount(res.paths.rx_index, minlength=len(rx)))
