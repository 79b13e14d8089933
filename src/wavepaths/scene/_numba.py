"""The numba twin of :func:`wavepaths.scene.polygon_query.points_in_polygons` (imported only
when numba is installed).

The numpy reference tests each query's polygon triangle slot by slot, a dozen passes over
fresh arrays per slot; here each query is one loop over its polygon's triangles with an
early exit, the same arithmetic in the same order (so the same answers, bit for bit).
"""

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def points_in_polygons(points, polygons, ptr, polygon_tris, triangles, vertices, dual, eps):
    k = points.shape[0]
    out = np.zeros(k, dtype=np.bool_)
    for i in range(k):
        q = polygons[i]
        for s in range(ptr[q], ptr[q + 1]):
            t = polygon_tris[s]
            o = triangles[t, 0]
            r0 = points[i, 0] - vertices[o, 0]
            r1 = points[i, 1] - vertices[o, 1]
            r2 = points[i, 2] - vertices[o, 2]
            v = dual[t, 0, 0] * r0 + dual[t, 0, 1] * r1 + dual[t, 0, 2] * r2
            w = dual[t, 1, 0] * r0 + dual[t, 1, 1] * r1 + dual[t, 1, 2] * r2
            if v >= -eps and w >= -eps and v + w <= 1 + eps:
                out[i] = True
                break
    return out


@numba.njit(cache=True, nogil=True)
def points_near_segments(P, O, U, L, margin, edge, dist):
    """The compiled twin of :func:`wavepaths.search.on_faces.points_near_edges`' loop: for each
    point of ``P`` (n, 3), the nearest segment ``O + t U``, ``0 <= t <= L`` (d of them), within
    ``margin``, written into ``edge`` (n,) and ``dist`` (n,) (left as given where none is). The
    same arithmetic as the numpy loop, in the same order."""
    for i in range(P.shape[0]):
        p0, p1, p2 = P[i, 0], P[i, 1], P[i, 2]
        best = margin
        found = -1
        for k in range(O.shape[0]):
            w0, w1, w2 = p0 - O[k, 0], p1 - O[k, 1], p2 - O[k, 2]
            t = (w0 * U[k, 0] + w1 * U[k, 1]) + w2 * U[k, 2]
            t = min(max(t, 0.0), L[k])
            e0, e1, e2 = w0 - t * U[k, 0], w1 - t * U[k, 1], w2 - t * U[k, 2]
            d = np.sqrt((e0 * e0 + e1 * e1) + e2 * e2)
            if d < best or (d == best and found < 0):
                best = d
                found = k
        if found >= 0:
            edge[i] = found
            dist[i] = best
