"""Rays for launched candidates (:mod:`wavepaths.search.launch`): directions, first hits
(Embree names the face, float64 places the point), and the branches of a ray whose spacing
reaches a convex edge of the face it hits."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..errors import WavepathsError

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene


def fibonacci_directions(n: int) -> np.ndarray:
    """(n, 3) unit vectors spread evenly over the sphere (a Fibonacci lattice: equal-area
    bands in z, golden-angle steps in azimuth); spacing about ``sqrt(4 pi / n)`` rad."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, 1.0))
    phi = np.pi * (1.0 + 5.0**0.5) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def first_hits(scene: "Scene", origin: np.ndarray, direction: np.ndarray, far: float, eps: float):
    """(polygon or -1, distance along the unit ``direction`` [m]) of each ray's first hit.

    The caster (Embree, float32) names the face; the distance is the float64 intersection
    with that face's plane, so the reflected rays start on their mirrors."""
    caster = scene.raycaster
    hits = getattr(caster, "first_hits", None)
    if hits is not None:
        tri = hits(origin + eps * direction, direction, far)
    else:
        first = getattr(caster, "first_triangle", None)
        if first is None:
            raise WavepathsError("launched candidates need a ray caster with first hits (Embree: pip install embreex)")
        tri = first(origin + eps * direction, origin + far * direction)
    poly = np.where(tri >= 0, scene.triangle_polygon[np.maximum(tri, 0)], -1)
    hit = np.nonzero(poly >= 0)[0]
    dist = np.full(len(origin), far)
    n = scene.polygon_normal[poly[hit]]
    den = np.einsum("ij,ij->i", n, direction[hit])
    num = scene.polygon_offset[poly[hit]] - np.einsum("ij,ij->i", n, origin[hit])
    ok = np.abs(den) > 1e-12
    dist[hit[ok]] = np.maximum(num[ok] / den[ok], 0.0)  # float32 may name a face a hair behind
    poly[hit[~ok]] = -1  # a graze along the plane: no reflection
    return poly, dist


def first_hits_past(scene: "Scene", origin: np.ndarray, direction: np.ndarray, far: float, eps: float,
                     skip: np.ndarray, rounds: int = 3):
    """:func:`first_hits`, passing through the polygons ``skip`` (k, m) of each ray (-1: none):
    the faces of the wedge a fan ray leaves, or the mirror a reflected ray leaves. A ray that
    leaves an edge into the wedge's exterior never meets the wedge's own faces; one that does
    grazes them within float32 resolution of its start (a ground plane's far edge seen at half
    a degree), and is cast again from there."""
    poly, dist = first_hits(scene, origin, direction, far, eps)
    for _ in range(rounds):
        again = np.nonzero((poly[:, None] == skip).any(axis=1) & (poly >= 0))[0]
        if len(again) == 0:
            break
        start = origin[again] + dist[again, None] * direction[again]
        p2, d2 = first_hits(scene, start, direction[again], far, eps)
        poly[again] = p2
        dist[again] = np.where(p2 >= 0, dist[again] + d2, far)
    return poly, dist


FOOTPRINT_MAX = 2.0
"""Largest footprint of the rays' spacing on a plane, in spacings (grazing incidence)."""


def _adjacency(scene: "Scene") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSR over polygons: for each polygon, its (dihedron, other polygon) pairs across its
    convex edges (the diffracting dihedra: where one face can shadow the other, so a beam can
    pass beside the corner as a sliver; at a concave corner both faces look into the same
    space and the rays on either side follow both). Kept on the scene
    (:meth:`~wavepaths.scene.model.Scene.memo`)."""
    return scene.memo("launch_adjacency", lambda: _compute_adjacency(scene))


def _compute_adjacency(scene: "Scene") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_adjacency`, computed."""
    D = scene.dihedra
    owner = np.repeat(np.arange(len(D.face_ptr) - 1), np.diff(D.face_ptr))
    # every ordered pair of distinct faces of one dihedron
    fa, fb = [], []
    for j in range(int(np.diff(D.face_ptr).max(initial=0))):
        for i in range(int(np.diff(D.face_ptr).max(initial=0))):
            if i == j:
                continue
            ok = np.nonzero(np.diff(D.face_ptr) > max(i, j))[0]
            fa.append(D.face_ptr[ok] + i)
            fb.append(D.face_ptr[ok] + j)
    fa = np.concatenate(fa) if fa else np.zeros(0, np.int64)
    fb = np.concatenate(fb) if fb else np.zeros(0, np.int64)
    pa, pb, dd = D.face_polygon[fa], D.face_polygon[fb], owner[fa]
    keep = (pa != pb) & D.diffracting[dd]
    pa, pb, dd = pa[keep], pb[keep], dd[keep]
    o = np.argsort(pa, kind="stable")
    ptr = np.searchsorted(pa[o], np.arange(scene.num_polygons + 1))
    return ptr, dd[o], pb[o]


