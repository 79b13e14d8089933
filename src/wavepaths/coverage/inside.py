"""Which points lie inside a solid object (a building), by ray parity.

A coverage cell whose centre lies inside a building has no meaningful field: the map
marks it NaN instead of tracing it. An object counts as *solid* when its triangles close
it up, except perhaps for an opening at its base (city meshes often leave out the
floor of each building): every edge is shared by exactly two of the object's triangles,
or by one when the edge lies at the object's lowest ``z``. Flat objects (a ground plane)
are never solid.

A point is inside a solid when an upward ray from it crosses that object's triangles an
odd number of times (the open base cannot be crossed by a ray going up). Rays are cast
along three generic upward directions and the majority decides, so a ray that passes
exactly through an edge or a vertex (float64 ties on regular grids) cannot flip the
answer alone. The crossings are counted in float64 with numpy: a shear along the ray
direction turns every ray vertical, triangles are binned on a 2-D hash grid of the
sheared plane, and each (point, triangle) pair in the same bin gets a 2-D
point-in-triangle test and a height comparison. No Embree, no float32.

Points lying exactly on a surface of a solid are on its boundary: either answer may come.
Overlapping solids of one object (intersecting meshes merged into one object) break the
parity of that object; separate objects may overlap freely.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene

# Three upward directions, tilted ~7 degrees in unrelated azimuths: generic with respect
# to the axis-aligned edges of buildings and to regular grids.
RAY_DIRECTIONS = np.array(
    [[0.1234567, 0.0456789, 1.0], [-0.0876543, 0.1012345, 1.0], [0.0432109, -0.1376543, 1.0]]
)
PAIR_BUDGET = 1 << 21  # (point, triangle) pairs tested at once


@dataclass(frozen=True)
class SolidObjects:
    """The solid objects of a scene (see module docstring).

    Attributes
    ----------
    objects : (s,) int64
        Object ids (indices into ``scene.object_names``).
    closed : (s,) bool
        False for a solid whose base is open.
    base_z : (s,) float64 [m]
        Lowest ``z`` of each solid.
    triangles : (t,) int64
        Scene triangles of the solids.
    triangle_solid : (t,) int64
        Row in ``objects`` of each of those triangles.
    """

    objects: np.ndarray
    closed: np.ndarray
    base_z: np.ndarray
    triangles: np.ndarray
    triangle_solid: np.ndarray

    def __len__(self) -> int:
        return len(self.objects)


def solid_objects(scene: "Scene") -> SolidObjects:
    """Find the objects of ``scene`` that are closed, or open only at their base."""
    inc = scene.incidence
    n_obj = max(len(scene.object_names), int(scene.triangle_object.max()) + 1)
    tol = scene.length_tolerance(scene.tolerances.plane_distance)
    tri_z = scene.vertices[scene.triangles][:, :, 2]
    zmin = np.full(n_obj, np.inf)
    zmax = np.full(n_obj, -np.inf)
    np.minimum.at(zmin, scene.triangle_object, tri_z.min(axis=1))
    np.maximum.at(zmax, scene.triangle_object, tri_z.max(axis=1))

    edge = np.repeat(np.arange(len(inc.edges)), inc.counts)
    key = edge * n_obj + scene.triangle_object[inc.incidence_tri]
    uk, count = np.unique(key, return_counts=True)
    e, o = uk // n_obj, uk % n_obj
    edge_z = scene.vertices[inc.edges[e]][:, :, 2].max(axis=1)
    at_base = edge_z <= zmin[o] + tol
    bad = (count > 2) | ((count == 1) & ~at_base)
    open_base = (count == 1) & at_base
    is_bad = np.zeros(n_obj, bool)
    is_bad[o[bad]] = True
    has_opening = np.zeros(n_obj, bool)
    has_opening[o[open_base]] = True
    present = np.isfinite(zmin)
    solid = present & ~is_bad & (zmax - zmin > tol)
    objects = np.nonzero(solid)[0]
    row = np.full(n_obj, -1)
    row[objects] = np.arange(len(objects))
    tris = np.nonzero(solid[scene.triangle_object])[0]
    return SolidObjects(objects, ~has_opening[objects], zmin[objects], tris, row[scene.triangle_object[tris]])


def inside_solid_objects(scene: "Scene", points: np.ndarray, solids: SolidObjects | None = None) -> np.ndarray:
    """(k,) bool: whether each point (k, 3) [m] lies inside a solid object of ``scene``.

    ``points`` must be finite (callers check). See the module docstring for the rule.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    solids = solid_objects(scene) if solids is None else solids
    if len(solids) == 0 or len(points) == 0:
        return np.zeros(len(points), bool)
    corners = scene.vertices[scene.triangles[solids.triangles]]  # (t, 3, 3)
    tol = scene.length_tolerance(scene.tolerances.plane_distance)
    votes = np.zeros(len(points), np.int64)
    for d in RAY_DIRECTIONS:
        votes += _odd_crossings(points, corners, solids, d, tol)
    return votes >= 2


