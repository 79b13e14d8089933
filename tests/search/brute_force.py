"""A slow, independent enumerator of propagation paths, for completeness tests.

It shares no search code with the engine: every sequence of faces (and of faces and one
edge) is tried without pruning, reflection points come from explicit mirror images, the
diffraction point from a bounded numerical minimisation of the path length (not the seed's
closed form), the topological test from face angles around the edge (not FindDihedron),
and occlusion from the float64 numpy caster.

Where the faces and edges come from is the caller's choice:

- :func:`enumerate_paths` takes them from the engine's scene: its polygons (normals,
  offsets, point-in-polygon from their triangles' areas) and its dihedra. It shares the
  search's topology, so it cannot see a topology bug (a dihedron too short, an edge kind
  missing would be missing from both sides).
- :func:`enumerate_box_paths` takes them in closed form from the corners of axis-aligned
  boxes standing on a square ground (:func:`box_faces_and_edges`): nothing from the
  engine's scene but the triangles the caster tests occlusion against. Its keys index
  these faces and edges; :func:`geometric_key` gives an engine path the same key from its
  interaction points.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.optimize import minimize_scalar

from wavepaths.raycast.numpy_caster import NumpyRayCaster


@dataclass(frozen=True)
class Face:
    """A planar reflecting face: points x with ``normal @ x == offset`` and ``contains(x)``."""

    normal: np.ndarray
    offset: float
    contains: Callable[[np.ndarray], bool]


@dataclass(frozen=True)
class Edge:
    """An edge segment ``origin + t direction``, 0 <= t <= length, and the unit vectors in
    its faces' planes, perpendicular to it, pointing from it into each face."""

    origin: np.ndarray
    direction: np.ndarray
    length: float
    face_directions: np.ndarray


def scene_faces_and_edges(scene):
    """The engine scene's polygons and dihedra as faces and edges (indices unchanged)."""
    faces = [Face(scene.polygon_normal[q], float(scene.polygon_offset[q]),
                  lambda x, q=q: in_polygon(scene, x, q)) for q in range(scene.num_polygons)]
    dih = scene.dihedra
    edges = [Edge(dih.origin[i], dih.direction[i], float(dih.length[i]), dih.face_direction[dih.faces(i)])
             for i in range(len(dih))]
    return faces, edges


def _rectangle(axis, value, lo, hi, tol=1e-9):
    """An axis-aligned rectangle in the plane ``x[axis] == value`` spanning [lo, hi] on the
    other two axes (the normal's sign does not matter to a mirror)."""
    normal = np.zeros(3)
    normal[axis] = 1.0
    other = [a for a in range(3) if a != axis]
    lo, hi = np.asarray(lo, float)[other], np.asarray(hi, float)[other]
    return Face(normal, float(value), lambda x: bool(np.all(x[other] >= lo - tol) and np.all(x[other] <= hi + tol)))


