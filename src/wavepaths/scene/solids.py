"""Which points lie inside a solid (a building), by ray parity.

A coverage cell whose centre lies inside a building has no meaningful field: the map
marks it NaN instead of tracing it. Solids are found on the triangle mesh itself, across
object boundaries (Sionna RT's city scenes split each building into a wall object and a
roof object, neither closed alone): the scene's triangles are grouped into connected
components through shared edges, and a component is *solid* when every edge of it is
shared by an even number of its triangles, except edges at the component's lowest
``z``, which may border one (city meshes often leave out the floor of each building).
Such a surface bounds a region in the mod-2 sense, so ray parity is well defined even
where blocks touch along an edge (four triangles) or share a wall. Flat components (a
ground plane alone) are never solid. In a component that does not bound a region (a block
with an awning hinged on its roof edge), each object that does by itself is a solid.

A point is inside a solid when an upward ray from it crosses that component's triangles
an odd number of times (a ray going up cannot cross the open base); below the base of an
open component nothing is inside. Rays are cast along three generic upward directions
and the majority decides, so a ray that passes exactly through an edge or a vertex
(float64 ties on regular grids) cannot flip the answer alone. The crossings are counted
in float64 with numpy: a shear along the ray direction turns every ray vertical,
triangles are binned on a 2-D hash grid of the sheared plane, and each (point,
triangle) pair in the same bin gets a 2-D point-in-triangle test and a height
comparison. No Embree, no float32.

Points lying exactly on a surface of a solid are on its boundary: either answer may come.
A solid written double-sided (every face twice, as some exporters do) would cancel every
crossing; its triangles count once each (:func:`_undoubled`).

This is wavepaths' one "is a point inside" rule: :mod:`wavepaths.scene.closed` applies it
(:func:`inside_solids`, per solid) to transmitters inside closed objects and to the sides of
coincident faces (contact faces).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

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
    """The solids of a scene: connected triangle components that bound a region.

    Attributes
    ----------
    objects : (s,) object array of tuple of int
        For each solid, the object ids (indices into ``scene.object_names``) its
        triangles belong to.
    closed : (s,) bool
        False for a solid whose base is open.
    base_z : (s,) float64 [m]
        Lowest ``z`` of each solid.
    triangles : (t,) int64
        Scene triangles of the solids.
    triangle_solid : (t,) int64
        Solid (row of the arrays above) of each of those triangles.
    """

    objects: np.ndarray
    closed: np.ndarray
    base_z: np.ndarray
    triangles: np.ndarray
    triangle_solid: np.ndarray

    def __len__(self) -> int:
        return len(self.closed)


def _bounding_groups(scene: "Scene", label: np.ndarray, tol: float):
    """For triangle groups ``label`` (f,) int64 numbered 0..g-1: which bound a region.

    Returns ``good`` (g,) bool, ``closed`` (g,) bool and ``base_z`` (g,) float64: every edge
    borders an even number of the group's triangles, except at the group's lowest ``z``;
    the group is not flat.
    """
    g = int(label.max()) + 1
    inc = scene.incidence
    tri_z = scene.vertices[scene.triangles][:, :, 2]
    zmin = np.full(g, np.inf)
    zmax = np.full(g, -np.inf)
    np.minimum.at(zmin, label, tri_z.min(axis=1))
    np.maximum.at(zmax, label, tri_z.max(axis=1))
    edge = np.repeat(np.arange(len(inc.edges)), inc.counts)
    key, count = np.unique(edge * g + label[inc.incidence_tri], return_counts=True)
    e, grp = key // g, key % g
    odd = count % 2 == 1
    at_base = scene.vertices[inc.edges[e]][:, :, 2].max(axis=1) <= zmin[grp] + tol
    bad = np.zeros(g, bool)
    bad[grp[odd & ~at_base]] = True
    opening = np.zeros(g, bool)
    opening[grp[odd & at_base]] = True
    return ~bad & (zmax - zmin > tol), ~opening, zmin


def solid_objects(scene: "Scene") -> SolidObjects:
    """Find the solids of ``scene`` (see the module docstring).

    Connected components that bound a region are solids; in a component that does not
    (a block with an awning hinged on its roof edge), each object that bounds a region by
    itself is one.
    """
    inc = scene.incidence
    f = scene.num_triangles
    tol = scene.length_tolerance(scene.tolerances.plane_distance)
    edge = np.repeat(np.arange(len(inc.edges)), inc.counts)  # edge of each incidence entry
    same = edge[1:] == edge[:-1]
    a, b = inc.incidence_tri[:-1][same], inc.incidence_tri[1:][same]
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(f, f))
    n_comp, comp = connected_components(graph, directed=False)
    good_c, closed_c, base_c = _bounding_groups(scene, comp, tol)
    # fallback inside components that do not bound a region: their objects one by one
    _, part = np.unique(comp * (int(scene.triangle_object.max()) + 1) + scene.triangle_object, return_inverse=True)
    part = part.reshape(-1)
    good_p, closed_p, base_p = _bounding_groups(scene, part, tol)
    use_comp = good_c[comp]
    use_part = ~use_comp & good_p[part]
    tris = np.nonzero(use_comp | use_part)[0]
    # one numbering for both kinds: components first, then parts
    key = np.where(use_comp[tris], comp[tris], n_comp + part[tris])
    ids, owner = np.unique(key, return_inverse=True)
    owner = owner.reshape(-1)
    is_comp = ids < n_comp
    closed = np.where(is_comp, closed_c[np.minimum(ids, n_comp - 1)], closed_p[np.maximum(ids - n_comp, 0)])
    base_z = np.where(is_comp, base_c[np.minimum(ids, n_comp - 1)], base_p[np.maximum(ids - n_comp, 0)])
    tris, owner = _undoubled(scene, tris, owner)
    pairs = np.unique(np.stack([owner, scene.triangle_object[tris]], axis=1), axis=0)  # sorted by solid
    groups = np.split(pairs[:, 1], np.cumsum(np.bincount(pairs[:, 0], minlength=len(ids)))[:-1])
    objects = np.empty(len(ids), dtype=object)
    objects[:] = [tuple(g.tolist()) for g in groups]
    return SolidObjects(objects, closed, base_z, tris, owner)


def _undoubled(scene: "Scene", tris: np.ndarray, owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``tris`` (with their solids ``owner``) with each doubled solid halved.

    A double-sided export writes every face twice (the same corners, either winding): each
    crossing then counts twice and ray parity calls every point outside. A solid in which
    every triangle (by its corners) occurs an even number of times keeps half of each, if
    that half bounds a region (every edge in an even number of its triangles but at its
    base); in any other solid coincident triangles stay (two touching buildings' faces on
    their shared wall, both counted, leave it inside neither's region: the parity of their
    union).
    """
    corners = np.sort(scene.triangles[tris], axis=1)
    _, first, inverse, counts = np.unique(np.column_stack([owner, corners]), axis=0, return_index=True,
                                          return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    doubled = np.ones(int(owner.max()) + 1 if len(owner) else 0, bool)
    np.logical_and.at(doubled, owner[first], counts % 2 == 0)
    if not doubled.any():
        return tris, owner
    # the k-th copy of each triangle, by position: the first half of the copies kept
    order = np.argsort(inverse, kind="stable")
    rank = np.empty(len(tris), np.int64)
    rank[order] = np.arange(len(tris)) - np.repeat(np.cumsum(counts) - counts, counts)
    keep = ~doubled[owner] | (rank < counts[inverse] // 2)
    # a doubled solid whose half bounds no region (a wall duplicated in two objects, a flat
    # sheet) keeps no triangle: never inside, as when its copies cancelled
    half = keep & doubled[owner]
    tri = scene.triangles[tris[half]]
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    solid = np.tile(owner[half], 3)
    key, n = np.unique(np.column_stack([solid, edges]), axis=0, return_counts=True)
    z = scene.vertices[:, 2]
    zmin = np.full(len(doubled), np.inf)
    np.minimum.at(zmin, owner[half], z[tri].min(axis=1))
    tol = scene.length_tolerance(scene.tolerances.plane_distance)
    open_edge = (n % 2 == 1) & (np.maximum(z[key[:, 1]], z[key[:, 2]]) > zmin[key[:, 0]] + tol)
    broken = np.zeros(len(doubled), bool)
    broken[key[open_edge, 0]] = True
    keep &= ~broken[owner]
    return tris[keep], owner[keep]


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
        odd = np.zeros(len(points), bool)
        odd[_odd_crossings(points, corners, solids, d, tol)[0]] = True
        votes += odd
    return votes >= 2


def inside_solids(scene: "Scene", points: np.ndarray, solids: SolidObjects) -> np.ndarray:
    """(k, s) bool: whether each point (k, 3) [m] lies inside each solid (the same rule, per solid).

    Dense in points x solids: meant for a few points (transmitters, test points).
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    votes = np.zeros((len(points), len(solids)), np.int64)
    if len(solids) == 0 or len(points) == 0:
        return votes > 0
    corners = scene.vertices[scene.triangles[solids.triangles]]
    tol = scene.length_tolerance(scene.tolerances.plane_distance)
    for d in RAY_DIRECTIONS:
        p, s = _odd_crossings(points, corners, solids, d, tol)
        votes[p, s] += 1
    return votes >= 2


def _odd_crossings(points: np.ndarray, corners: np.ndarray, solids: SolidObjects, direction: np.ndarray,
                   tol: float) -> tuple[np.ndarray, np.ndarray]:
    """The (point, solid) pairs crossed an odd number of times by the ray ``p + t direction``, t > 0.

    Returns two (m,) int64 arrays, each pair once.
    """
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
        return np.zeros(0, np.int64), np.zeros(0, np.int64)

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

    out_p, out_s = [], []
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
        out_p.append(p_odd[ok])
        out_s.append(s_odd[ok])
        s = e
    return np.concatenate(out_p).astype(np.int64), np.concatenate(out_s).astype(np.int64)