def _odd_crossings(points: np.ndarray, corners: np.ndarray, solids: SolidObjects, direction: np.ndarray,
                   tol: float) -> np.ndarray:
    """(k,) bool: an odd number of crossings of one solid along the ray ``p + t direction``, t > 0."""
    slope = direction[:2] / direction[2]
    p2 = points[:, :2] - points[:, 2:3] * slope  # sheared: the ray becomes vertical
    c2 = corners[:, :, :2] - corners[:, :, 2:3] * slope
    cz = corners[:, :, 2]
    # barycentric maps in the sheared plane; rays parallel to a triangle never cross it
    e1 = c2[:, 1] - c2[:, 0]
    e2 = c2[:, 2] - c2[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    area_tol = 1e-12 * np.maximum(np.abs(e1).max(axis=1), np.abs(e2).max(axis=1)) ** 2
    live = np.abs(det) > area_tol
    c2, cz, e1, e2, det = c2[live], cz[live], e1[live], e2[live], det[live]
    owner = solids.triangle_solid[live]
    if len(det) == 0:
        return np.zeros(len(points), bool)

    # hash grid over the sheared plane: (triangle, bin) pairs, sorted by bin
    lo_t, hi_t = c2.min(axis=1), c2.max(axis=1)
    extent = hi_t.max(axis=0) - lo_t.min(axis=0)
    bin_size = max(float(np.median((hi_t - lo_t).max(axis=1))), float(extent.max()) / 4096, 1e-9)
    origin = lo_t.min(axis=0)
    ix0, iy0 = np.floor((lo_t - origin) / bin_size).astype(np.int64).T
    ix1, iy1 = np.floor((hi_t - origin) / bin_size).astype(np.int64).T
    nbx = int(ix1.max()) + 1
    wx, wy = ix1 - ix0 + 1, iy1 - iy0 + 1
    per_tri = wx * wy
    tri = np.repeat(np.arange(len(det)), per_tri)
    local = np.arange(len(tri)) - np.repeat(np.cumsum(per_tri) - per_tri, per_tri)
    bx = ix0[tri] + local % wx[tri]
    by = iy0[tri] + local // wx[tri]
    key = by * nbx + bx
    order = np.argsort(key, kind="stable")
    tri, key = tri[order], key[order]
    uk, start, count = np.unique(key, return_index=True, return_counts=True)

    pb = np.floor((p2 - origin) / bin_size).astype(np.int64)
    in_range = (pb[:, 0] >= 0) & (pb[:, 0] < nbx) & (pb[:, 1] >= 0) & (pb[:, 1] <= int(iy1.max()))
    pkey = np.where(in_range, pb[:, 1] * nbx + pb[:, 0], -1)
    pos = np.clip(np.searchsorted(uk, pkey), 0, len(uk) - 1)
    match = in_range & (uk[pos] == pkey)
    n_cand = np.where(match, count[pos], 0)

    odd = np.zeros(len(points), bool)
    # points in blocks whose candidate pairs fit the budget
    cum = np.cumsum(n_cand)
    s = 0
    while s < len(points):
        base = cum[s - 1] if s else 0
        e = int(np.searchsorted(cum, base + PAIR_BUDGET, side="right"))
        e = max(e, s + 1)
        rows = np.arange(s, e)
        cnt = n_cand[rows]
        pi = np.repeat(rows, cnt)
        offs = np.arange(len(pi)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        ti = tri[np.repeat(start[pos[rows]], cnt) + offs]
        q = p2[pi] - c2[ti, 0]
        w1 = (q[:, 0] * e2[ti, 1] - q[:, 1] * e2[ti, 0]) / det[ti]
        w2 = (e1[ti, 0] * q[:, 1] - e1[ti, 1] * q[:, 0]) / det[ti]
        w0 = 1.0 - w1 - w2
        hit = (w0 >= 0) & (w1 >= 0) & (w2 >= 0)
        z_hit = w0 * cz[ti, 0] + w1 * cz[ti, 1] + w2 * cz[ti, 2]
        hit &= z_hit > points[pi, 2]
        pi, so = pi[hit], owner[ti[hit]]
        pair = pi * len(solids) + so
        up, n = np.unique(pair, return_counts=True)
        p_odd, s_odd = up[n % 2 == 1] // len(solids), up[n % 2 == 1] % len(solids)
        # below an open base the ray enters without crossing: not inside
        ok = solids.closed[s_odd] | (points[p_odd, 2] >= solids.base_z[s_odd] - tol)
        odd[p_odd[ok]] = True
        s = e
    return odd
