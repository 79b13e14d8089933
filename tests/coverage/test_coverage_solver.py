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
    grid = PlanarGrid(center=[0.0, 0.0], height=1.5, size=[60.0, 60.0], cell_size=4.0)
    first = coverage(scene, [[-60.0, 0.0, 10.0]], grid, opts, settings=settings)
    again = coverage(scene, [[-30.0, 0.0, 10.0]], grid, opts, settings=settings)
    fresh = inside_solid_objects(scene, grid.cell_centers().reshape(-1, 3)).reshape(first.inside.shape)
    assert first.inside.any() and np.array_equal(first.inside, fresh) and np.array_equal(again.inside, fresh)
    cache = scene.__dict__["_coverage_cache"]
    assert sum(k.startswith("inside:") for k in cache) == 1
    for i in range(INSIDE_CACHE_SIZE + 2):
        g = PlanarGrid(center=[float(i), 0.0], height=1.5, size=[20.0, 20.0], cell_size=4.0)
        m = coverage(scene, [[-60.0, 0.0, 10.0]], g, opts, settings=settings)
        assert np.array_equal(m.inside, inside_solid_objects(scene, g.cell_centers().reshape(-1, 3)).reshape(m.inside.shape))
    assert sum(k.startswith("inside:") for k in cache) == INSIDE_CACHE_SIZE
