"""Ragged (CSR) array helpers shared across stages."""

from __future__ import annotations

import numpy as np


def ranks(count: np.ndarray) -> np.ndarray:
    """``0 .. count[i] - 1`` for each ``i``, concatenated (the position of each element of a
    ragged array within its row, rows of ``count`` elements)."""
    count = np.asarray(count)
    return np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
