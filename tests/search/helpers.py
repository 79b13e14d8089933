"""Helpers shared by the path-search tests."""

from __future__ import annotations

import numpy as np


def path_keys(p) -> list:
    """(tx, rx, interactions, primitives, vertices rounded to 1e-6 m) of every path, sorted."""
    keys = []
    for i in range(len(p)):
        n = int(p.depth[i])
        keys.append((int(p.tx_index[i]), int(p.rx_index[i]), tuple(p.interactions[i, :n].tolist()),
                     tuple(p.primitive[i, :n].tolist()), tuple(np.round(p.vertices[i, : n + 2].ravel(), 6).tolist())))
    return sorted(keys)
