"""Compiled kernel of :mod:`wavepaths.search.launch` (numba)."""

from __future__ import annotations

import numba as nb


@nb.njit(parallel=True, cache=True)
def tube_contains(start, end, r0, r1, points, out):  # pragma: no cover - compiled
    """out[k, p]: point p lies within segment k's tube (radius r0 at ``start`` to r1 at
    ``end``, linear in the parameter of the point's closest point on the segment)."""
    for k in nb.prange(start.shape[0]):
        dx = end[k, 0] - start[k, 0]
        dy = end[k, 1] - start[k, 1]
        dz = end[k, 2] - start[k, 2]
        L2 = dx * dx + dy * dy + dz * dz
        for p in range(points.shape[0]):
            px = points[p, 0] - start[k, 0]
            py = points[p, 1] - start[k, 1]
            pz = points[p, 2] - start[k, 2]
            u = (px * dx + py * dy + pz * dz) / L2 if L2 > 0.0 else 0.0
            u = min(max(u, 0.0), 1.0)
            qx = px - u * dx
            qy = py - u * dy
            qz = pz - u * dz
            r = r0[k] + u * (r1[k] - r0[k])
            out[k, p] = qx * qx + qy * qy + qz * qz <= r * r
