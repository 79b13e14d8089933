"""Edges of a triangle soup and the triangles incident to each edge.

Pure functions on arrays, used by the polygon grouping and by the dihedron builder.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class EdgeIncidence:
    """The unique undirected edges of a triangle mesh and their incident triangles.

    Attributes
    ----------
    edges : (e, 2) int64
        Vertex indices of each edge, ``edges[:, 0] < edges[:, 1]``.
    triangle_edges : (f, 3) int64
        Edge index of each triangle side (side ``i`` joins corners ``i`` and ``i+1``).
    incidence_ptr : (e + 1,) int64
        CSR pointer: the triangles incident to edge ``j`` are
        ``incidence_tri[incidence_ptr[j]:incidence_ptr[j + 1]]``.
    incidence_tri : (sum of counts,) int64
        Incident triangle indices, grouped by edge.
    incidence_side : (sum of counts,) int64
        Which side (0, 1, 2) of that triangle the edge is.
    """

    edges: np.ndarray
    triangle_edges: np.ndarray
    incidence_ptr: np.ndarray
    incidence_tri: np.ndarray
    incidence_side: np.ndarray

    @property
    def counts(self) -> np.ndarray:
        """(e,) int64: number of triangles on each edge."""
        return np.diff(self.incidence_ptr)


def edge_incidence(triangles: np.ndarray) -> EdgeIncidence:
    """Build :class:`EdgeIncidence` for ``triangles`` (f, 3) int64."""
    f = len(triangles)
    sides = np.stack(
        [triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]], axis=1
    ).reshape(-1, 2)
    sides = np.sort(sides, axis=1)
    edges, inverse = np.unique(sides, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    order = np.argsort(inverse, kind="stable")
    counts = np.bincount(inverse, minlength=len(edges))
    ptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    flat_tri = np.repeat(np.arange(f), 3)
    flat_side = np.tile(np.arange(3), f)
    return EdgeIncidence(
        edges=edges.astype(np.int64).reshape(-1, 2),
        triangle_edges=inverse.reshape(f, 3).astype(np.int64),
        incidence_ptr=ptr,
        incidence_tri=flat_tri[order].astype(np.int64),
        incidence_side=flat_side[order].astype(np.int64),
    )


def triangle_normals(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (right-hand rule on the vertex order) and areas.

    Returns
    -------
    normals : (f, 3) float64
    areas : (f,) float64 [m^2]
    """
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    cross = np.cross(b - a, c - a)
    norm = np.linalg.norm(cross, axis=1)
    safe = np.where(norm > 0, norm, 1.0)
    return cross / safe[:, None], 0.5 * norm


class _UnionFind:
    def __init__(self, n: int) -> None:
        self.parent = np.arange(n)

    def find_all(self) -> np.ndarray:
        p = self.parent
        while True:
            q = p[p]
            if np.array_equal(q, p):
                return p
            p = q

    def union_pairs(self, a: np.ndarray, b: np.ndarray) -> None:
        # iterate to a fixed point with vectorised hooking (pairs are few per scene)
        for _ in range(64):
            roots = self.find_all()
            ra, rb = roots[a], roots[b]
            diff = ra != rb
            if not diff.any():
                self.parent = roots
                return
            lo = np.minimum(ra[diff], rb[diff])
            hi = np.maximum(ra[diff], rb[diff])
            self.parent = roots
            np.minimum.at(self.parent, hi, lo)
        # fall back to the exact scalar union for pathological chains
        roots = self.find_all()
        parent = roots.copy()

        def find(x: int) -> int:
            while parent[x] != x:
                parent[x] = parent[parent[x]]
                x = parent[x]
            return x

        for x, y in zip(a.tolist(), b.tolist()):
            rx, ry = find(x), find(y)
            if rx != ry:
                parent[max(rx, ry)] = min(rx, ry)
        self.parent = parent