def neighbour_branches(scene: "Scene", poly: np.ndarray, x: np.ndarray, u: np.ndarray, radius: np.ndarray,
                        origin: np.ndarray, compiled: bool = True):
    """Where a ray's tube hit polygon ``poly`` at ``x`` near one of its edges, the polygons
    across that edge that the rest of the tube may hit instead (a beam that is a sliver beside
    a corner, which no ray of the fan follows): ``(row, polygon, distance along u to its
    plane)``. Near means within the footprint of the rays' spacing ``radius`` on the hit
    plane, ``radius / |u . n|``, at most ``FOOTPRINT_MAX`` spacings: the beam between this
    ray and its neighbour may straddle the edge. (A cap of 4 branched almost every hit of
    munich's fans, 7x the candidates; without the factor, one D-R path of the street canyon
    is missed at 1,024 directions per turn.)"""
    ptr, dih, other = _adjacency(scene)
    from . import kernels

    if compiled and kernels.available():
        from . import _numba_launch

        D = scene.dihedra
        c = np.ascontiguousarray
        args = (c(poly, dtype=np.int64), c(x, dtype=np.float64), c(u, dtype=np.float64), c(radius, dtype=np.float64),
                c(origin, dtype=np.float64), ptr, dih, other, D.origin, D.direction, D.length, scene.polygon_normal,
                scene.polygon_offset, c(scene.polygon_spheres[0]), float(FOOTPRINT_MAX))
        counts = np.empty(len(poly), np.int64)
        _numba_launch.branch_counts(*args, counts)
        start = np.zeros(len(poly) + 1, np.int64)
        np.cumsum(counts, out=start[1:])
        q, step = np.empty(int(start[-1]), np.int64), np.empty(int(start[-1]))
        _numba_launch.branch_fill(*args, start, q, step)
        return np.repeat(np.arange(len(poly)), counts), q, step
    cnt = ptr[poly + 1] - ptr[poly]
    row = np.repeat(np.arange(len(poly)), cnt)
    j = np.repeat(ptr[poly], cnt) + (np.arange(len(row)) - np.repeat(np.cumsum(cnt) - cnt, cnt))
    d, q = dih[j], other[j]
    D = scene.dihedra
    cos_i = np.abs(np.einsum("ij,ij->i", u, scene.polygon_normal[poly]))
    foot = radius * np.minimum(1.0 / np.maximum(cos_i, 1e-12), FOOTPRINT_MAX)
    v = x[row] - D.origin[d]
    t = np.clip(np.einsum("ij,ij->i", v, D.direction[d]), 0.0, D.length[d])
    near = np.einsum("ij,ij->i", v - t[:, None] * D.direction[d], v - t[:, None] * D.direction[d]) <= foot[row] ** 2
    row, q = row[near], q[near]
    # only where the ray comes from the front of the polygon beyond the edge: its origin and
    # the polygon hit lie on opposite sides of that polygon's plane (a convex corner seen
    # from outside); otherwise no neighbouring ray can reach its front
    n = scene.polygon_normal[q]
    off = scene.polygon_offset[q]
    centre = scene.polygon_spheres[0][poly[row]]
    side_o = np.einsum("ij,ij->i", n, origin[row]) - off
    side_p = np.einsum("ij,ij->i", n, centre) - off
    front = side_o * side_p < 0
    row, q, n = row[front], q[front], n[front]
    den = np.einsum("ij,ij->i", n, u[row])
    # the ray's own line, continued (or shortened) to the other polygon's plane, from x
    num = scene.polygon_offset[q] - np.einsum("ij,ij->i", n, x[row])
    ok = np.abs(den) > 1e-9
    row, q, step = row[ok], q[ok], num[ok] / den[ok]
    return row, q, step


def reflect_and_branch(scene: "Scene", origin: np.ndarray, u: np.ndarray, poly: np.ndarray, dist: np.ndarray,
                       travelled: np.ndarray, spacing_base, spacing_slope, spacing_scale: float = 1.0):
    """The rays that go on after the hits ``poly`` (k,) at ``dist`` (k,): each hit's specular
    reflection, and its branches (:func:`neighbour_branches`) to the faces beside it.

    The rays' spacing at a hit is ``(spacing_base + spacing_slope * (travelled + dist)) /
    spacing_scale`` (``spacing_base``, ``spacing_slope``: scalars or (k,) arrays). Returns ``(rows, mirror, origin, direction, travelled)``: for
    each new ray the row of the ray it continues, the face it reflects on, its start and
    unit direction, and the unfolded distance from the source to its start [m].
    """
    hr = np.nonzero(poly >= 0)[0]
    x = origin[hr] + dist[hr, None] * u[hr]
    at = travelled[hr] + dist[hr]
    spacing = (np.broadcast_to(spacing_base, poly.shape)[hr]
               + np.broadcast_to(spacing_slope, poly.shape)[hr] * at) / spacing_scale
    br, bq, bstep = neighbour_branches(scene, poly[hr], x, u[hr], spacing, origin[hr])
    rows = np.concatenate([hr, hr[br]])
    mirror = np.concatenate([poly[hr], bq])
    start = np.concatenate([x, x[br] + bstep[:, None] * u[hr[br]]])
    at = np.concatenate([at, np.maximum(at[br] + bstep, 0.0)])
    n = scene.polygon_normal[mirror]
    v = u[rows]
    return rows, mirror, start, v - 2.0 * np.einsum("ij,ij->i", v, n)[:, None] * n, at