def box_faces_and_edges(boxes, ground):
    """Closed-form faces and diffracting edges of axis-aligned boxes ``(lo, hi)`` standing on
    the square ground ``|x|, |y| <= ground`` at z = 0 (tests/conftest.py::boxes_scene).

    Faces: each box's top and four sides, then the ground. A box's bottom is not a face: it
    lies on the ground and faces into it, no ray from above the ground reaches it.

    Edges (only the wedges, the free space around them wider than pi):

    - each box's 4 vertical edges (z from 0 to the top) and 4 top edges: right-angled
      corners, n = 1.5; the faces' directions from the box's axes;
    - the ground's 4 border edges: free edges of a half-plane, n = 2, one face each.

    A box's 4 bottom edges are not wedges: the ground continues on both sides of them, and
    the free space around them is the quarter above the ground outside the box (n = 0.5).
    Boxes that overlap keep their full edges: the parts inside another box are occluded,
    and where two boxes' faces cross the union has concave corners only.
    """
    faces, edges = [], []
    ex, ey, ez = np.eye(3)
    for lo, hi in boxes:
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        assert lo[2] == 0.0, "boxes stand on the ground"
        faces.append(_rectangle(2, hi[2], lo, hi))  # top
        for axis in (0, 1):
            faces.append(_rectangle(axis, lo[axis], lo, hi))
            faces.append(_rectangle(axis, hi[axis], lo, hi))
        for x, sx in ((lo[0], 1.0), (hi[0], -1.0)):  # sx, sy: from the edge toward the box
            for y, sy in ((lo[1], 1.0), (hi[1], -1.0)):
                edges.append(Edge(np.array([x, y, 0.0]), ez, float(hi[2]), np.array([sx * ex, sy * ey])))
        for y, sy in ((lo[1], 1.0), (hi[1], -1.0)):  # top edges along x: the top face and a y side
            edges.append(Edge(np.array([lo[0], y, hi[2]]), ex, float(hi[0] - lo[0]), np.array([sy * ey, -ez])))
        for x, sx in ((lo[0], 1.0), (hi[0], -1.0)):  # top edges along y: the top face and an x side
            edges.append(Edge(np.array([x, lo[1], hi[2]]), ey, float(hi[1] - lo[1]), np.array([sx * ex, -ez])))
    g = float(ground)
    faces.append(_rectangle(2, 0.0, (-g, -g, 0.0), (g, g, 0.0)))
    for y, sy in ((-g, 1.0), (g, -1.0)):
        edges.append(Edge(np.array([-g, y, 0.0]), ex, 2 * g, np.array([sy * ey])))
    for x, sx in ((-g, 1.0), (g, -1.0)):
        edges.append(Edge(np.array([x, -g, 0.0]), ey, 2 * g, np.array([sx * ex])))
    return faces, edges


def geometric_key(faces, edges, kinds, points, tol=1e-6):
    """The key of a path with interactions ``kinds`` ("R"/"D") at ``points`` in terms of
    ``faces`` and ``edges``: the one face each reflection point lies on, the one edge each
    diffraction point lies strictly inside. AssertionError if none or several fit."""
    prims = []
    for kind, x in zip(kinds, points):
        if kind == "R":
            hit = [f for f, face in enumerate(faces) if abs(face.normal @ x - face.offset) < tol and face.contains(x)]
        else:
            hit = []
            for i, edge in enumerate(edges):
                t = (x - edge.origin) @ edge.direction
                if tol < t < edge.length - tol and np.linalg.norm(x - edge.origin - t * edge.direction) < tol:
                    hit.append(i)
        assert len(hit) == 1, f"{kind} point {x} on faces/edges {hit}"
        prims.append(hit[0])
    return tuple(kinds), tuple(prims)


def mirror(p, n, d):
    return p - 2 * (p @ n - d) * n


def in_polygon(scene, x, poly, tol=1e-9):
    for t in scene.polygon_triangles(poly):
        a, b, c = scene.vertices[scene.triangles[t]]
        area = np.linalg.norm(np.cross(b - a, c - a))
        parts = (np.linalg.norm(np.cross(b - x, c - x)) + np.linalg.norm(np.cross(c - x, a - x))
                 + np.linalg.norm(np.cross(a - x, b - x)))
        if parts <= area * (1 + tol) + 1e-12:
            return True
    return False


def crossing(a, b, n, d):
    da, db = a @ n - d, b @ n - d
    if da == db:
        return None
    t = da / (da - db)
    if not 1e-9 < t < 1 - 1e-9:
        return None
    return a + t * (b - a)


def unfold(faces, start, images, polys):
    """Reflection points going backwards from ``start`` toward the images; None if invalid."""
    pts = []
    y = start
    for img, q in zip(images[::-1], polys[::-1]):
        x = crossing(y, img, faces[q].normal, faces[q].offset)
        if x is None or not faces[q].contains(x):
            return None
        pts.append(x)
        y = x
    return pts[::-1]


def images_of(faces, p, polys):
    out = []
    for q in polys:
        p = mirror(p, faces[q].normal, faces[q].offset)
        out.append(p)
    return out


def sequences(p, k):
    for seq in itertools.product(range(p), repeat=k):
        if all(seq[i] != seq[i + 1] for i in range(k - 1)):
            yield list(seq)


