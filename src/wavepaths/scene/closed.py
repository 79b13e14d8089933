"""Closed objects: which polygons can only be seen from outside, and which are hidden.

Two receiver-independent facts prune the image tree without losing a path:

* a polygon of a **closed, consistently oriented object** (every edge of the object
  shared by exactly two of its triangles, traversed in opposite directions) can reflect
  only a wave arriving from outside the object, unless the source itself is inside it;
* a polygon lying entirely inside a coplanar polygon of another object (the floor of a
  building standing on the ground) is a contact face: any path reaching it would have to
  cross the other object's polygon, so it never reflects.
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


def outward_polygon_sign(scene: "Scene") -> np.ndarray:
    """(p,) float: +1 / -1 when ``polygon_normal`` points out of / into its closed object, 0 if open."""
    closed = closed_objects(scene)
    sign = np.zeros(scene.num_polygons)
    first = scene.polygon_tris[scene.polygon_tri_ptr[:-1]]
    for o in np.nonzero(closed)[0]:
        vol = _signed_volume(scene, int(o))
        if vol == 0:
            continue
        polys = np.nonzero(scene.polygon_object == o)[0]
        tri_n = scene.normals[first[polys]]
        agree = np.sign(np.einsum("ij,ij->i", tri_n, scene.polygon_normal[polys]))
        sign[polys] = agree * np.sign(vol)
    return sign


def hidden_polygons(scene: "Scene") -> np.ndarray:
    """(p,) bool: polygons entirely inside a coplanar polygon of another object (contact faces)."""
    tol = scene.length_tolerance(scene.tolerances.plane_distance)
    p = scene.num_polygons
    hidden = np.zeros(p, dtype=bool)
    n, d = scene.polygon_normal, scene.polygon_offset
    verts_of = [np.unique(scene.triangles[scene.polygon_triangles(i)]) for i in range(p)]
    for i in range(p):
        pts = scene.vertices[verts_of[i]]
        # candidate hosts: other objects, parallel, same plane
        par = (np.abs(n @ n[i]) > 1 - 1e-9) & (scene.polygon_object != scene.polygon_object[i])
        cand = np.nonzero(par)[0]
        if len(cand) == 0:
            continue
        on = np.all(np.abs(pts @ n[cand].T - d[cand]) <= tol, axis=0)
        for q in cand[on]:
            if points_in_polygons(scene, pts, np.full(len(pts), q)).all():
                hidden[i] = True
                break
    return hidden


def points_inside_closed(scene: "Scene", points: np.ndarray) -> np.ndarray:
    """(k, objects) bool: whether each point lies inside each closed object (ray parity, float64).

    A ray along a fixed irrational direction is cast from each point; crossings with the
    object's triangles are counted. Meant for a handful of points (transmitters).
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    closed = closed_objects(scene)
    out = np.zeros((len(points), len(closed)), dtype=bool)
    direction = np.array([0.5773502691896258, 0.5773502691896257, 0.5773502691896259])
    direction = direction + np.array([1e-3, -2e-3, 3e-3])
    direction /= np.linalg.norm(direction)
    for o in np.nonzero(closed)[0]:
        t = scene.triangles[scene.triangle_object == o]
        v0 = scene.vertices[t[:, 0]]
        e1 = scene.vertices[t[:, 1]] - v0
        e2 = scene.vertices[t[:, 2]] - v0
        pvec = np.cross(direction, e2)
        det = np.einsum("fj,fj->f", e1, pvec)
        ok = np.abs(det) > 1e-300
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        tvec = points[:, None, :] - v0[None]
        u = np.einsum("kfj,fj->kf", tvec, pvec) * inv
        q = np.cross(tvec, e1[None])
        v = (q @ direction) * inv
        s = np.einsum("kfj,fj->kf", q, e2) * inv
        hits = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (s > 0)
        out[:, o] = hits.sum(axis=1) % 2 == 1
    return out
