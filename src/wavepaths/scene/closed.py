"""Closed objects and coincident faces: which side of each polygon can reflect.

Receiver-independent facts prune the image tree without losing a path:

* a polygon of a **closed, consistently oriented object with a volume** (every edge of the
  object shared by exactly two of its triangles, traversed in opposite directions; signed
  volume above ``plane_distance`` times its area) can reflect only a wave arriving from
  outside the object, unless the source itself is inside it;
* **coincident faces** (a polygon lying entirely inside a coplanar polygon ``q``, of any
  object): each side of the common surface reflects once. A side of the inner polygon is
  dropped when ``q`` reflects on that side too (the duplicate), or when that side lies
  inside a solid (a contact face: the floor of a building standing on the ground, the
  shared wall of two touching blocks: a wave would have to come from inside the solid).
  Between two polygons covering each other, a side goes to the one whose normal faces it,
  then to the lower index.

A zero-thickness **double-sided screen** is therefore two-sided whatever its mesh: the
same quad twice with opposite orientations in one object (welded into one polygon with
triangles of both orientations, or a closed object without volume) reflects on both
sides; as two objects (or two materials), each copy reflects on its own front side. Its
edge is a half-plane (n = 2) for the diffraction search, which works on the mesh's edges.

"Is a point inside" is decided by the ray-parity rule of :mod:`wavepaths.scene.solids`
(three rays, float64), the same for coverage cells and for the sources here.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .polygon_query import points_in_polygons

if TYPE_CHECKING:  # pragma: no cover
    from .model import Scene


def closed_objects(scene: "Scene") -> np.ndarray:
    """(objects,) bool: the object is a closed, consistently oriented triangle surface."""
    n_obj = len(scene.object_names)
    tris = scene.triangles
    obj = scene.triangle_object
    closed = np.ones(n_obj, dtype=bool)
    # directed half-edges per object: each undirected edge must appear once in each direction
    heads = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    owner = np.concatenate([obj, obj, obj])
    und = np.sort(heads, axis=1)
    forward = heads[:, 0] < heads[:, 1]
    key = np.stack([owner, und[:, 0], und[:, 1]], axis=1)
    uniq, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    fwd = np.bincount(inv, weights=forward, minlength=len(uniq))
    good = (counts == 2) & (fwd == 1)
    bad_obj = np.unique(uniq[~good, 0])
    closed[bad_obj] = False
    present = np.zeros(n_obj, dtype=bool)
    present[obj] = True
    return closed & present


def _signed_volume(scene: "Scene", o: int) -> float:
    t = scene.triangles[scene.triangle_object == o]
    a, b, c = (scene.vertices[t[:, i]] - scene.center for i in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def solid_objects_mask(scene: "Scene") -> np.ndarray:
    """(objects,) bool, read-only: closed objects that enclose a volume (not a double-sided
    sheet). Computed once per scene (:attr:`Scene.solid_object_mask`): every coverage tile asks
    for it through the receivers' image trees, and its half-edge count sorts every edge of
    the scene."""
    return scene.solid_object_mask


def compute_solid_objects_mask(scene: "Scene") -> np.ndarray:
    """:func:`solid_objects_mask`, computed. A closed surface thinner than ``plane_distance``
    everywhere (the same quad twice with opposite orientations) has a signed volume below
    ``plane_distance`` times its area.
    """
    closed = closed_objects(scene)
    tol = scene.length_tolerance(scene.tolerances.plane_distance)
    area = np.bincount(scene.triangle_object, weights=scene.areas, minlength=len(closed))
    for o in np.nonzero(closed)[0]:
        if abs(_signed_volume(scene, int(o))) <= tol * area[o]:
            closed[o] = False
    return closed


def _solid_sign(scene: "Scene") -> np.ndarray:
    """(p,) float: +1 / -1 when ``polygon_normal`` points out of / into its solid object, else 0."""
    solid = solid_objects_mask(scene)
    sign = np.zeros(scene.num_polygons)
    poly = scene.triangle_polygon
    agree = np.sign(np.einsum("ij,ij->i", scene.normals, scene.polygon_normal[poly]))
    # a polygon welded from triangles of both orientations is a double-sided sheet
    lo = np.full(scene.num_polygons, 1.0)
    np.minimum.at(lo, poly, agree)
    for o in np.nonzero(solid)[0]:
        vol = _signed_volume(scene, int(o))
        polys = np.nonzero((scene.polygon_object == o) & (lo > 0))[0]
        sign[polys] = np.sign(vol)
    return sign


def coincident_polygons(scene: "Scene") -> tuple[np.ndarray, np.ndarray]:
    """Pairs ``(i, q)``: polygon ``i`` lies entirely inside the coplanar polygon ``q`` (q != i)."""
    tol = scene.length_tolerance(scene.tolerances.plane_distance)
    p = scene.num_polygons
    n, d = scene.polygon_normal, scene.polygon_offset
    out_i, out_q = [], []
    for i in range(p):
        pts = scene.vertices[np.unique(scene.triangles[scene.polygon_triangles(i)])]
        cand = np.nonzero(np.abs(n @ n[i]) > 1 - 1e-9)[0]
        cand = cand[cand != i]
        if len(cand) == 0:
            continue
        on = np.all(np.abs(pts @ n[cand].T - d[cand]) <= tol, axis=0)
        for q in cand[on]:
            if points_in_polygons(scene, pts, np.full(len(pts), q)).all():
                out_i.append(i)
                out_q.append(int(q))
    return np.array(out_i, dtype=np.int64), np.array(out_q, dtype=np.int64)


def _interior_points(scene: "Scene", polygons: np.ndarray) -> np.ndarray:
    """(k, 3): the centroid of the largest triangle of each polygon (a point inside it)."""
    out = np.zeros((len(polygons), 3))
    for j, i in enumerate(polygons):
        tris = scene.polygon_triangles(int(i))
        t = tris[np.argmax(scene.areas[tris])]
        out[j] = scene.vertices[scene.triangles[t]].mean(axis=0)
    return out


def polygon_sides(scene: "Scene") -> np.ndarray:
    """(p, 2) bool: whether each polygon reflects waves arriving on the side its normal points
    to (column 0) and on the other side (column 1). See the module docstring."""
    sign = _solid_sign(scene)
    base = np.stack([sign >= 0, sign <= 0], axis=1)
    sides = base.copy()
    ii, qq = coincident_polygons(scene)
    if len(ii) == 0:
        return sides
    contains = set(zip(ii.tolist(), qq.tolist()))
    # which sides of the inner polygons lie inside a solid (contact faces)
    from .solids import inside_solid_objects, solid_objects

    inner = np.unique(ii)
    x = _interior_points(scene, inner)
    delta = 4 * scene.length_tolerance(scene.tolerances.plane_distance)
    nrm = scene.polygon_normal[inner]
    solids = solid_objects(scene)
    in_solid = np.stack([inside_solid_objects(scene, x + delta * nrm, solids),
                         inside_solid_objects(scene, x - delta * nrm, solids)], axis=1)
    row = {int(i): r for r, i in enumerate(inner)}
    n = scene.polygon_normal
    for i, q in zip(ii.tolist(), qq.tolist()):
        flip = float(n[i] @ n[q]) < 0  # q's column for i's side 0 is 1 when the normals oppose
        mutual = (q, i) in contains
        for c in (0, 1):
            cq = 1 - c if flip else c
            if in_solid[row[i], c]:
                sides[i, c] = False
            elif base[q, cq]:
                if not mutual:
                    sides[i, c] = False  # q covers i and reflects there too
                else:
                    faces_i, faces_q = c == 0, cq == 0
                    q_wins = faces_q and not faces_i if faces_q != faces_i else q < i
                    if q_wins:
                        sides[i, c] = False
    return sides


def outward_polygon_sign(scene: "Scene") -> np.ndarray:
    """(p,) float: +1 / -1 when a polygon reflects only on the side its normal points to /
    only on the other side (the outside of a closed object), 0 if on both (or hidden)."""
    sides = scene.polygon_sides
    return np.where(sides[:, 0] & ~sides[:, 1], 1.0, np.where(sides[:, 1] & ~sides[:, 0], -1.0, 0.0))


def hidden_polygons(scene: "Scene") -> np.ndarray:
    """(p,) bool: polygons that reflect on neither side (contact faces, duplicates)."""
    return ~scene.polygon_sides.any(axis=1)


BOX_PAIRS = 1 << 20
"""(point, object) box tests held at once by :func:`points_inside_closed`."""


def points_inside_closed(scene: "Scene", points: np.ndarray) -> np.ndarray:
    """(k, objects) bool: whether each point lies inside each closed object with a volume.

    The ray-parity rule of :mod:`wavepaths.scene.solids` (three rays, majority, float64)
    applied to each such object alone, to the points within an object's bounding box
    (padded by the plane tolerance): a point outside every box lies inside none (the region
    a closed surface bounds is within its box; a point on the surface, where either answer
    may come, is within the padding). The receivers of a street-canyon coverage tile
    (1,024 cells at street level) then skip the parity test, which took 4 % of the map.
    """
    from .solids import SolidObjects, inside_solids

    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    solid = np.nonzero(solid_objects_mask(scene))[0]
    out = np.zeros((len(points), len(scene.object_names)), dtype=bool)
    if len(solid) == 0 or len(points) == 0:
        return out
    lo, hi = scene.object_boxes
    pad = scene.length_tolerance(scene.tolerances.plane_distance)
    lo, hi = lo[solid] - pad, hi[solid] + pad
    near = np.zeros(len(points), dtype=bool)
    step = max(1, BOX_PAIRS // len(solid))  # (point, object) pairs compared at once
    for s in range(0, len(points), step):
        p = points[s : s + step, None, :]
        near[s : s + step] = ((p >= lo) & (p <= hi)).all(axis=2).any(axis=1)
    if not near.any():
        return out
    index = np.full(len(scene.object_names), -1, dtype=np.int64)
    index[solid] = np.arange(len(solid))
    tris = np.nonzero(index[scene.triangle_object] >= 0)[0]
    groups = np.empty(len(solid), dtype=object)
    groups[:] = [(int(o),) for o in solid]
    solids = SolidObjects(groups, np.ones(len(solid), bool), np.full(len(solid), -np.inf), tris,
                          index[scene.triangle_object[tris]])
    rows = np.nonzero(near)[0]
    out[np.ix_(rows, solid)] = inside_solids(scene, points[rows], solids)
    return out


def object_boxes(scene: "Scene") -> tuple[np.ndarray, np.ndarray]:
    """(objects, 3) float64 twice: each object's bounding box over its triangles' corners
    (``+inf`` / ``-inf`` for an object without triangles); cached as :attr:`Scene.object_boxes`."""
    n = len(scene.object_names)
    corners = scene.vertices[scene.triangles].reshape(-1, 3)
    owner = np.repeat(scene.triangle_object, 3)
    lo, hi = np.full((n, 3), np.inf), np.full((n, 3), -np.inf)
    np.minimum.at(lo, owner, corners)
    np.maximum.at(hi, owner, corners)
    return lo, hi
