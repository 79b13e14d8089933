"""End points lying exactly on faces: which face, and which objects' surfaces.

A transmitter or receiver within the casters' plane tolerance of a polygon's plane and
inside the polygon lies on that face. It takes part in no reflection or diffraction there
(docs/search.md), and it is on the surface of the face's object, not inside it: the ray-parity
inside test, which may answer either way on a surface, is overruled there, both for the
warnings and for the one-sided culling of closed objects (an end on a block's edge had the
block's faces reflect from inside, in one direction of travel only).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._ragged import ranks
from ..scene.model import Scene

BUDGET = 50_000_000  # (points x polygons) distance tests; beyond it nothing is reported on a face


def _near_planes(scene: Scene, points: np.ndarray, tol: float, budget: int) -> tuple[np.ndarray, np.ndarray]:
    """``(point, polygon)`` index pairs of every point within ``tol`` [m] of a polygon's plane:
    (points x polygons) distances, in chunks of about 4 M; none beyond ``budget`` of them."""
    n, p = len(points), scene.num_polygons
    z = np.zeros(0, np.int64)
    if n == 0 or p == 0 or n * p > budget:
        return z, z
    step = max(1, (1 << 22) // p)
    rows, polys = [z], [z]
    for s in range(0, n, step):
        dist = np.abs(points[s : s + step] @ scene.polygon_normal.T - scene.polygon_offset[None, :])
        i, q = np.nonzero(dist <= tol)
        rows.append(s + i)
        polys.append(q)
    return np.concatenate(rows), np.concatenate(polys)


def _on_face_pairs(scene: Scene, points: np.ndarray, budget: int) -> tuple[np.ndarray, np.ndarray]:
    """``(point, polygon)`` index pairs of every point lying on a polygon (see the module docstring)."""
    from ..raycast import plane_tolerance
    from ..scene.polygon_query import points_in_polygons

    i, q = _near_planes(scene, points, plane_tolerance(scene), budget)
    if len(i) == 0:
        return i, q
    on = points_in_polygons(scene, points[i], q)
    return i[on], q[on]


def points_on_faces(scene: Scene, points: np.ndarray, budget: int = BUDGET) -> np.ndarray:
    """(n,) int64: a polygon each point lies exactly on (within the casters' plane tolerance), or -1.

    Such a point takes part in no reflection or diffraction on that polygon or its edges
    (its side of the face is undefined, docs/search.md), so the field computed there is
    the limit from neither side: :func:`~wavepaths.search.trace.trace` reports it. (points x
    polygons) distance tests, chunked; skipped (all -1) beyond ``budget`` of them.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.full(len(points), -1, dtype=np.int64)
    i, q = _on_face_pairs(scene, points, budget)
    out[i] = q  # (one of them, for a point on several)
    return out


def points_near_edges(scene: Scene, points: np.ndarray, budget: int = BUDGET) -> tuple[np.ndarray, np.ndarray]:
    """End points closer to a polygon's edge than the search's point-in-polygon margin.

    Within :func:`~wavepaths.scene.polygon_query.polygon_margin_length` (4e-9 of the scene's
    size) of an edge, a reflection on the edge's faces may be accepted at a point just beyond
    the edge, where the exact geometry has none, and the diffraction there then takes that
    reflection's boundary side: a review found the total field of a transmitter 0.3 to 30 nm
    from the built-in wedge's edge (a 125 m scene: the margin is 0.5 um) off by up to 25 dB,
    without a word. :func:`~wavepaths.search.trace.trace` reports such points.

    A point that near an edge is that near the plane of each of the edge's faces: the
    (points x polygons) plane distances, chunked as :func:`points_on_faces` takes them (and
    skipped with it beyond ``budget``), give the few candidates, whose distances to their
    polygons' edges (the dihedra on them) are then taken exactly.

    Returns
    -------
    dihedron : (n,) int64
        The nearest dihedron (edge segment) within the margin, or -1.
    distance : (n,) float64
        The distance to it [m], or ``inf``.
    """
    from ..scene.polygon_query import polygon_margin_length

    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    dihedron, distance = np.full(len(points), -1, dtype=np.int64), np.full(len(points), np.inf)
    margin = polygon_margin_length(scene)
    i, q = _near_planes(scene, points, margin, budget)
    if len(i) == 0:
        return dihedron, distance
    ptr, edges = scene.memo("polygon_dihedra", lambda: _polygon_dihedra(scene))
    count = ptr[q + 1] - ptr[q]
    i = np.repeat(i, count)
    k = edges[np.repeat(ptr[q], count) + ranks(count)]
    D = scene.dihedra
    w = points[i] - D.origin[k]
    t = np.clip(np.einsum("ij,ij->i", w, D.direction[k]), 0.0, D.length[k])
    e = np.linalg.norm(w - t[:, None] * D.direction[k], axis=1)
    near = e <= margin
    i, k, e = i[near], k[near], e[near]
    order = np.lexsort((k, e))[::-1]  # the nearest (then the lowest dihedron) written last: it wins
    dihedron[i[order]], distance[i[order]] = k[order], e[order]
    return dihedron, distance


def _polygon_dihedra(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """CSR ``(ptr, dihedra)``: the dihedra (edges) on each polygon, each once."""
    D = scene.dihedra
    owner = np.repeat(np.arange(len(D.length)), np.diff(D.face_ptr))
    pairs = np.unique(np.stack([D.face_polygon, owner], axis=1), axis=0)
    ptr = np.searchsorted(pairs[:, 0], np.arange(scene.num_polygons + 1))
    return ptr, pairs[:, 1].astype(np.int64)


def points_on_surfaces(scene: Scene, points: np.ndarray, budget: int = BUDGET) -> np.ndarray:
    """(n, objects) bool: whether each point lies exactly on a face of each object
    (every face it lies on counts: a point on a block's edge is on two of its faces)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.zeros((len(points), len(scene.object_names)), dtype=bool)
    i, q = _on_face_pairs(scene, points, budget)
    out[i, scene.polygon_object[q]] = True
    return out


@dataclass(frozen=True)
class SurfaceCone:
    """The surface of one closed shell of a solid object around a point lying on it: the shell's
    faces through the point.

    Near the point the solid is a cone (its tangent cone), bounded by the faces' own cones:
    a half-space on one face, a wedge on an edge (convex or reflex), a polyhedral cone at a
    corner. :func:`SurfaceCone.into` tells the directions that enter it.

    Attributes
    ----------
    normals : (k, 3) float64
        Outward unit normals of the faces (polygons) the point lies on.
    tri_face : (t,) int64
        The face (row of ``normals``) of each triangle of those faces that holds the point.
    edge_normals : (t, 3, 3) float64
        Each such triangle's in-plane unit normals of its three sides, pointing into it.
    edge_on : (t, 3) bool
        Whether the point lies on each side's line (within the plane tolerance): the side
        bounds the triangle's cone at the point.
    reference : (3,) float64
        A unit direction just outside the shell: into the first face's triangle (toward its
        centroid, or its farthest corner from a point at the centroid), tilted off it along
        its outward normal by 1e-3 rad, or by half the smallest angle at which another
        face's plane crosses that tilt (a slot whose walls meet at 1e-4 rad).
    """

    normals: np.ndarray
    tri_face: np.ndarray
    edge_normals: np.ndarray
    edge_on: np.ndarray
    reference: np.ndarray

    @classmethod
    def face_interior(cls, normal: np.ndarray) -> "SurfaceCone":
        """The cone at a point inside one face, off its triangles' sides: the half-space
        below the face, whose :meth:`into` is ``d . normal < -1e-12 |d|``."""
        n = np.asarray(normal, dtype=np.float64).reshape(1, 3)
        return cls(n, np.zeros(1, np.int64), np.zeros((1, 3, 3)), np.zeros((1, 3), bool), n[0])

    @property
    def is_face_interior(self) -> bool:
        """Whether the point lies inside one face, off its triangles' sides (one normal, no side on it)."""
        return len(self.normals) == 1 and not self.edge_on.any()

    def _in_face_cone(self, face: int, w: np.ndarray) -> np.ndarray:
        """(m,) bool: whether the in-plane directions ``w`` (m, 3) point into ``face``'s polygon."""
        out = np.zeros(len(w), dtype=bool)
        for t in np.flatnonzero(self.tri_face == face):
            side = w @ self.edge_normals[t].T  # (m, 3): >= 0 on the triangle's side of each edge
            out |= np.all((side >= -1e-12 * np.linalg.norm(w, axis=1)[:, None]) | ~self.edge_on[t][None, :], axis=1)
        return out

    def into(self, d: np.ndarray) -> np.ndarray:
        """(m,) bool: whether the directions ``d`` (m, 3) from the point enter the solid.

        Exact for the polyhedral cone: the segment from ``d`` to :attr:`reference` (both
        seen from the point) crosses the faces' cones an odd number of times. A direction
        within 1e-12 rad of a face's plane and pointing into that face runs along the
        surface, the limit from outside: not into.
        """
        d = np.asarray(d, dtype=np.float64).reshape(-1, 3)
        d = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
        r = self.reference
        crossings = np.zeros(len(d), dtype=np.int64)
        along = np.zeros(len(d), dtype=bool)
        for f, n in enumerate(self.normals):
            sd, sr = d @ n, float(r @ n)
            flat = np.abs(sd) <= 1e-12
            if flat.any():
                along[flat] |= self._in_face_cone(f, d[flat])
            cross = ((sd < 0) & (sr > 0)) | ((sd > 0) & (sr < 0))
            if cross.any():
                tau = sd[cross] / (sd[cross] - sr)
                w = d[cross] + tau[:, None] * (r[None, :] - d[cross])
                w -= (w @ n)[:, None] * n[None, :]  # in the plane, to rounding
                crossings[np.flatnonzero(cross)] += self._in_face_cone(f, w)
        return (crossings % 2 == 1) & ~along


def _shells(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """``(shell, outward)``: per triangle, its shell (the edge-connected part of its object: a
    penthouse modelled as its own closed box in the building's mesh is one) and its outward
    unit normal if its object is a solid (the winding's normal, turned by the sign of the
    object's volume; closed objects are consistently wound), else zeros. Kept on the scene
    (:meth:`~wavepaths.scene.model.Scene.memo`)."""
    return scene.memo("shells", lambda: _compute_shells(scene))


def _compute_shells(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_shells`, computed."""
    from ..scene.closed import _signed_volume, solid_objects_mask
    from ..scene.mesh_topology import _UnionFind

    tris = scene.triangles
    inc = scene.incidence
    uf = _UnionFind(len(tris))
    # triangles of one object on one edge are joined (on the edge two touching blocks
    # share, four triangles meet: two of each)
    for k in np.unique(inc.counts[inc.counts >= 2]).tolist():
        block = inc.incidence_tri[inc.incidence_ptr[:-1][inc.counts == k][:, None] + np.arange(k)[None, :]]
        for x in range(k):
            for y in range(x + 1, k):
                a, b = block[:, x], block[:, y]
                same = scene.triangle_object[a] == scene.triangle_object[b]
                uf.union_pairs(a[same], b[same])
    shell = uf.find_all().astype(np.int64)
    v = scene.vertices[tris]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    solid = solid_objects_mask(scene)
    sign = np.array([np.sign(_signed_volume(scene, o)) if solid[o] else 0.0 for o in range(len(solid))])
    outward = n * sign[scene.triangle_object][:, None]
    return shell, outward


def _triangle_sides(v: np.ndarray, n: np.ndarray, point: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """In-plane unit normals (m, 3, 3) of the sides of triangles ``v`` (m, 3, 3) of normals ``n``,
    pointing into them (side i from vertex i to i + 1), and ``point``'s distances (m, 3) to the
    sides' lines, positive inside: one point (3,) for every triangle, or one per triangle (m, 3)."""
    sides = np.roll(v, -1, axis=1) - v
    inward = np.cross(n[:, None, :], sides)
    inward /= np.maximum(np.linalg.norm(inward, axis=2, keepdims=True), 1e-300)
    toward = np.einsum("mij,mij->mi", np.roll(v, -2, axis=1) - v, inward)
    inward *= np.where(toward < 0, -1.0, 1.0)[..., None]
    return inward, np.einsum("mij,mij->mi", np.asarray(point)[..., None, :] - v, inward)


def _surface_cone(point: np.ndarray, faces: list[tuple], tol: float) -> SurfaceCone:
    """The :class:`SurfaceCone` of one closed shell at ``point`` from its faces there: per face
    (a polygon's triangles of the shell holding the point) its outward unit normal, the
    triangles' vertices (m, 3, 3), and their sides' inward normals and the point's distances
    to them (:func:`_triangle_sides`)."""
    normals, tri_face, edge_normals, edge_on = [], [], [], []
    for f, (n, v, inward, dist) in enumerate(faces):
        normals.append(n)
        tri_face += [f] * len(v)
        edge_normals.append(inward)
        edge_on.append(dist <= tol)
    normals = np.asarray(normals)
    # the reference: from the point into its first triangle (toward its centroid, or its farthest
    # corner when the point is the centroid), tilted off the face along the outward normal by
    # 1e-3 rad, or by half the smallest angle at which another face's plane crosses that tilt
    n0, v0 = faces[0][0], faces[0][1][0]
    w0 = v0.mean(axis=0) - point
    w0 -= (w0 @ n0) * n0
    size = np.linalg.norm(v0 - v0.mean(axis=0), axis=1).max()
    if np.linalg.norm(w0) <= 1e-6 * size:
        w0 = v0[np.argmax(np.linalg.norm(v0 - point, axis=1))] - point
        w0 -= (w0 @ n0) * n0
    w0 /= np.linalg.norm(w0)
    lift = 1e-3
    for nf in normals[1:]:
        den = float(n0 @ nf)
        if abs(den) > 1e-300:
            alpha = np.arctan(-float(w0 @ nf) / den)  # where cos(a) w0 + sin(a) n0 meets nf's plane
            if 0.0 < alpha < np.pi / 2:
                lift = min(lift, 0.5 * alpha)
    ref = np.cos(lift) * w0 + np.sin(lift) * n0
    return SurfaceCone(normals, np.asarray(tri_face, np.int64), np.concatenate(edge_normals),
                       np.concatenate(edge_on), ref / np.linalg.norm(ref))


def solid_surface_cones(scene: Scene, points: np.ndarray, budget: int = BUDGET) -> dict[int, list[SurfaceCone]]:
    """For each point lying on faces of solid objects: ``{point: [SurfaceCone per closed shell]}``
    (a point on the edge two touching blocks share lies on both; a leg enters the solid when it
    enters any of them). Empty for points on no solid."""
    from ..raycast import plane_tolerance
    from ..scene.closed import solid_objects_mask

    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    i, q = _on_face_pairs(scene, points, budget)
    if len(i) == 0:
        return {}
    keep = solid_objects_mask(scene)[scene.polygon_object[q]]
    i, q = i[keep], q[keep]
    if len(i) == 0:
        return {}
    shell, outward = _shells(scene)
    tol = plane_tolerance(scene)
    order = np.argsort(i, kind="stable")
    i, q = i[order], q[order]
    uniq, start, count = np.unique(i, return_index=True, return_counts=True)
    # a point on one face only, strictly inside one of its triangles (the common case: a
    # receiver on a roof), has the half-space below the face as its cone: all such at once
    single = count == 1
    inside, normal = _strictly_inside(scene, points[uniq[single]], q[start[single]], outward, tol)
    out: dict[int, list[SurfaceCone]] = {int(p): [SurfaceCone.face_interior(n)]
                                         for p, n in zip(uniq[single][inside], normal[inside])}
    rest = np.ones(len(uniq), dtype=bool)
    rest[np.flatnonzero(single)[inside]] = False
    for p, s0, c in zip(uniq[rest].tolist(), start[rest].tolist(), count[rest].tolist()):
        point = points[p]
        faces: dict[int, list[tuple]] = {}
        for poly in q[s0 : s0 + c].tolist():
            t = scene.polygon_triangles(poly)
            v = scene.vertices[scene.triangles[t]]
            inward, dist = _triangle_sides(v, outward[t], point)
            held = np.all(dist >= -tol, axis=1)
            t, v, inward, dist = t[held], v[held], inward[held], dist[held]
            for sh in np.unique(shell[t]).tolist():
                mine = shell[t] == sh
                faces.setdefault(sh, []).append((outward[t[mine][0]], v[mine], inward[mine], dist[mine]))
        cones = [_surface_cone(point, f, tol) for f in faces.values()]
        if cones:
            out[int(p)] = cones
    return out


def _strictly_inside(scene: Scene, points: np.ndarray, polygons: np.ndarray, outward: np.ndarray,
                     tol: float) -> tuple[np.ndarray, np.ndarray]:
    """``(inside, normal)``: whether each point (k, 3) lies inside a triangle of its polygon
    (k,) farther than ``tol`` from the triangle's three sides (:func:`_triangle_sides`' test,
    all rows at once), and the polygon's outward unit normal (k, 3)."""
    ptr, tris = scene.polygon_tri_ptr, scene.polygon_tris
    cnt = ptr[polygons + 1] - ptr[polygons]
    row = np.repeat(np.arange(len(polygons)), cnt)
    first = np.repeat(ptr[polygons], cnt)
    t = tris[first + np.arange(len(row)) - np.repeat(np.cumsum(cnt) - cnt, cnt)]
    _, dist = _triangle_sides(scene.vertices[scene.triangles[t]], outward[t], points[row])
    strict = np.all(dist > tol, axis=1)
    inside = np.bincount(row[strict], minlength=len(polygons)) > 0
    return inside, outward[tris[ptr[polygons]]]


def legs_into_solids(paths, tx_cones: dict[int, list[SurfaceCone]], rx_cones: dict[int, list[SurfaceCone]],
                     rx_offset: int = 0) -> np.ndarray:
    """(N,) bool: paths whose first leg leaves a transmitter lying on a solid's surface into the
    solid, or whose last leg reaches a receiver lying on one from inside it.

    The occlusion rule lets a segment pass whose end lies on a face (docs/stress.md, "What
    blocks a segment"): from a point on a block's wall, a leg through the block crosses no face
    in its interior. Whether a leg from such an end enters the solid is decided by the
    solid's tangent cone at the end (:meth:`SurfaceCone.into`): on a face, against its outward
    normal; on a convex edge or corner, against every face there (a leg from a roof's edge
    over the street enters no block); on a reflex edge, against either. A leg along a face
    is the limit from outside and stays. ``rx_offset``: the receivers' index offset of
    ``paths`` (a coverage tile's).
    """
    bad = np.zeros(len(paths), dtype=bool)
    if not tx_cones and not rx_cones or len(paths) == 0:
        return bad
    rows = np.arange(len(paths))
    first = paths.vertices[:, 1] - paths.vertices[:, 0]
    back = paths.vertices[rows, paths.depth] - paths.vertices[rows, paths.depth + 1]  # from rx to the vertex before
    for index, legs, cones_of in ((paths.tx_index, first, tx_cones), (paths.rx_index + rx_offset, back, rx_cones)):
        if not cones_of:
            continue
        # points inside one face: d . n < -1e-12 |d| (SurfaceCone.into for that cone), every path at once
        simple = {p: c[0].normals[0] for p, c in cones_of.items() if len(c) == 1 and c[0].is_face_interior}
        if simple:
            keys = np.fromiter(simple, dtype=np.int64, count=len(simple))
            o = np.argsort(keys)
            keys, normals = keys[o], np.asarray(list(simple.values()))[o]
            at = np.minimum(np.searchsorted(keys, index), len(keys) - 1)
            on = np.flatnonzero(keys[at] == index)
            d = legs[on]
            d = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
            bad[on] |= np.einsum("ij,ij->i", d, normals[at[on]]) < -1e-12
        # the others (edges, corners, sides): each point's paths, grouped once
        others = [p for p in cones_of if p not in simple]
        if others:
            o = np.argsort(index, kind="stable")
            lo = np.searchsorted(index[o], others, side="left")
            hi = np.searchsorted(index[o], others, side="right")
            for point, a, b in zip(others, lo.tolist(), hi.tolist()):
                on = o[a:b]
                for cone in cones_of[point] if len(on) else ():
                    bad[on] |= cone.into(legs[on])
    return bad
