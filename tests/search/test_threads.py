"""trace() on several threads: tiles traced at once give the paths of one thread, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths import TraceOptions, WavepathsError, trace
from wavepaths.scene import load_scene

TX = np.array([[-60.0, 0.0, 10.0]])


def _receivers(rng, n: int) -> np.ndarray:
    street = rng.uniform(size=n) < 0.5
    y = np.where(street, rng.uniform(-9, 9, n), np.sign(rng.uniform(-1, 1, n)) * rng.uniform(27, 39, n))
    return np.column_stack([rng.uniform(-95, 95, n), y, np.full(n, 1.5)])


@pytest.mark.parametrize("compiled", [True, False])
def test_threads_give_the_same_paths_and_counts(rng, compiled):
    """Scattered receivers (the flat reflection query) and a cluster of them (the chain-beam
    tree, built on first use by whichever tile needs it first): every array of the result
    equals that of one thread; every counter equals that of one thread with the same tiles
    (the culling counters depend on the tiling, not on the threads); progress reaches every
    receiver, in order."""
    scene = load_scene("street_canyon")
    g = np.linspace(-2.0, 2.0, 6)
    cluster = np.stack(np.meshgrid(g + 20.0, g, [1.5], indexing="ij"), axis=-1).reshape(-1, 3)
    rx = np.concatenate([_receivers(rng, 40), cluster])
    opts = TraceOptions(max_reflections=3, diffraction=True, diffraction_reflections=2, compiled=compiled)
    ref = trace(scene, TX, rx, opts, threads=1)
    assert len(ref) > 1000
    for n in (2, 3):
        seen: list[int] = []
        got = trace(scene, TX, rx, opts, threads=n, progress=seen.append)
        assert seen == sorted(seen) and seen[-1] == len(rx) and len(seen) >= 2 * n  # several tiles ran
        for name in ("tx_index", "rx_index", "depth", "interactions", "primitive", "triangle", "wedge_faces",
                     "vertices"):
            np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)
        size = -(-len(rx) // (2 * n))  # the tiles trace() cuts for n threads
        same_tiles = trace(scene, TX, rx, opts.with_(rx_batch=size), threads=1)
        assert got.stats == same_tiles.stats


def test_threads_must_be_positive():
    scene = load_scene("street_canyon")
    for bad in (0, -1, 1.5, "2", True):  # (1.5 was taken as 1)
        with pytest.raises(WavepathsError, match="`threads` must be a positive integer"):
            trace(scene, TX, np.array([[20.0, 0.0, 1.5]]), threads=bad)
