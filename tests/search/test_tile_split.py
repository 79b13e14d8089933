"""Tiles whose receivers' image trees together exceed the guard are traced in halves."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths.errors import ImageTreeTooLarge
from wavepaths.scene import load_scene
from wavepaths.search import TraceOptions, images, trace
from wavepaths.search.tile import RX_VISIBILITY_GROUP

from .helpers import path_keys

TX = np.array([[-60.0, 0.0, 10.0]])


def _receivers(rng, n: int) -> np.ndarray:
    return np.column_stack([rng.uniform(-90, 90, n), rng.uniform(-9, 9, n), np.full(n, 1.5)])


def _guard_counts(scene, rx: np.ndarray, order: int) -> np.ndarray:
    """(n,) int: per receiver alone, the largest count the guard of build_image_levels sees
    (order 1 before the hidden-mirror culling, which runs after the guard)."""
    out = []
    for r in rx:
        st: dict = {}
        lv = images.build_image_levels(scene, r[None], order, True, st, visibility_group=RX_VISIBILITY_GROUP)
        first = len(lv[1]) + st.get("images_order_1_culled_hidden", 0)
        out.append(max([first] + [len(x) for x in lv[2:]]))
    return np.array(out)


def test_a_tile_over_the_guard_is_split_and_finds_the_same_paths(monkeypatch, rng):
    scene = load_scene("street_canyon")
    rx = _receivers(rng, 10)
    opts = TraceOptions(max_reflections=1, diffraction=True, diffraction_reflections=2, rx_batch=10)
    ref = trace(scene, TX, rx, opts)
    counts = _guard_counts(scene, rx, 2)
    assert counts.sum() > counts.max()  # the whole tile is over a guard at the largest single count
    monkeypatch.setattr(images, "MAX_IMAGES", int(counts.max()))
    got = trace(scene, TX, rx, opts)
    assert got.stats["rx_tile_splits"] >= 1
    assert ref.stats.get("rx_tile_splits", 0) == 0
    assert len(ref) > 0 and path_keys(got) == path_keys(ref)
    # a single receiver over the guard: the error names it, nothing is silently dropped
    monkeypatch.setattr(images, "MAX_IMAGES", int(counts.min()) - 1)
    with pytest.raises(ImageTreeTooLarge, match="image tree of order"):
        trace(scene, TX, rx, opts)


def test_a_split_coverage_tile_with_a_tolerance_keeps_its_receivers(monkeypatch, rng):
    """With ``tolerance_db`` the diffracted candidates are held back per tile (their receiver
    indices local to the tile): after a split they must still land on their own cells."""
    from wavepaths.coverage import CoverageOptions, PlanarGrid, coverage
    from wavepaths.fields import FieldConfig

    scene = load_scene("street_canyon")
    grid = PlanarGrid(center=[0.0, 0.0], height=1.5, size=[40.0, 16.0], cell_size=4.0)
    opts = TraceOptions(max_reflections=1, diffraction=True, diffraction_reflections=2, tolerance_db=0.5)
    settings = CoverageOptions(workers=1, coherent=False)
    cfg = FieldConfig(3.5e9)
    ref = coverage(scene, TX, grid, opts, fields=cfg, settings=settings)
    counts = _guard_counts(scene, grid.cell_centers().reshape(-1, 3), 2)
    monkeypatch.setattr(images, "MAX_IMAGES", int(counts.max()))
    got = coverage(scene, TX, grid, opts, fields=cfg, settings=settings)
    assert got.stats["rx_tile_splits"] >= 1
    assert np.array_equal(np.nan_to_num(got.num_paths), np.nan_to_num(ref.num_paths))
    assert np.allclose(got.path_gain_db(), ref.path_gain_db(), rtol=0, atol=1e-9, equal_nan=True)
