"""Polygons as beam apertures: the rectangles the last leg of a reflected chain must pass.

Each polygon is enclosed in a rectangle in its plane (:func:`polygon_quads`); a chain's
last leg must pass through the rectangles of all its mirrors, each unfolded forward
across the later mirrors (:func:`chain_apertures`), which bounds it by the side planes of
the pyramids from the chain's last image through them (:func:`quad_side_planes`,
:func:`chain_beams_meet`). Every plane test keeps a margin of ``1e-9`` of the scene
diagonal and of the distance, so none drops a valid path.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene
    from .images import ImageLevel


def polygon_quads(scene: "Scene") -> np.ndarray:
    """(p, 4, 3) float64: a rectangle in each polygon's plane that contains the polygon [m].

    The rectangle is aligned with the principal axes of the polygon's corners in its plane
    and padded by ``1e-6`` of its size plus the scene's plane tolerance, so that every point
    the point-in-polygon test accepts (barycentric margin ``1e-9``) lies inside it. Its
    corners go around it in order. A beam through the polygon lies in the beam through its
    rectangle, which is a convex cone with four side planes (:func:`quad_side_planes`).
    """
    tri = scene.triangles
    poly = scene.triangle_polygon
    p = scene.num_polygons
    corners = scene.vertices[tri]  # (f, 3, 3)
    owner = np.repeat(poly, 3)
    pts = corners.reshape(-1, 3)
    count = np.bincount(owner, minlength=p).astype(np.float64)
    mean = np.zeros((p, 3))
    np.add.at(mean, owner, pts)
    mean /= np.maximum(count, 1)[:, None]
    n = scene.polygon_normal
    mean -= (np.einsum("ij,ij->i", mean, n) - scene.polygon_offset)[:, None] * n  # onto the plane
    rel = pts - mean[owner]
    cov = np.zeros((p, 3, 3))
    np.add.at(cov, owner, rel[:, :, None] * rel[:, None, :])
    proj = np.eye(3)[None] - n[:, :, None] * n[:, None, :]
    cov = proj @ cov @ proj
    _, vec = np.linalg.eigh(cov)
    u = vec[:, :, 2]  # largest in-plane axis
    u -= np.einsum("ij,ij->i", u, n)[:, None] * n
    norm = np.linalg.norm(u, axis=1)
    # polygons without a dominant axis: any in-plane direction
    axis = np.eye(3)[np.argmin(np.abs(n), axis=1)]
    fallback = np.cross(n, axis)
    bad = norm < 1e-6
    u[bad] = fallback[bad]
    u /= np.linalg.norm(u, axis=1)[:, None]
    v = np.cross(n, u)
    cu, cv = np.einsum("ij,ij->i", rel, u[owner]), np.einsum("ij,ij->i", rel, v[owner])
    lo_u = np.full(p, np.inf)
    hi_u = np.full(p, -np.inf)
    lo_v = np.full(p, np.inf)
    hi_v = np.full(p, -np.inf)
    np.minimum.at(lo_u, owner, cu)
    np.maximum.at(hi_u, owner, cu)
    np.minimum.at(lo_v, owner, cv)
    np.maximum.at(hi_v, owner, cv)
    pad = 1e-6 * np.hypot(hi_u - lo_u, hi_v - lo_v) + 2 * scene.length_tolerance(scene.tolerances.plane_distance)
    lo_u, hi_u, lo_v, hi_v = lo_u - pad, hi_u + pad, lo_v - pad, hi_v + pad
    us = np.stack([lo_u, hi_u, hi_u, lo_u], axis=1)
    vs = np.stack([lo_v, lo_v, hi_v, hi_v], axis=1)
    return mean[:, None, :] + us[:, :, None] * u[:, None, :] + vs[:, :, None] * v[:, None, :]


@dataclass(frozen=True)
class Apertures:
    """Bounding shapes of a scene's polygons, as beam apertures.

    Attributes
    ----------
    centre : (p, 3) float64, radius : (p,) float64
        Bounding spheres (:func:`~wavepaths.scene.polygon_shapes.polygon_spheres`) [m].
    quads : (p, 4, 3) float64
        Bounding rectangles in their planes (:func:`polygon_quads`) [m].
    """

    centre: np.ndarray
    radius: np.ndarray
    quads: np.ndarray


def scene_apertures(scene: "Scene") -> Apertures:
    """The :class:`Apertures` of ``scene``'s polygons."""
    centre, radius = scene.polygon_spheres
    return Apertures(centre, radius, polygon_quads(scene))


