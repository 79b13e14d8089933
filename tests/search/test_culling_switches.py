"""Every conservative culling test can be switched off, and switching it off finds the same paths."""

from __future__ import annotations

import re

import numpy as np
import pytest

from wavepaths.errors import WavepathsError
from wavepaths.scene import load_scene
from wavepaths.search import TraceOptions, kernels, trace
from wavepaths.search.options import CULLING_COUNTERS, CULLING_TESTS

from .helpers import path_keys


def _street_receivers(rng, n: int) -> np.ndarray:
    """(n, 3) receivers at 1.5 m in the built-in street canyon: in the street (|y| < 10) or
    behind the buildings (|y| > 25), never inside them."""
    street = rng.uniform(size=n) < 0.5
    y = np.where(street, rng.uniform(-9, 9, n), np.sign(rng.uniform(-1, 1, n)) * rng.uniform(27, 39, n))
    return np.column_stack([rng.uniform(-95, 95, n), y, np.full(n, 1.5)])


@pytest.mark.parametrize("name", sorted(CULLING_TESTS))
def test_switching_a_culling_test_off_keeps_every_path_and_rejects_nothing_by_it(name, rng):
    if name == "receiver_aperture" and not kernels.available():
        pytest.skip("the receiver aperture test runs in the compiled kernel only (numba, the `fast` extra)")
    scene = load_scene("street_canyon")
    rx = _street_receivers(rng, 40)
    tx = np.array([[-60.0, 0.0, 10.0]])
    opts = TraceOptions(max_reflections=1, diffraction=True, diffraction_reflections=2, rx_batch=2)
    on = trace(scene, tx, rx, opts)
    off = trace(scene, tx, rx, opts.with_(disable_culling={name}))
    assert len(on) > 0
    assert path_keys(on) == path_keys(off)
    culled = {k: v for k, v in on.stats.items() if re.fullmatch(CULLING_COUNTERS[name], k)}
    assert sum(culled.values()) > 0, f"{name} culled nothing here: the test would not show it is safe"
    assert all(v == 0 for k, v in off.stats.items() if k in culled)


def test_unknown_culling_test_is_an_error():
    with pytest.raises(WavepathsError, match="unknown culling"):
        TraceOptions(disable_culling={"no_such_test"})


def test_receiver_side_by_edge_tree_finds_the_same_paths_as_the_dense_one(monkeypatch, rng):
    """The two implementations of the numpy receiver side (dense products, edge-tree queries)
    agree (the tree runs without the reach lists, which send every pair to the dense form;
    the compiled receiver side is always dense)."""
    import wavepaths.search.diffraction as diffraction

    scene = load_scene("street_canyon")
    rx = _street_receivers(rng, 30)
    tx = np.array([[-60.0, 0.0, 10.0]])
    opts = TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=2, rx_batch=8, compiled=False)
    dense = trace(scene, tx, rx, opts)
    monkeypatch.setattr(diffraction, "DENSE_RECEIVER_SIDE_MAX_DIHEDRA", 0)
    tree = trace(scene, tx, rx, opts.with_(disable_culling={"mirror_reach"}))
    assert not any("rejected_mirror_side" in k for k in tree.stats)  # the tree path ran
    assert any("rejected_mirror_side" in k for k in dense.stats)
    assert len(dense) > 0
    assert path_keys(dense) == path_keys(tree)
