"""Small geometric kernels on arrays: mirror images, line-plane intersections,
and the seed's closed-form diffraction point (§2.3)."""

from __future__ import annotations

import numpy as np


def mirror_points(points: np.ndarray, normals: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Mirror images of ``points`` across planes ``n . x = d``.

    Parameters
    ----------
    points : (..., 3) float64 [m]
    normals : (..., 3) float64, unit
    offsets : (...,) float64 [m]

    Returns
    -------
    (..., 3) float64: ``x - 2 (n . x - d) n``.
    """
    dist = np.einsum("...j,...j->...", points, normals) - offsets
    return points - 2.0 * dist[..., None] * normals


def segment_plane_intersection(a: np.ndarray, b: np.ndarray, normals: np.ndarray, offsets: np.ndarray):
    """Where the segments ``a -> b`` cross the planes ``n . x = d``.

    Parameters
    ----------
    a, b : (k, 3) float64
    normals : (k, 3) float64
    offsets : (k,) float64

    Returns
    -------
    points : (k, 3) float64
    t : (k,) float64
        Parameter along ``a -> b``; the crossing lies strictly inside the segment
        when ``0 < t < 1``. Segments parallel to their plane get ``t = nan``-free
        sentinel ``-1``.
    """
    da = np.einsum("ij,ij->i", a, normals) - offsets
    db = np.einsum("ij,ij->i", b, normals) - offsets
    den = da - db
    ok = np.abs(den) > 0
    t = np.where(ok, da / np.where(ok, den, 1.0), -1.0)
    return a + t[:, None] * (b - a), t


def diffraction_point_parameter(
    e: np.ndarray, r: np.ndarray, origin: np.ndarray, direction: np.ndarray
) -> np.ndarray:
    """Closed-form diffraction point on an edge line (seed §2.3).

    With ``t_e``, ``t_r`` the parameters of the projections of ``E`` and ``R`` on the
    edge line ``origin + t * direction`` and ``d_e``, ``d_r`` their distances to it,
    Keller's equal-angle law ``tan(alpha) = tan(beta)`` gives

    ``t = (t_e d_r + t_r d_e) / (d_e + d_r)``.

    Parameters
    ----------
    e, r : (..., 3) float64
        End points (or image points) [m].
    origin : (..., 3) float64
        A point A of the edge line [m].
    direction : (..., 3) float64
        Unit edge vector.

    Returns
    -------
    (...,) float64
        ``t`` [m from A]. When both points lie on the line (``d_e + d_r = 0``) the
        midpoint of their projections is returned: the path then runs along the edge
        and is rejected later by the segment and validity tests.
    """
    ve = e - origin
    vr = r - origin
    te = np.einsum("...j,...j->...", ve, direction)
    tr = np.einsum("...j,...j->...", vr, direction)
    de = np.linalg.norm(ve - te[..., None] * direction, axis=-1)
    dr = np.linalg.norm(vr - tr[..., None] * direction, axis=-1)
    s = de + dr
    ok = s > 0
    return np.where(ok, (te * dr + tr * de) / np.where(ok, s, 1.0), 0.5 * (te + tr))
