"""Dihedra: one per edge support segment, with every face incident to it (seed §3.2).

The seed (Aveneau & Mériaux, §3.1-3.2) replaces the naive "one wedge per pair of
faces" with one structure per edge: a 3-D line and the list of *all* faces on it. An
edge shared by three or more faces (objects touching, a box on a ground plane) is then
represented once, and the validity test of §3.3 (:mod:`wavepaths.topology.find_dihedron`)
picks the pair of faces that bounds the topological volume a path lives in.

Construction (the "corefinement" the seed assumes, footnote 2):

0. mesh edges are split at the scene vertices lying inside them (T-junctions: a low
   building against a tall one, their corners on one line), and pieces with the same end
   vertices are merged, so that each stretch of a line carries exactly the faces around it;
1. every unique mesh edge gets one face entry per incident triangle, with the seed's
   ``P_f``: the unit vector in the face plane, perpendicular to the edge, pointing
   into the face;
2. an edge lying inside another polygon (the foot of a box standing on a ground
   plane, a frame set into a wall) gets that polygon as faces too: one half-face on
   each side of the edge where the polygon extends.
   Edges lying partly inside a polygon of their plane are first cut where they cross its
   border (:func:`_split_at_polygon_borders`), so this is decided piece by piece;
3. edges whose faces are all coplanar (triangulation diagonals, coplanar junctions)
   are flat: they are skipped and counted, never candidates;
4. collinear edges that share a vertex and carry the same set of polygons are merged
   into one segment, so a diffraction point falling on the shared vertex is found
   exactly once.

Not handled (documented in docs/scenes.md): objects that interpenetrate (their
intersection curves are not computed).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .._vec import unit as _unit

from ..scene.mesh_topology import _UnionFind
from ..scene.polygon_query import points_in_polygons
from .flatness import coplanar_entries, flat_widest_sector
from .grid import grid_index, grid_pairs, grid_query, vertices_near_edges

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene


@dataclass(frozen=True, eq=False)
class Dihedra:
    """Struct of arrays over the ``d`` dihedra of a scene.

    Attributes
    ----------
    origin : (d, 3) float64
        Start point A of each edge segment [m].
    direction : (d, 3) float64
        Unit edge vector ``w`` (from A to B).
    length : (d,) float64
        Segment length [m]; B = origin + length * direction.
    face_ptr : (d + 1,) int64
        CSR pointer into the face arrays.
    face_triangle : (nf,) int64
        A triangle of the scene that carries the face (gives object and material).
    face_polygon : (nf,) int64
    face_direction : (nf, 3) float64
        The seed's ``P_f``: unit, in the face plane, perpendicular to the edge,
        pointing from the edge into the face.
    face_normal : (nf, 3) float64
        Unit normal of the face's plane (orientation of its triangle).
    face_count : (d,) int64
        Distinct polygons on the edge (a polygon the edge runs through counts once).
    max_sector : (d,) float64
        Largest angle [rad] between consecutive faces around the edge; the edge can
        diffract only into a sector wider than pi.
    diffracting : (d,) bool
        ``max_sector > pi`` (beyond the flat tolerance): the candidates of the path search.
    mesh_edges_ptr, mesh_edges : CSR, int64
        The mesh edges (after the splits at T-junctions and at the borders of coplanar
        polygons, steps 0 and 2) merged into each dihedron.
    skipped_flat_edges : int
        Mesh edges whose faces are all coplanar (not dihedra).
    """

    origin: np.ndarray
    direction: np.ndarray
    length: np.ndarray
    face_ptr: np.ndarray
    face_triangle: np.ndarray
    face_polygon: np.ndarray
    face_direction: np.ndarray
    face_normal: np.ndarray
    face_count: np.ndarray
    max_sector: np.ndarray
    diffracting: np.ndarray
    mesh_edges_ptr: np.ndarray
    mesh_edges: np.ndarray
    skipped_flat_edges: int

    def __len__(self) -> int:
        return len(self.origin)

    @property
    def end(self) -> np.ndarray:
        """(d, 3) float64: end point B of each segment [m]."""
        return self.origin + self.length[:, None] * self.direction

    @property
    def faces_per_dihedron(self) -> np.ndarray:
        """(d,) int64: number of face entries (half-faces of a through-polygon count twice)."""
        return np.diff(self.face_ptr)

    def faces(self, i: int) -> slice:
        """Slice of the face arrays belonging to dihedron ``i``."""
        return slice(int(self.face_ptr[i]), int(self.face_ptr[i + 1]))


def _edges_inside_polygons(scene: "Scene", edge_a: np.ndarray, edge_b: np.ndarray):
    """Pairs (edge, polygon) where the edge lies in the plane and box of a polygon.

    Candidates come from a uniform grid over the polygons' bounding boxes (cost ~ edges x
    polygons per cell, not edges x polygons); the plane test then keeps edges whose two
    end points lie in the polygon's plane.
    """
    tol = scene.length_tolerance(scene.tolerances.plane_distance)
    n = scene.polygon_normal
    d = scene.polygon_offset
    p = len(n)
    if len(edge_a) == 0 or p == 0:
        z = np.zeros(0, dtype=np.int64)
        return z, z
    tri_poly = scene.triangle_polygon
    corners = scene.vertices[scene.triangles]
    lo = np.full((p, 3), np.inf)
    hi = np.full((p, 3), -np.inf)
    np.minimum.at(lo, tri_poly, corners.min(axis=1))
    np.maximum.at(hi, tri_poly, corners.max(axis=1))
    lo -= tol
    hi += tol
    mid = 0.5 * (edge_a + edge_b)
    ei, pi = grid_pairs(lo, hi, mid)
    inside_box = np.all((mid[ei] >= lo[pi]) & (mid[ei] <= hi[pi]), axis=1)
    ei, pi = ei[inside_box], pi[inside_box]
    da = np.abs(np.einsum("ij,ij->i", edge_a[ei], n[pi]) - d[pi])
    db = np.abs(np.einsum("ij,ij->i", edge_b[ei], n[pi]) - d[pi])
    ok = (da <= tol) & (db <= tol)
    return ei[ok], pi[ok]


def _split_t_junctions(scene: "Scene"):
    """The mesh edges, split at the vertices lying inside them (T-junctions), coinciding pieces merged.

    Two objects whose edges run along one line with different end points (a low building
    against a tall one: their corners share the line up to the low roof) have no common
    mesh edge: the short edge's top vertex lies *inside* the long edge. Each edge is cut
    at every scene vertex within the weld tolerance of its interior, and pieces with the
    same two end vertices become one edge carrying the faces of all of them, so the
    common stretch gets every face around it (often flat: a facade continuing another)
    and the rest keeps its own.

    Returns
    -------
    edges : (e, 2) int64
        End vertices of each edge, sorted.
    entry_edge, entry_tri, entry_side : (n,) int64
        One entry per (edge, incident triangle), grouped by edge: the triangle and the
        side of it that the (unsplit) mesh edge was; the corner opposite that side is
        off the edge, so the face direction is computed as for a whole edge.
    splits : int
        Vertices found inside edges.
    """
    inc = scene.incidence
    verts = scene.vertices
    E = inc.edges
    counts = inc.counts
    ptr = inc.incidence_ptr
    entry_edge = np.repeat(np.arange(len(E)), counts)
    if len(E) == 0:
        return E, entry_edge, inc.incidence_tri, inc.incidence_side, 0
    a, b = verts[E[:, 0]], verts[E[:, 1]]
    tol = scene.length_tolerance(scene.tolerances.weld)
    length = np.linalg.norm(b - a, axis=1)
    w = (b - a) / np.where(length > 0, length, 1.0)[:, None]
    lo, hi = np.minimum(a, b) - tol, np.maximum(a, b) + tol
    vi, ei = vertices_near_edges(a, b, lo, hi, tol, verts)
    keep = (vi != E[ei, 0]) & (vi != E[ei, 1])
    keep &= np.all((verts[vi] >= lo[ei]) & (verts[vi] <= hi[ei]), axis=1)
    vi, ei = vi[keep], ei[keep]
    rel = verts[vi] - a[ei]
    t = np.einsum("ij,ij->i", rel, w[ei])
    off = np.linalg.norm(rel - t[:, None] * w[ei], axis=1)
    on = (off <= tol) & (t > tol) & (t < length[ei] - tol)
    vi, ei, t = vi[on], ei[on], t[on]
    if len(vi) == 0:
        return E, entry_edge, inc.incidence_tri, inc.incidence_side, 0
    o = np.lexsort((t, ei))
    vi, ei = vi[o], ei[o]
    split = np.unique(ei)
    pieces, piece_parent = _cut(E, split, np.bincount(ei, minlength=len(E))[split], vi)
    whole = np.setdiff1d(np.arange(len(E)), split)
    parent = np.concatenate([whole, piece_parent])
    pairs = np.sort(np.concatenate([E[whole], pieces]), axis=1)
    edges, new_id = np.unique(pairs, axis=0, return_inverse=True)
    new_id = new_id.reshape(-1)
    c = counts[parent]
    row = np.repeat(np.arange(len(parent)), c)
    src = np.repeat(ptr[parent], c) + (np.arange(int(c.sum())) - np.repeat(np.cumsum(c) - c, c))
    e_edge = new_id[row]
    order = np.argsort(e_edge, kind="stable")
    src = src[order]
    return edges.astype(np.int64), e_edge[order], inc.incidence_tri[src], inc.incidence_side[src], int(len(vi))


def _polygon_borders(scene: "Scene") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The border of every polygon, as segments grouped by polygon.

    A mesh edge is on the border of polygon ``P`` when exactly one triangle of ``P`` is
    incident to it (a triangulation diagonal has two).

    Returns
    -------
    ptr : (p + 1,) int64
        CSR pointer: polygon ``P``'s border segments are ``ptr[P]:ptr[P + 1]``.
    c, d : (s, 3) float64
        The segments' end points [m].
    """
    inc = scene.incidence
    p = scene.num_polygons
    edge = np.repeat(np.arange(len(inc.edges)), inc.counts)
    key = edge.astype(np.int64) * (p + 1) + scene.triangle_polygon[inc.incidence_tri]
    keys, count = np.unique(key, return_counts=True)
    keys = keys[count == 1]
    e, poly = keys // (p + 1), keys % (p + 1)  # sorted by edge: regroup by polygon
    order = np.argsort(poly, kind="stable")
    e, poly = e[order], poly[order]
    ptr = np.concatenate([[0], np.cumsum(np.bincount(poly, minlength=p))]).astype(np.int64)
    v = scene.vertices
    return ptr, v[inc.edges[e, 0]], v[inc.edges[e, 1]]