class _Planes:
    """Whether triangles lie in the plane of others: by their normals' angle, or by distance.

    ``agree(u, v)`` is true where triangle ``v`` is coplanar with triangle ``u``: their normals
    within the angle tolerance (parallel or anti-parallel), or, with ``vertices`` given, every
    corner of ``v`` within ``distance`` [m] of ``u``'s plane. The distance is what float32
    meshes need: their vertices are rounded to about 6e-8 of the coordinates, which turns the
    normal of a triangle 0.1 m thin by up to 5e-4 rad but moves no corner off its true plane
    by more than that rounding (5e-5 m at 800 m).
    """

    def __init__(self, normals: np.ndarray, cos_tolerance: float, vertices: np.ndarray | None = None,
                 triangles: np.ndarray | None = None, distance: float = 0.0, cos_fold: float = -1.0):
        self.normals = normals
        self.cos_tolerance = cos_tolerance
        self.corners = None if vertices is None or triangles is None else vertices[triangles]  # (f, 3, 3)
        self.distance = distance
        self.cos_fold = cos_fold  # the distance test only where the normals agree within this

    def agree(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        dot = np.abs(np.einsum("ij,ij->i", self.normals[u], self.normals[v]))
        ok = dot >= self.cos_tolerance
        if self.corners is not None and self.distance > 0.0 and not ok.all():
            far = np.flatnonzero(~ok & (dot >= self.cos_fold))
            cu, cv, n = self.corners[u[far]], self.corners[v[far]], self.normals[u[far]]
            off = np.abs(np.einsum("ikj,ij->ik", cv - cu[:, :1, :], n)).max(axis=1)
            ok[far] = off <= self.distance
        return ok


def area_order(areas: np.ndarray) -> np.ndarray:
    """(f,) int64: triangle indices from the largest area down, the lowest index first among equals."""
    return np.lexsort((np.arange(len(areas)), -areas))


def largest_per_label(labels: np.ndarray, n: int, order: np.ndarray) -> np.ndarray:
    """(n,) int64: per label ``0..n-1``, the first of its triangles in ``order`` (:func:`area_order`:
    its largest triangle)."""
    rank = np.empty(len(order), dtype=np.int64)
    rank[order] = np.arange(len(order))
    best = np.full(n, len(order), dtype=np.int64)
    np.minimum.at(best, labels, rank)
    return order[best]


def _split_curved(labels: np.ndarray, planes: _Planes, a: np.ndarray, b: np.ndarray,
                  areas: np.ndarray | None = None) -> np.ndarray:
    """Components whose triangles turn by more than the tolerance, split by region growing.

    Joining neighbours whose planes agree chains: a curved surface of small folds (a ground
    following the Earth, 7.8e-6 rad per 50 m facet) became one polygon metres off its own
    plane. In a component where some triangle is not coplanar (:class:`_Planes`) with its
    reference triangle (its largest, whose plane the vertices' rounding disturbs least; the
    first where ``areas`` is not given), the triangles are regrown from seeds (the largest
    left, the lowest index among equal areas), each region taking the neighbours (joined
    pairs ``a``, ``b``) coplanar with its seed. Planar components are left as they are.
    """
    f = len(labels)
    if f == 0:
        return labels
    by_rank = np.arange(f) if areas is None else area_order(areas)
    best = largest_per_label(labels, int(labels.max()) + 1, by_rank)
    ref = best[labels]
    off = ~planes.agree(ref, np.arange(f))
    if not off.any():
        return labels
    bad = np.zeros(len(best), dtype=bool)
    bad[labels[off]] = True
    inside = bad[labels]
    pick = inside[a] & inside[b]
    neighbours: dict[int, list[int]] = {}
    for u, v in zip(a[pick].tolist(), b[pick].tolist()):
        neighbours.setdefault(u, []).append(v)
        neighbours.setdefault(v, []).append(u)
    out = labels.copy()
    fresh = int(labels.max()) + 1
    done = ~inside
    # the same test as _Planes.agree, one pair at a time on Python floats (a curved terrain of
    # 10^5 triangles visits each of them a few times)
    rows = np.flatnonzero(inside)
    keys = rows.tolist()
    normals = dict(zip(keys, planes.normals[rows].tolist()))
    corners = None
    if planes.corners is not None and planes.distance > 0.0:
        corners = dict(zip(keys, planes.corners[rows].reshape(-1, 9).tolist()))
    cos_tol, dist, cos_fold = planes.cos_tolerance, planes.distance, planes.cos_fold
    for seed in by_rank[inside[by_rank]].tolist():
        if done[seed]:
            continue
        done[seed] = True
        out[seed] = fresh
        n0, n1, n2 = normals[seed]
        p0, p1, p2 = corners[seed][:3] if corners is not None else (0.0, 0.0, 0.0)
        stack = [seed]
        while stack:
            u = stack.pop()
            for v in neighbours.get(u, ()):
                if done[v]:
                    continue
                m0, m1, m2 = normals[v]
                dot = abs(n0 * m0 + n1 * m1 + n2 * m2)
                ok = dot >= cos_tol
                if not ok and corners is not None and dot >= cos_fold:
                    c = corners[v]
                    ok = max(abs((c[i] - p0) * n0 + (c[i + 1] - p1) * n1 + (c[i + 2] - p2) * n2)
                             for i in (0, 3, 6)) <= dist
                if ok:
                    done[v] = True
                    out[v] = fresh
                    stack.append(v)
        fresh += 1
    return out


def coplanar_components(
    incidence: EdgeIncidence,
    normals: np.ndarray,
    group: np.ndarray,
    cos_tolerance: float,
    vertices: np.ndarray | None = None,
    triangles: np.ndarray | None = None,
    distance: float = 0.0,
    areas: np.ndarray | None = None,
    cos_fold: float = -1.0,
) -> np.ndarray:
    """Label the connected sets of coplanar triangles with the same ``group``.

    Two triangles are joined when they share an edge, carry the same ``group`` value
    (object and material) and their normals are parallel or anti-parallel within the
    tolerance (a shared edge then puts them in one plane), or, with ``vertices`` and
    ``triangles`` given, when the corners of the one nearer the shared edge lie within
    ``distance`` [m] of the other's plane (float32 rounding turns a thin triangle's normal,
    not its corners: :class:`_Planes`). Components that turn are regrown (:func:`_split_curved`).

    Parameters
    ----------
    incidence : EdgeIncidence
    normals : (f, 3) float64
    group : (f,) int64
    cos_tolerance : float
        ``cos`` of the largest angle between normals still called coplanar.
    vertices, triangles : (v, 3) float64, (f, 3) int64, optional
        The mesh, for the distance test.
    distance : float
        [m] The largest distance of a corner from the other triangle's plane still called
        coplanar (0: the angle alone).
    areas : (f,) float64, optional
        Triangle areas: the largest triangle of a component is its reference plane.
    cos_fold : float
        ``cos`` of the largest fold the distance test may join (``flat_angle``; -1: any).

    Returns
    -------
    (f,) int64
        Component label per triangle, numbered 0..p-1 in order of first triangle.
    """
    f = len(normals)
    counts = incidence.counts
    ptr = incidence.incidence_ptr
    tri = incidence.incidence_tri
    pairs_a, pairs_b = [], []
    # all pairs of triangles incident to the same edge, grouped by edge valence k
    for k in np.unique(counts[counts >= 2]):
        idx = np.nonzero(counts == k)[0]
        block = tri[ptr[idx][:, None] + np.arange(k)[None, :]]  # (m, k)
        for i in range(k):
            for j in range(i + 1, k):
                pairs_a.append(block[:, i])
                pairs_b.append(block[:, j])
    planes = _Planes(normals, cos_tolerance, vertices, triangles, distance, cos_fold)
    uf = _UnionFind(f)
    a = b = np.zeros(0, np.int64)
    if pairs_a:
        a = np.concatenate(pairs_a)
        b = np.concatenate(pairs_b)
        same = group[a] == group[b]
        a, b = a[same], b[same]
        if planes.corners is not None:
            # the taller triangle (farther corner from the shared edge: the larger area over the
            # same base) is the reference plane, the other's corners are measured against it
            tall = areas[a] >= areas[b] if areas is not None else np.ones(len(a), dtype=bool)
            u, v = np.where(tall, a, b), np.where(tall, b, a)
        else:
            u, v = a, b
        keep = planes.agree(u, v)
        a, b = a[keep], b[keep]
        uf.union_pairs(a, b)
    roots = uf.find_all()
    _, labels = np.unique(roots, return_inverse=True)
    labels = _split_curved(labels.astype(np.int64), planes, a, b, areas)
    # renumber by first occurrence so labels are stable and readable
    first = np.full(labels.max() + 1 if f else 0, f, dtype=np.int64)
    np.minimum.at(first, labels, np.arange(f))
    rank = np.argsort(np.argsort(first))
    return rank[labels].astype(np.int64)
