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

