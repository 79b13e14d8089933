"""A slow, independent enumerator of propagation paths, for completeness tests.

It shares no search code with the engine: every sequence of polygons (and of polygons
and one dihedron) is tried without pruning, reflection points come from explicit
mirror images, the diffraction point from a bounded numerical minimisation of the path
length (not the seed's closed form), the topological test from face angles around the
edge (not FindDihedron), point-in-polygon from triangle areas, and occlusion from the
float64 numpy caster.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.optimize import minimize_scalar

from wavepaths.raycast.numpy_caster import NumpyRayCaster


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


def unfold(scene, start, images, polys):
    """Reflection points going backwards from ``start`` toward the images; None if invalid."""
    pts = []
    y = start
    for img, q in zip(images[::-1], polys[::-1]):
        x = crossing(y, img, scene.polygon_normal[q], scene.polygon_offset[q])
        if x is None or not in_polygon(scene, x, q):
            return None
        pts.append(x)
        y = x
    return pts[::-1]


def images_of(scene, p, polys):
    out = []
    for q in polys:
        p = mirror(p, scene.polygon_normal[q], scene.polygon_offset[q])
        out.append(p)
    return out


def sequences(p, k):
    for seq in itertools.product(range(p), repeat=k):
        if all(seq[i] != seq[i + 1] for i in range(k - 1)):
            yield list(seq)


def same_open_sector(dih, i, e, r, p):
    """E and R strictly inside one sector between the faces around the edge, wider than pi."""
    w = dih.direction[i]
    faces = dih.face_direction[dih.faces(i)]
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
    """All paths as a set of (kinds, primitives, rounded length) tuples."""
    caster = NumpyRayCaster(scene)
    found = {}

    def visible(chain):
        a = np.array(chain[:-1])
        b = np.array(chain[1:])
        return not caster.occluded(a, b).any()

    if visible([tx, rx]):
        found[((), ())] = np.linalg.norm(rx - tx)
    npoly = scene.num_polygons
    for k in range(1, max_reflections + 1):
        for seq in sequences(npoly, k):
            imgs = images_of(scene, tx, seq)
            pts = unfold(scene, rx, imgs, seq)
            if pts is None:
                continue
            chain = [tx, *pts, rx]
            if visible(chain):
                found[(("R",) * k, tuple(seq))] = sum(np.linalg.norm(np.diff(chain, axis=0), axis=1))
    if not diffraction:
        return found
    dih = scene.dihedra
    for i in range(len(dih)):
        o, w, length = dih.origin[i], dih.direction[i], dih.length[i]
        for a in range(diffraction_reflections + 1):
            for b in range(diffraction_reflections + 1 - a):
                for sa in sequences(npoly, a):
                    for sb in sequences(npoly, b):
                        e = images_of(scene, tx, sa)[-1] if a else tx
                        r = images_of(scene, rx, sb[::-1])[-1] if b else rx
                        res = minimize_scalar(lambda t: np.linalg.norm(o + t * w - e) + np.linalg.norm(o + t * w - r),
                                              bounds=(0, length), method="bounded", options={"xatol": 1e-12})
                        t = res.x
                        if t < 1e-6 or t > length - 1e-6:
                            continue  # minimum on an end point: no stationary path on this edge
                        p = o + t * w
                        if not same_open_sector(dih, i, e, r, p):
                            continue
                        pre = unfold(scene, p, images_of(scene, tx, sa), sa) if a else []
                        post = unfold(scene, p, images_of(scene, rx, sb[::-1]), sb[::-1]) if b else []
                        if pre is None or post is None:
                            continue
                        chain = [tx, *pre, p, *post[::-1], rx]
                        if visible(chain):
                            key = (("R",) * a + ("D",) + ("R",) * b, tuple(sa) + (i,) + tuple(sb))
                            found[key] = sum(np.linalg.norm(np.diff(chain, axis=0), axis=1))
    return found
