"""The receiver-to-transmitter join of the diffraction search, chunked to bound memory."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths.search.context import DiffractionSources
from wavepaths.search.diffraction import _join_chunks


def sources(keys: np.ndarray) -> DiffractionSources:
    o = np.argsort(keys, kind="stable")
    k = keys[o]
    uk, start, count = np.unique(k, return_index=True, return_counts=True)
    return DiffractionSources(o, np.zeros(len(k), np.int64), k, uk, start.astype(np.int64), count.astype(np.int64))


@pytest.mark.parametrize("budget", [1, 7, 100, 10**9])
def test_chunks_are_the_full_join_and_respect_the_budget(rng, budget):
    src = sources(rng.integers(0, 40, 300))
    keys = rng.integers(-5, 50, 500)
    pairs, sizes = [], []
    for rows, src_rows in _join_chunks(src, keys, budget):
        assert (src.key[src_rows] == keys[rows]).all()
        pairs += list(zip(rows.tolist(), src_rows.tolist()))
        sizes.append((len(rows), len(np.unique(rows))))
    ref = [(i, j) for i in range(len(keys)) for j in range(len(src.key)) if src.key[j] == keys[i]]
    assert sorted(pairs) == sorted(ref)
    # a chunk exceeds the budget only when it holds a single receiver-side row
    assert all(n <= budget or u == 1 for n, u in sizes)


def test_no_sources_or_no_keys_yield_nothing(rng):
    assert list(_join_chunks(sources(np.zeros(0, np.int64)), np.arange(5))) == []
    assert list(_join_chunks(sources(np.arange(5)), np.zeros(0, np.int64))) == []
    assert list(_join_chunks(sources(np.arange(5)), np.arange(10, 20))) == []