BORDER_SAMPLES_PER_CHUNK = 1 << 12
"""Points along the edges looked up at once in :func:`_split_at_polygon_borders` (bounds its memory)."""


def _coplanar_polygon_pairs(scene: "Scene", a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (edge, polygon) where edge ``[a, b]`` lies in the polygon's plane and meets its
    (padded) bounding box somewhere along its length, not only at its midpoint.

    Points are sampled along each edge every half grid cell of
    :func:`~wavepaths.topology.grid.grid_pairs` (which looks them up), and the boxes are padded
    by half that spacing: a box that the segment meets holds, padded, the sample nearest the
    meeting point.
    """
    tol = scene.length_tolerance(scene.tolerances.plane_distance)
    n, d = scene.polygon_normal, scene.polygon_offset
    p = len(n)
    z = np.zeros(0, dtype=np.int64)
    if len(a) == 0 or p == 0:
        return z, z
    corners = scene.vertices[scene.triangles]
    lo = np.full((p, 3), np.inf)
    hi = np.full((p, 3), -np.inf)
    np.minimum.at(lo, scene.triangle_polygon, corners.min(axis=1))
    np.maximum.at(hi, scene.triangle_polygon, corners.max(axis=1))
    cells = 256
    h = 0.5 * max(float((hi.max(axis=0) - lo.min(axis=0)).max()) / cells, tol)
    lo, hi = lo - (0.5 * h + tol), hi + (0.5 * h + tol)
    length = np.linalg.norm(b - a, axis=1)
    per = np.ceil(length / h).astype(np.int64) + 1  # samples per edge, both ends included
    first = np.concatenate([[0], np.cumsum(per)])
    # the signed distances of the edges' ends to every plane are cheap beside the lookups:
    # each chunk keeps only its coplanar pairs before they are made unique
    found = []
    grid = grid_index(lo, hi, cells)  # once: a ground's box takes every cell
    for s0 in range(0, int(first[-1]), BORDER_SAMPLES_PER_CHUNK):
        s = np.arange(s0, min(s0 + BORDER_SAMPLES_PER_CHUNK, int(first[-1])))
        edge = np.searchsorted(first, s, side="right") - 1
        f = (s - first[edge]) / np.maximum(per[edge] - 1, 1)
        pts = a[edge] + f[:, None] * (b[edge] - a[edge])
        si, pi = grid_query(grid, pts)
        ei = edge[si]
        ok = np.abs(np.einsum("ij,ij->i", a[ei], n[pi]) - d[pi]) <= tol
        ei, pi, si = ei[ok], pi[ok], si[ok]
        ok = np.abs(np.einsum("ij,ij->i", b[ei], n[pi]) - d[pi]) <= tol
        ei, pi, si = ei[ok], pi[ok], si[ok]
        ok = np.all((pts[si] >= lo[pi]) & (pts[si] <= hi[pi]), axis=1)
        found.append(np.unique(ei[ok].astype(np.int64) * p + pi[ok]))
    pairs = np.unique(np.concatenate(found))
    return pairs // p, pairs % p


def _split_at_polygon_borders(scene: "Scene", verts: np.ndarray, edges: np.ndarray, entry_edge: np.ndarray,
                              entry_tri: np.ndarray, entry_side: np.ndarray):
    """Edges split where they cross the border of a polygon whose plane they lie in.

    An edge that runs partly inside another polygon (a roof edge whose end overlaps a
    coplanar neighbouring roof, a box standing across the border of the ground) has the
    polygon's two half-faces on one stretch only: there its air sector is smaller, and it
    may not diffract at all, while the rest keeps its own faces. Each such edge is cut at
    its crossings with the polygon's border segments (:func:`_polygon_borders`), so that
    step 2 of :func:`build_dihedra` decides the half-faces piece by piece. Borders running
    along the edge are skipped: their end vertices already split it (step 0). Pieces that
    end up with the same faces are merged again by step 4.

    Returns
    -------
    verts : (v + c, 3) float64
        ``verts`` with the ``c`` crossing points appended.
    edges, entry_edge, entry_tri, entry_side
        As :func:`_split_t_junctions` returns them, for the pieces.
    splits : int
        Crossing points found.
    """
    a, b = verts[edges[:, 0]], verts[edges[:, 1]]
    ce, cp = _coplanar_polygon_pairs(scene, a, b)
    tol = scene.length_tolerance(scene.tolerances.weld)
    if len(ce):
        # not the polygons incident to the edge (it is on their border or a diagonal of them)
        p = scene.num_polygons + 1
        incident = np.isin(ce * p + cp, entry_edge.astype(np.int64) * p + scene.triangle_polygon[entry_tri])
        ce, cp = ce[~incident], cp[~incident]
    bptr, bc, bd = _polygon_borders(scene)
    m = bptr[cp + 1] - bptr[cp]
    pe = np.repeat(ce, m)  # (edge, border segment) pairs
    seg = np.repeat(bptr[cp], m) + (np.arange(int(m.sum())) - np.repeat(np.cumsum(m) - m, m))
    length = np.linalg.norm(b - a, axis=1)
    w = (b - a) / np.where(length > 0, length, 1.0)[:, None]
    # closest points of the lines a + t w (t in metres) and c + s u (s in [0, 1])
    u = bd[seg] - bc[seg]
    r = a[pe] - bc[seg]
    B = np.einsum("ij,ij->i", w[pe], u)
    C = np.einsum("ij,ij->i", u, u)
    D = np.einsum("ij,ij->i", w[pe], r)
    E = np.einsum("ij,ij->i", u, r)
    den = C - B * B  # C sin^2 of the angle between the lines
    crossing = den > 1e-12 * C
    den = np.where(crossing, den, 1.0)
    t = (B * E - C * D) / den
    s = (E - B * D) / den
    gap = np.linalg.norm(r + t[:, None] * w[pe] - s[:, None] * u, axis=1)
    ulen = np.sqrt(C)
    crossing &= (gap <= tol) & (t > tol) & (t < length[pe] - tol)
    crossing &= (s * ulen >= -tol) & (s * ulen <= ulen + tol)
    pe, t = pe[crossing], t[crossing]
    if len(pe) == 0:
        return verts, edges, entry_edge, entry_tri, entry_side, 0
    o = np.lexsort((t, pe))
    pe, t = pe[o], t[o]
    # one split point per cluster of crossings within the weld tolerance (a border corner
    # on the edge is crossed by its two segments)
    new = np.ones(len(pe), dtype=bool)
    new[1:] = (pe[1:] != pe[:-1]) | (t[1:] - t[:-1] > tol)
    pe, t = pe[new], t[new]
    split = np.unique(pe)
    vid = len(verts) + np.arange(len(pe))
    verts = np.concatenate([verts, a[pe] + t[:, None] * w[pe]])
    # the crossings run from edges[., 0] to edges[., 1], the direction t is measured in
    pieces, piece_parent = _cut(edges, split, np.bincount(pe, minlength=len(edges))[split], vid)
    pieces = np.sort(pieces, axis=1)
    whole = np.setdiff1d(np.arange(len(edges)), split)
    parent = np.concatenate([whole, piece_parent])
    out_edges = np.concatenate([edges[whole], pieces])
    # each piece carries its parent's entries
    e_ptr = np.concatenate([[0], np.cumsum(np.bincount(entry_edge, minlength=len(edges)))])
    c = np.diff(e_ptr)[parent]
    row = np.repeat(np.arange(len(parent)), c)
    src = np.repeat(e_ptr[parent], c) + (np.arange(int(c.sum())) - np.repeat(np.cumsum(c) - c, c))
    return (verts, out_edges.astype(np.int64), row.astype(np.int64), entry_tri[src], entry_side[src], int(len(pe)))


def _cut(edges: np.ndarray, split: np.ndarray, inner: np.ndarray, nodes_inside: np.ndarray):
    """The pieces of the edges ``split`` (rows of ``edges``, end vertex ids) cut at their interior
    nodes: ``nodes_inside`` holds vertex ids grouped by edge, ``inner[i]`` of them for
    ``split[i]``, in order from ``edges[., 0]`` to ``edges[., 1]``.

    Returns ``(pieces, parent)``: (p, 2) int64 end vertex ids of each piece (between consecutive
    nodes of its edge's chain: start, interior nodes, end) and (p,) the edge it comes from.
    """
    node_ptr = np.concatenate([[0], np.cumsum(inner + 2)])
    nodes = np.empty(int(node_ptr[-1]), dtype=np.int64)
    nodes[node_ptr[:-1]] = edges[split, 0]
    nodes[node_ptr[1:] - 1] = edges[split, 1]
    pos = np.arange(len(nodes_inside)) - np.repeat(np.cumsum(inner) - inner, inner)
    nodes[np.repeat(node_ptr[:-1], inner) + 1 + pos] = nodes_inside
    n_pieces = inner + 1
    k = np.arange(int(n_pieces.sum())) - np.repeat(np.cumsum(n_pieces) - n_pieces, n_pieces)
    first = np.repeat(node_ptr[:-1], n_pieces) + k
    return np.stack([nodes[first], nodes[first + 1]], axis=1), np.repeat(split, n_pieces)


def build_dihedra(scene: "Scene") -> Dihedra:
    """Build the :class:`Dihedra` of ``scene`` (seed §3.2).

    Cost: O(edges) for the incidence, plus O(edges x polygons) bounding-box tests to
    find edges lying inside other polygons (chunked; once per scene).
    """
    tris = scene.triangles
    edges, entry_edge, entry_tri, entry_side, _ = _split_t_junctions(scene)
    verts, edges, entry_edge, entry_tri, entry_side, _ = _split_at_polygon_borders(
        scene, scene.vertices, edges, entry_edge, entry_tri, entry_side)
    num_e = len(edges)
    a = verts[edges[:, 0]]
    b = verts[edges[:, 1]]
    w = _unit(b - a)
    elen = np.linalg.norm(b - a, axis=1)
    cos_tol = np.cos(scene.tolerances.coplanar_angle)

    # 1. one face entry per incident triangle (edges split at T-junctions first)
    counts = np.bincount(entry_edge, minlength=num_e)
    third = verts[tris[entry_tri, (entry_side + 2) % 3]]
    rel = third - a[entry_edge]
    perp = rel - np.einsum("ij,ij->i", rel, w[entry_edge])[:, None] * w[entry_edge]
    # a triangle whose corner opposite the edge lies within the weld tolerance of the edge's
    # line (a sliver along it, or a T-junction patch split at its own tip) has no direction
    # away from the edge: its entry would be a zero or rounding-noise face direction, a
    # spurious face that splits a sector. Dropped, unless the edge has no other entry.
    proper = np.sqrt(np.einsum("ij,ij->i", perp, perp)) > scene.length_tolerance(scene.tolerances.weld)
    proper |= np.bincount(entry_edge, weights=proper, minlength=num_e)[entry_edge] == 0
    key_inc = entry_edge.astype(np.int64) * (scene.num_polygons + 1) + scene.triangle_polygon[entry_tri]
    entry_edge, entry_tri, perp = entry_edge[proper], entry_tri[proper], perp[proper]
    pf = _unit(perp)
    height = np.sqrt(np.einsum("ij,ij->i", perp, perp))  # of the face's corner above the edge [m]
    entry_poly = scene.triangle_polygon[entry_tri]

    # 2. edges running inside other polygons get that polygon's half-faces
    ce, cp = _edges_inside_polygons(scene, a, b)
    incident = np.zeros(len(ce), dtype=bool)
    if len(ce):
        # drop polygons already incident to the edge (the dropped slivers' included: the edge
        # does not run inside them either)
        key_c = ce.astype(np.int64) * (scene.num_polygons + 1) + cp
        incident = np.isin(key_c, key_inc)
    ce, cp = ce[~incident], cp[~incident]
    extra_e, extra_p, extra_pf, extra_tri = [], [], [], []
    if len(ce):
        side_dir = _unit(np.cross(scene.polygon_normal[cp], w[ce]))
        mid = 0.5 * (a[ce] + b[ce])
        probe = np.maximum(elen[ce] * 1e-3, scene.length_tolerance(scene.tolerances.weld) * 10)
        for sign in (1.0, -1.0):
            pts = mid + sign * probe[:, None] * side_dir
            inside = points_in_polygons(scene, pts, cp)
            extra_e.append(ce[inside])
            extra_p.append(cp[inside])
            extra_pf.append(sign * side_dir[inside])
            extra_tri.append(scene.polygon_tris[scene.polygon_tri_ptr[cp[inside]]])
    if extra_e:
        entry_edge = np.concatenate([entry_edge, *extra_e])
        entry_poly = np.concatenate([entry_poly, *extra_p])
        pf = np.concatenate([pf, *extra_pf])
        entry_tri = np.concatenate([entry_tri, *extra_tri])
        # a half-face of a polygon the edge runs inside has no corner: the angle test alone
        height = np.concatenate([height, np.full(len(entry_edge) - len(height), np.inf)])
    order = np.argsort(entry_edge, kind="stable")
    entry_edge, entry_poly, pf, entry_tri = entry_edge[order], entry_poly[order], pf[order], entry_tri[order]
    height = height[order]
    counts = np.bincount(entry_edge, minlength=num_e)
    ptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)

    # 3. sectors around each edge, flatness
    x_hat = pf[ptr[:-1][entry_edge]]  # first face of each edge as the angular origin
    y_hat = np.cross(w[entry_edge], x_hat)
    ang = np.mod(np.arctan2(np.einsum("ij,ij->i", pf, y_hat), np.einsum("ij,ij->i", pf, x_hat)), 2 * np.pi)
    srt = np.lexsort((ang, entry_edge))
    ang_sorted = ang[srt]
    nxt = np.roll(np.arange(len(ang_sorted)), -1)
    last = ptr[1:] - 1
    nxt[last] = ptr[:-1]  # wrap to the first face of the same edge
    gaps = np.mod(ang_sorted[nxt] - ang_sorted, 2 * np.pi)
    gaps[last] += np.where(counts == 1, 2 * np.pi, 0.0)  # a free edge: one 2*pi sector
    # a single-entry wrap gives 0 above; fix the general wrap for counts > 1
    wrap = counts > 1
    gaps[last[wrap]] = 2 * np.pi - (ang_sorted[last[wrap]] - ang_sorted[ptr[:-1][wrap]])
    max_sector = np.zeros(num_e)
    np.maximum.at(max_sector, entry_edge[srt], gaps)
    flat_sector = flat_widest_sector(scene, w, entry_edge, pf, height, srt, nxt, gaps, max_sector, counts)
    collinear = coplanar_entries(scene, w, entry_edge, pf, height, ptr, cos_tol)
    all_collinear = np.bincount(entry_edge, weights=~collinear, minlength=num_e) == 0
    has_opposite = np.bincount(entry_edge, weights=np.einsum("ij,ij->i", pf, x_hat) < 0, minlength=num_e) > 0
    flat = (counts >= 2) & all_collinear & has_opposite
    keep = ~flat

    # 4. merge collinear chains with the same polygon set
    kept = np.nonzero(keep)[0]
    max_faces = int(counts.max()) if num_e else 0
    poly_key = np.full((num_e, max(max_faces, 1)), -1, dtype=np.int64)
    slot = np.arange(len(entry_edge)) - ptr[entry_edge]
    poly_key[entry_edge, slot] = entry_poly
    poly_key.sort(axis=1)
    _, set_id = np.unique(poly_key, axis=0, return_inverse=True)
    set_id = set_id.reshape(-1)
    uf = _UnionFind(num_e)
    vert_edge_v = np.concatenate([edges[kept, 0], edges[kept, 1]])
    vert_edge_e = np.concatenate([kept, kept])
    o = np.lexsort((vert_edge_e, vert_edge_v))
    vv, ve = vert_edge_v[o], vert_edge_e[o]
    same_v = vv[1:] == vv[:-1]
    pa, pb = ve[:-1][same_v], ve[1:][same_v]
    # only adjacent pairs in the sorted order: enough when exactly two edges of a set meet
    ok = (set_id[pa] == set_id[pb]) & (np.abs(np.einsum("ij,ij->i", w[pa], w[pb])) >= cos_tol)
    # and only when they leave the shared vertex in opposite directions (a needle's two long
    # edges share a vertex and a direction, but are two edges)
    shared = vv[1:][same_v]
    other_a = np.where(edges[pa, 0] == shared, edges[pa, 1], edges[pa, 0])
    other_b = np.where(edges[pb, 0] == shared, edges[pb, 1], edges[pb, 0])
    ok &= np.einsum("ij,ij->i", verts[other_a] - verts[shared], verts[other_b] - verts[shared]) < 0
    if ok.any():
        # a vertex where more than two edges of the same set meet is a branching point: do not merge there
        vcount = np.bincount(vv, minlength=len(verts))
        ok &= vcount[vv[1:][same_v]] == 2
        uf.union_pairs(pa[ok], pb[ok])
    roots = uf.find_all()[kept]
    groups, group_of = np.unique(roots, return_inverse=True)
    group_of = group_of.reshape(-1)
    ng = len(groups)
    rep = kept[np.unique(group_of, return_index=True)[1]]  # representative mesh edge per group
    wr = w[rep]
    ar = a[rep]
    # extent along the representative direction
    ta = np.einsum("ij,ij->i", a[kept] - ar[group_of], wr[group_of])
    tb = np.einsum("ij,ij->i", b[kept] - ar[group_of], wr[group_of])
    tmin = np.full(ng, np.inf)
    tmax = np.full(ng, -np.inf)
    np.minimum.at(tmin, group_of, np.minimum(ta, tb))
    np.maximum.at(tmax, group_of, np.maximum(ta, tb))
    origin = ar + tmin[:, None] * wr
    length = tmax - tmin

    f_counts = counts[rep]
    f_ptr = np.concatenate([[0], np.cumsum(f_counts)]).astype(np.int64)
    f_owner = np.repeat(np.arange(ng), f_counts)
    f_idx = np.repeat(ptr[rep], f_counts) + (np.arange(int(f_ptr[-1])) - f_ptr[:-1][f_owner])
    face_tri = entry_tri[f_idx]
    face_poly = entry_poly[f_idx]
    face_dir = pf[f_idx]
    face_normal = scene.polygon_normal[face_poly]
    pairs = np.unique(np.stack([f_owner, face_poly], axis=1), axis=0)
    distinct = np.bincount(pairs[:, 0], minlength=ng).astype(np.int64)
    m_order = np.argsort(group_of, kind="stable")
    m_ptr = np.concatenate([[0], np.cumsum(np.bincount(group_of, minlength=ng))]).astype(np.int64)
    sector = max_sector[rep]
    flat_tol = scene.tolerances.coplanar_angle
    return Dihedra(
        origin=origin,
        direction=wr,
        length=length,
        face_ptr=f_ptr,
        face_triangle=face_tri.astype(np.int64),
        face_polygon=face_poly.astype(np.int64),
        face_direction=face_dir,
        face_normal=face_normal,
        face_count=distinct,
        max_sector=sector,
        diffracting=(sector > np.pi + flat_tol) & ~flat_sector[rep],
        mesh_edges_ptr=m_ptr,
        mesh_edges=kept[m_order].astype(np.int64),
        skipped_flat_edges=int(flat.sum()),
    )