def quad_side_planes(apex: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """(m, 4, 3) float64: inward unit normals of the side planes of the beams from ``apex`` through ``quads``.

    Parameters
    ----------
    apex : (m, 3) float64
    quads : (m, 4, 3) float64
        Convex quadrilaterals, corners in order (either way round).

    Returns
    -------
    (m, 4, 3) float64
        Side plane ``i`` passes through the apex and corners ``i``, ``i + 1``; a point ``X`` is
        inside the (pointed, convex) beam iff ``normal_i . (X - apex) >= 0`` for all four.
        Degenerate planes (apex in the quad's plane, zero-width quad) get a zero normal, which
        every point passes.
    """
    rel = quads - apex[:, None, :]
    m = np.cross(rel, np.roll(rel, -1, axis=1))
    nq = np.cross(quads[:, 2] - quads[:, 0], quads[:, 3] - quads[:, 1])
    s = -np.sign(np.einsum("ij,ij->i", nq, apex - quads[:, 0]))
    norm = np.linalg.norm(m, axis=2)
    return m * (s[:, None] / np.where(norm > 0, norm, np.inf))[:, :, None]


def _mirror_across(points: np.ndarray, polygons: np.ndarray, scene: "Scene") -> np.ndarray:
    """``points`` (m, ..., 3) mirrored across the planes of ``polygons`` (m,)."""
    n = scene.polygon_normal[polygons]
    d = scene.polygon_offset[polygons]
    shape = (len(polygons),) + (1,) * (points.ndim - 2) + (3,)
    dist = np.einsum("i...j,i...j->i...", points, n.reshape(shape)) - d.reshape(shape[:-1])
    return points - 2.0 * dist[..., None] * n.reshape(shape)


def chain_apertures(
    scene: "Scene", level: "ImageLevel", rows: np.ndarray, centre: np.ndarray | None = None,
    radius: np.ndarray | None = None, quads: np.ndarray | None = None,
) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """What the last leg of each chain passes through, seen from its last image.

    Unfolding a chain ``q_1 .. q_k`` across its mirrors, the last leg (from the last
    reflection point to the receiver, or to a diffraction point) lies on a ray from the last
    image ``I_k`` that crosses ``q_k`` and the images of ``q_j`` (j < k) mirrored across
    ``q_{j+1}``, then ``q_{j+2}``, .., ``q_k`` (where the earlier reflection points unfold to).

    Parameters
    ----------
    scene : Scene
    level : ImageLevel
    rows : (m,) int64
    centre, radius : (p, 3), (p,) float64, optional
        Polygon bounding spheres (:func:`~wavepaths.scene.polygon_shapes.polygon_spheres`).
    quads : (p, 4, 3) float64, optional
        Polygon rectangles (:func:`polygon_quads`).

    Returns
    -------
    centres : (m, k, 3), radii : (m, k)
        The mirrors' bounding spheres, mirrored so [m] (None without ``centre``).
    quads : (m, k, 4, 3)
        Their rectangles, mirrored so (None without ``quads``).
    """
    k = level.order
    polys = level.polygons[rows]
    cen = None if centre is None else centre[polys]
    rad = None if radius is None else radius[polys]
    qd = None if quads is None else quads[polys]
    for j in range(k - 1):
        for i in range(j + 1, k):
            if cen is not None:
                cen[:, j] = _mirror_across(cen[:, j], polys[:, i], scene)
            if qd is not None:
                qd[:, j] = _mirror_across(qd[:, j], polys[:, i], scene)
    return cen, rad, qd


def chain_beams_meet(
    scene: "Scene", level: "ImageLevel", rows: np.ndarray, quads: np.ndarray, centre: np.ndarray,
    radius: np.ndarray | None = None, end: np.ndarray | None = None, slack: float | None = None,
    owner: np.ndarray | None = None,
) -> np.ndarray:
    """(m,) bool: whether the last leg of chain ``rows[owner[i]]`` can reach target ``i`` (a sphere or a segment).

    The target is the sphere ``(centre[i], radius[i])``, or the segment ``centre[i] -> end[i]``
    when ``end`` is given. Without ``owner`` target ``i`` is tested against chain
    ``rows[i]``; with it (several targets per chain), the per-chain work (the mirrored
    apertures and the beams' side planes) is done once per chain. Two necessary conditions
    for a point of the target to end the last leg (see :func:`chain_apertures`):

    * it lies beyond the last mirror ``q_k``, on the side opposite the last image (the
      back-tracing needs the segment from it to ``I_k`` to cross ``q_k``'s plane);
    * the ray from ``I_k`` to it passes through the rectangle of ``q_k`` and those of the
      earlier mirrors mirrored forward, so it is inside each of these convex beams.

    Each is tested as "not entirely outside one bounding plane" (a sphere: centre farther
    than its radius outside; a segment: both ends outside), with a margin ``slack`` [m]
    (default ``1e-9`` of the scene diagonal plus ``1e-9`` of the distance to the apex): a
    target that some valid leg reaches always passes.
    """
    k = level.order
    owner = np.arange(len(rows)) if owner is None else np.asarray(owner, np.int64)
    m = len(owner)
    if m == 0:
        return np.zeros(0, bool)
    eps = scene.length_tolerance(1e-9) if slack is None else slack
    apex_c = level.images[rows, -1]  # per chain
    qk = level.polygons[rows, -1]
    n_c = scene.polygon_normal[qk]
    d_c = scene.polygon_offset[qk]
    side_c = np.sign(np.einsum("ij,ij->i", apex_c, n_c) - d_c)  # the last image's side of q_k
    apex, n, d, side = apex_c[owner], n_c[owner], d_c[owner], side_c[owner]
    rad = np.zeros(m) if radius is None else radius
    far = 1e-9 * np.linalg.norm(centre - apex, axis=1) + eps
    if end is None:
        keep = side * (np.einsum("ij,ij->i", centre, n) - d) < rad + far
    else:
        far = np.maximum(far, 1e-9 * np.linalg.norm(end - apex, axis=1) + eps)
        keep = (side * (np.einsum("ij,ij->i", centre, n) - d) < far) | (
            side * (np.einsum("ij,ij->i", end, n) - d) < far
        )
    idx = np.nonzero(keep)[0]
    used, inv = np.unique(owner[idx], return_inverse=True)  # chains still needed, once each
    _, _, qd = chain_apertures(scene, level, rows[used], quads=quads)
    for j in range(k):
        if len(idx) == 0:
            break
        planes = quad_side_planes(apex_c[used], qd[:, j])[inv]
        a = np.einsum("ikj,ij->ik", planes, centre[idx] - apex[idx])
        if end is None:
            ok = (a >= -(rad[idx] + far[idx])[:, None]).all(axis=1)
        else:
            b = np.einsum("ikj,ij->ik", planes, end[idx] - apex[idx])
            ok = (np.maximum(a, b) >= -far[idx][:, None]).all(axis=1)
        idx, inv = idx[ok], inv[ok]
    out = np.zeros(m, bool)
    out[idx] = True
    return out
