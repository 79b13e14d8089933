"""Small geometric kernels on arrays: mirror images, line-plane intersections,
and the seed's closed-form diffraction point (§2.3)."""

from __future__ import annotations

import numpy as np

from .._vec import dot3


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
    da = dot3(a, normals) - offsets  # the kernels' summation order (wavepaths._vec)
    db = dot3(b, normals) - offsets
    den = da - db
    ok = np.abs(den) > 0
    t = np.where(ok, da / np.where(ok, den, 1.0), -1.0)
    return a + t[:, None] * (b - a), t


def diffraction_point_parameter(
    e: np.ndarray, r: np.ndarray, origin: np.ndarray, direction: np.ndarray
) -> np.ndarray:
    """Closed-form diffraction point on an edge line (seed §2.3).

    With ``v_e = E - A``, ``v_r = R - A`` (``A = origin``, ``w = direction``), the
    projections ``t_e = v_e . w``, ``t_r = v_r . w`` of ``E`` and ``R`` on the edge line
    ``A + t w`` and their distances to it ``d_e = |v_e - t_e w|``,
    ``d_r = |v_r - t_r w|``, Keller's equal-angle law ``tan(alpha) = tan(beta)``, i.e.
    ``(t - t_e) / d_e = (t_r - t) / d_r``, gives

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

    Notes
    -----
    The distances come from the projected vector ``v - t w``, not from
    ``d^2 = v . v - t^2``: the latter cancels when a point is close to the edge line
    (its absolute error is about ``eps |v|^2 / d``, against ``eps |v|`` here). Recomputing
    only the rows with ``d^2 < c v . v`` does not pay: with ``c = 1e-6`` (rows rare, a few
    ns per point saved) the error just above the threshold is up to 2e3 times this
    kernel's, and with ``c = 1e-2`` (error within 20x) the recomputation costs as much as
    the projection. The speed comes from elementwise ufuncs on the coordinate columns
    instead of ``einsum`` and ``np.linalg.norm`` over the length-3 axis (both slow for it).
    Inputs of equal shapes are used as they are; other shapes are broadcast first.
    """
    shape = e.shape
    if not (r.shape == shape and origin.shape == shape and direction.shape == shape):
        e, r, origin, direction = np.broadcast_arrays(e, r, origin, direction)
        shape = e.shape
    if len(shape) == 1:  # one point pair: a 0-d result
        return diffraction_point_parameter(e[None], r[None], origin[None], direction[None]).reshape(())
    with np.errstate(over="ignore", invalid="ignore"):  # the rows beyond the range are recomputed below
        t, s = _point_parameter(e, r, origin, direction)
    # rows beyond float64's range for the squares of the distances (coordinates above ~1e154
    # overflow, below ~1e-154 underflow): again on coordinates scaled by a power of two, which
    # is exact, so that coordinates of any finite magnitude give the point (docs/stress.md S23;
    # the scale is the largest coordinate's, so ends 1e-165 m from the line of an edge 1 m away
    # still underflow: the midpoint)
    if t.size and not (np.isfinite(t.sum()) and s.min() >= _SCALED_BELOW):  # (two passes, no temporaries)
        rows = np.nonzero(~np.isfinite(t) | (s < _SCALED_BELOW))
        big = np.maximum(np.maximum(np.abs(e[rows]).max(axis=-1), np.abs(r[rows]).max(axis=-1)),
                         np.abs(origin[rows]).max(axis=-1))
        # 2^-exponent of the largest coordinate (capped at 2^1000: subnormal inputs come up to ~1e-22)
        k = np.ldexp(1.0, np.minimum(-np.frexp(np.where(np.isfinite(big) & (big > 0), big, 1.0))[1], 1000))[..., None]
        t2, _ = _point_parameter(e[rows] * k, r[rows] * k, origin[rows] * k, direction[rows])
        t[rows] = t2 / k[..., 0]
    return t


_SCALED_BELOW = 2.0**-460
"""``d_e + d_r`` [m] below which :func:`diffraction_point_parameter` recomputes a row on scaled
coordinates (the squares of distances near 2^-460 are near float64's subnormal range)."""


def _point_parameter(e: np.ndarray, r: np.ndarray, origin: np.ndarray, direction: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`diffraction_point_parameter` on arrays of equal shapes (..., 3), and ``d_e + d_r``."""
    w = direction
    ve = np.subtract(e, origin, dtype=np.float64)
    vr = np.subtract(r, origin, dtype=np.float64)
    p = ve * w  # scratch (..., 3)
    te = p[..., 0] + p[..., 1]
    te += p[..., 2]
    np.multiply(vr, w, out=p)
    tr = p[..., 0] + p[..., 1]
    tr += p[..., 2]
    np.multiply(te[..., None], w, out=p)
    ve -= p  # v_e - t_e w, perpendicular to the edge
    np.multiply(tr[..., None], w, out=p)
    vr -= p
    ve *= ve
    de = ve[..., 0] + ve[..., 1]
    de += ve[..., 2]
    np.sqrt(de, out=de)
    vr *= vr
    dr = vr[..., 0] + vr[..., 1]
    dr += vr[..., 2]
    np.sqrt(dr, out=dr)
    t = te * dr
    t += tr * de
    s = de
    s += dr  # d_e + d_r (d_e is not used again)
    if s.all():  # no row with both points on the line (NaN rows stay NaN, as before)
        t /= s
        return t, s
    ok = s > 0
    return np.where(ok, t / np.where(ok, s, 1.0), 0.5 * (te + tr)), s


def diffraction_point_reduced(te: np.ndarray, de: np.ndarray, tr: np.ndarray, dr: np.ndarray) -> np.ndarray:
    """The closed-form point (seed §2.3) from the end points' reduced coordinates.

    ``t = (t_e d_r + t_r d_e) / (d_e + d_r)``, with ``t_e, t_r`` the coordinates of the
    projections of E and R along the edge [m from its origin] and ``d_e, d_r`` their
    distances to the edge line [m] (see :func:`diffraction_point_parameter`, which
    computes them from 3-D points). The path search computes them once per (end point,
    edge) and calls this per candidate pair: a few flops each.

    Parameters
    ----------
    te, de, tr, dr : (k,) float64

    Returns
    -------
    (k,) float64
        ``t`` [m]; the midpoint ``(t_e + t_r) / 2`` where ``d_e + d_r = 0``.
    """
    den = de + dr
    num = te * dr
    num += tr * de
    if den.all():
        return np.divide(num, den, out=num)
    ok = den > 0
    return np.where(ok, num / np.where(ok, den, 1.0), 0.5 * (te + tr))
