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


def _split_curved(labels: np.ndarray, normals: np.ndarray, a: np.ndarray, b: np.ndarray,
                  cos_tolerance: float) -> np.ndarray:
    """Components whose triangles turn by more than the tolerance, split by region growing.

    Joining neighbours whose normals agree chains: a curved surface of small folds (a ground
    following the Earth, 7.8e-6 rad per 50 m facet) became one polygon metres off its own
    plane. In a component where some triangle's normal is farther than the tolerance from its
    first triangle's, the triangles are regrown from seeds (the lowest index left), each
    region taking the neighbours (joined pairs ``a``, ``b``) within the tolerance of its seed's
    normal. Planar components are left as they are.
    """
    f = len(labels)
    if f == 0:
        return labels
    first = np.full(int(labels.max()) + 1, f, dtype=np.int64)
    np.minimum.at(first, labels, np.arange(f))
    off = np.abs(np.einsum("ij,ij->i", normals, normals[first[labels]])) < cos_tolerance
    if not off.any():
        return labels
    bad = np.zeros(len(first), dtype=bool)
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
    for seed in np.flatnonzero(inside).tolist():
        if done[seed]:
            continue
        n0 = normals[seed]
        done[seed] = True
        out[seed] = fresh
        stack = [seed]
        while stack:
            u = stack.pop()
            for v in neighbours.get(u, ()):
                if not done[v] and abs(float(normals[v] @ n0)) >= cos_tolerance:
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
) -> np.ndarray:
    """Label the connected sets of coplanar triangles with the same ``group``.

    Two triangles are joined when they share an edge, carry the same ``group`` value
    (object and material) and their normals are parallel or anti-parallel within the
    tolerance (a shared edge then puts them in one plane).

    Parameters
    ----------
    incidence : EdgeIncidence
    normals : (f, 3) float64
    group : (f,) int64
    cos_tolerance : float
        ``cos`` of the largest angle between normals still called coplanar.

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
    uf = _UnionFind(f)
    a = b = np.zeros(0, np.int64)
    if pairs_a:
        a = np.concatenate(pairs_a)
        b = np.concatenate(pairs_b)
        keep = (group[a] == group[b]) & (np.abs(np.einsum("ij,ij->i", normals[a], normals[b])) >= cos_tolerance)
        a, b = a[keep], b[keep]
        uf.union_pairs(a, b)
    roots = uf.find_all()
    _, labels = np.unique(roots, return_inverse=True)
    labels = _split_curved(labels.astype(np.int64), normals, a, b, cos_tolerance)
    # renumber by first occurrence so labels are stable and readable
    first = np.full(labels.max() + 1 if f else 0, f, dtype=np.int64)
    np.minimum.at(first, labels, np.arange(f))
    rank = np.argsort(np.argsort(first))
    return rank[labels].astype(np.int64)
