"""The numba kernel behind :func:`wavepaths.em.antennas.antenna_field_vectors` (imported
only when numba is installed).

The numpy code of :mod:`wavepaths.em.antennas` and :mod:`wavepaths.em.polarization` is
the reference: this kernel runs its expressions direction by direction, in the same
order, without its dozens of temporaries (a coverage tile evaluates both antennas on
tens of thousands of paths). Equal to the reference to rounding
(``tests/em/test_antennas.py``).
"""

import math

import numba
import numpy as np

PATTERN_CODES = {"iso": 0, "dipole": 1, "hw_dipole": 2, "tr38901": 3}
MODEL_CODES = {"tr38901_1": 1, "tr38901_2": 2}

_SQRT_1_5 = math.sqrt(1.5)
_SQRT_1_643 = math.sqrt(1.643)
_DEG65 = math.radians(65.0)


@numba.njit(cache=True, nogil=True, inline="always")
def _amplitude(pattern, zl, rho, x, y, tol):
    # wavepaths.em.antennas._vertical_amplitude on the local direction (x, y, zl)
    if pattern == 0:
        return 1.0
    if pattern == 1:
        return _SQRT_1_5 * rho
    if pattern == 2:
        w = 2.0 * (1.0 + abs(zl))
        u = rho * rho / w
        s = 1.0 if u == 0.0 else math.sin(math.pi * u) / (math.pi * u)  # np.sinc
        return _SQRT_1_643 * s * (math.pi * rho / w)
    # tr38901: theta, phi of wavepaths.em.polarization._theta_phi (its rho is this rho)
    theta = math.atan2(rho, zl)
    phi = 0.0 if rho <= tol else math.atan2(y, x)
    tv = (theta - math.pi / 2) / _DEG65
    th = phi / _DEG65
    a_v = -min(12.0 * (tv * tv), 30.0)
    a_h = -min(12.0 * (th * th), 30.0)
    a_db = -min(-(a_v + a_h), 30.0) + 8.0
    return 10.0 ** (a_db / 20.0)


@numba.njit(cache=True, nogil=True)
def field_vectors(d, R, pattern, slant, model, tol, out):
    """:func:`wavepaths.em.antennas.antenna_field_vectors` into ``out`` (N, P, 3) complex128
    for raw directions ``d`` (N, 3) (normalised here as
    :func:`wavepaths.em.polarization.as_unit_directions` does), the rotation ``R`` (3, 3),
    ``pattern`` and ``model`` codes (:data:`PATTERN_CODES`, :data:`MODEL_CODES`), the ports'
    slant angles ``slant`` (P,) and the pole tolerance ``tol``.

    Returns the first row that is not finite or is a zero vector, or -1 (the caller raises
    the reference's error).
    """
    cos_s, sin_s = np.cos(slant), np.sin(slant)
    for i in range(d.shape[0]):
        x, y, z = d[i, 0], d[i, 1], d[i, 2]
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            return i
        # as_unit_directions: by the largest component first, then by the norm
        scale = max(max(abs(x), abs(y)), abs(z))
        if scale == 0.0:
            return i
        x, y, z = x / scale, y / scale, z / scale
        n = math.sqrt(x * x + y * y + z * z)
        x, y, z = x / n, y / n, z / n
        # _local_pattern: d' = R^T d, re-normalised
        xl = R[0, 0] * x + R[1, 0] * y + R[2, 0] * z
        yl = R[0, 1] * x + R[1, 1] * y + R[2, 1] * z
        zl = R[0, 2] * x + R[1, 2] * y + R[2, 2] * z
        n = math.sqrt(xl * xl + yl * yl + zl * zl)
        xl, yl, zl = xl / n, yl / n, zl / n
        # _spherical_basis of d'
        rho = math.sqrt(xl * xl + yl * yl)
        if rho <= tol:
            # the pole: phi_hat is y_hat made orthogonal to d' (one Gram-Schmidt step)
            fx, fy, fz = -yl * xl, 1.0 - yl * yl, -yl * zl
            m = math.sqrt(fx * fx + fy * fy + fz * fz)
            p0, p1, p2 = fx / m, fy / m, fz / m
            t0, t1, t2 = p1 * zl - p2 * yl, p2 * xl - p0 * zl, p0 * yl - p1 * xl
        else:
            cos_phi, sin_phi = xl / rho, yl / rho
            p0, p1, p2 = -sin_phi, cos_phi, 0.0
            t0, t1, t2 = zl * cos_phi, zl * sin_phi, -rho
        amp = _amplitude(pattern, zl, rho, xl, yl, tol)  # the basis's rho, the same expression
        for port in range(slant.shape[0]):
            cz, sz = cos_s[port], sin_s[port]
            if model == 2:
                a, b = cz, sz
            else:
                a = t1 * sz - t2 * cz
                b = p1 * sz - p2 * cz
                nn = math.sqrt(a * a + b * b)
                safe = nn if nn > tol else 1.0
                a, b = a / safe, b / safe
            ca, cb = a * amp, b * amp
            l0, l1, l2 = ca * t0 + cb * p0, ca * t1 + cb * p1, ca * t2 + cb * p2
            for k in range(3):
                out[i, port, k] = R[k, 0] * l0 + R[k, 1] * l1 + R[k, 2] * l2
    return -1
