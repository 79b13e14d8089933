"""The numba twin of :func:`wavepaths.search.through_vertices.reflection_chords_numpy`: the
chords between the legs at every reflection point, in one pass over the paths. Imported
only when numba is installed."""

import math

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def reflection_chords(V, kinds, prim, normal, chord, height):
    """``(A, B, row)``: the chords' ends (m, 3) and their paths (m,), as the numpy reference."""
    n, d = kinds.shape
    count = 0
    for i in range(n):
        for j in range(d):
            if kinds[i, j] == 1:
                count += 1
    A = np.empty((count, 3))
    B = np.empty((count, 3))
    row = np.empty(count, np.int64)
    m = 0
    for i in range(n):
        for j in range(d):
            if kinds[i, j] != 1:
                continue
            ax = V[i, j, 0] - V[i, j + 1, 0]
            ay = V[i, j, 1] - V[i, j + 1, 1]
            az = V[i, j, 2] - V[i, j + 1, 2]
            bx = V[i, j + 2, 0] - V[i, j + 1, 0]
            by = V[i, j + 2, 1] - V[i, j + 1, 1]
            bz = V[i, j + 2, 2] - V[i, j + 1, 2]
            la = math.sqrt(ax * ax + ay * ay + az * az)
            lb = math.sqrt(bx * bx + by * by + bz * bz)
            if not (la > 0.0 and lb > 0.0):
                continue
            ax /= la
            ay /= la
            az /= la
            bx /= lb
            by /= lb
            bz /= lb
            q = prim[i, j]
            cos_t = abs(ax * normal[q, 0] + ay * normal[q, 1] + az * normal[q, 2])
            cap = 0.25 * min(la, lb)
            if not (cap * cos_t >= height):  # decided before dividing: no rounding skips a chord
                continue
            delta = min(max(chord, height / cos_t), cap)
            A[m, 0] = V[i, j + 1, 0] + delta * ax
            A[m, 1] = V[i, j + 1, 1] + delta * ay
            A[m, 2] = V[i, j + 1, 2] + delta * az
            B[m, 0] = V[i, j + 1, 0] + delta * bx
            B[m, 1] = V[i, j + 1, 1] + delta * by
            B[m, 2] = V[i, j + 1, 2] + delta * bz
            row[m] = i
            m += 1
    return A[:m], B[:m], row[:m]
