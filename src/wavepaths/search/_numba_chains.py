"""The numba twin of the degenerate-chain test of :func:`wavepaths.search.chains.occluded_chains`
(segments joining two interactions no longer than the weld tolerance, first or last
segments no longer than the plane tolerance). Imported only when numba is installed."""

import math

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def degenerate_chains(vertices, weld, plane_tol):
    """(k,) bool: :func:`wavepaths.search.chains.occluded_chains`' degenerate chains, one pass.

    A segment joining two interactions no longer than ``weld``, or (for chains with at least
    one interaction) a first or last segment no longer than ``plane_tol``; the same lengths
    (``sqrt`` of the summed squared differences) and comparisons as the numpy form.
    """
    k, s = vertices.shape[0], vertices.shape[1]
    out = np.zeros(k, dtype=np.bool_)
    for i in range(k):
        for j in range(s - 1):
            inner = 0 < j < s - 2
            end = s > 2 and (j == 0 or j == s - 2)
            if not (inner or end):
                continue
            d0 = vertices[i, j + 1, 0] - vertices[i, j, 0]
            d1 = vertices[i, j + 1, 1] - vertices[i, j, 1]
            d2 = vertices[i, j + 1, 2] - vertices[i, j, 2]
            length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if (inner and length <= weld) or (end and length <= plane_tol):
                out[i] = True
                break
    return out