def same_open_sector(edge, e, r, p):
    """E and R strictly inside one sector between the faces around the edge, wider than pi."""
    w = edge.direction
    faces = edge.face_directions
    x = faces[0]
    y = np.cross(w, x)

    def angle(v):
        v = v - (v @ w) * w
        return np.mod(np.arctan2(v @ y, v @ x), 2 * np.pi)

    fa = np.sort([angle(f) for f in faces])
    ae, ar = angle(e - p), angle(r - p)
    if np.min(np.abs(np.subtract.outer(fa, [ae, ar]))) < 1e-9:
        return False
    se = (np.searchsorted(fa, ae) - 1) % len(fa)
    sr = (np.searchsorted(fa, ar) - 1) % len(fa)
    # only a sector wider than pi (a convex wedge's outside) diffracts: a concave corner
    # (the foot of a box on the ground, n <= 1) is handled by reflections alone
    width = (np.append(fa, fa[0] + 2 * np.pi)[se + 1] - fa[se]) if len(fa) > 1 else 2 * np.pi
    return se == sr and width > np.pi + 1e-9


def enumerate_paths(scene, tx, rx, max_reflections=2, diffraction=True, diffraction_reflections=1):
    """All paths as {(kinds, primitives): length}, primitives indexing the scene's polygons and
    dihedra (the engine's own topology: see the module docstring)."""
    faces, edges = scene_faces_and_edges(scene)
    return _enumerate(faces, edges, NumpyRayCaster(scene), tx, rx, max_reflections, diffraction,
                      diffraction_reflections)


def enumerate_box_paths(scene, boxes, ground, tx, rx, max_reflections=2, diffraction=True,
                        diffraction_reflections=1):
    """All paths as {(kinds, primitives): length} in a scene of boxes on a ground, primitives
    indexing :func:`box_faces_and_edges` (closed form, not the engine's polygons and dihedra);
    ``scene`` only gives the triangles the occlusion test casts against."""
    faces, edges = box_faces_and_edges(boxes, ground)
    return _enumerate(faces, edges, NumpyRayCaster(scene), tx, rx, max_reflections, diffraction,
                      diffraction_reflections)


def _enumerate(faces, edges, caster, tx, rx, max_reflections, diffraction, diffraction_reflections):
    found = {}

    def visible(chain):
        a = np.array(chain[:-1])
        b = np.array(chain[1:])
        return not caster.occluded(a, b).any()

    if visible([tx, rx]):
        found[((), ())] = np.linalg.norm(rx - tx)
    npoly = len(faces)
    for k in range(1, max_reflections + 1):
        for seq in sequences(npoly, k):
            imgs = images_of(faces, tx, seq)
            pts = unfold(faces, rx, imgs, seq)
            if pts is None:
                continue
            chain = [tx, *pts, rx]
            if visible(chain):
                found[(("R",) * k, tuple(seq))] = sum(np.linalg.norm(np.diff(chain, axis=0), axis=1))
    if not diffraction:
        return found
    for i, edge in enumerate(edges):
        o, w, length = edge.origin, edge.direction, edge.length
        for a in range(diffraction_reflections + 1):
            for b in range(diffraction_reflections + 1 - a):
                for sa in sequences(npoly, a):
                    for sb in sequences(npoly, b):
                        e = images_of(faces, tx, sa)[-1] if a else tx
                        r = images_of(faces, rx, sb[::-1])[-1] if b else rx
                        res = minimize_scalar(lambda t: np.linalg.norm(o + t * w - e) + np.linalg.norm(o + t * w - r),
                                              bounds=(0, length), method="bounded", options={"xatol": 1e-12})
                        t = res.x
                        if t < 1e-6 or t > length - 1e-6:
                            continue  # minimum on an end point: no stationary path on this edge
                        p = o + t * w
                        if not same_open_sector(edge, e, r, p):
                            continue
                        pre = unfold(faces, p, images_of(faces, tx, sa), sa) if a else []
                        post = unfold(faces, p, images_of(faces, rx, sb[::-1]), sb[::-1]) if b else []
                        if pre is None or post is None:
                            continue
                        chain = [tx, *pre, p, *post[::-1], rx]
                        if visible(chain):
                            key = (("R",) * a + ("D",) + ("R",) * b, tuple(sa) + (i,) + tuple(sb))
                            found[key] = sum(np.linalg.norm(np.diff(chain, axis=0), axis=1))
    return found
