"""Benchmark 1 with both searches compiled: the closed form and the reduced Newton search as
numba loops over the pairs (imported only when numba is installed).

The numpy figures of :mod:`wavepaths.bench.point_search` compare the two algorithms as
whole-array passes: a Newton iteration there costs a dozen array passes over the pairs still
iterating, where a compiled loop keeps each pair in registers until it converges. Compiled,
both pay only their arithmetic, so the ratio is the algorithms' own: the closed form's two
projections and one division against the Newton search's projections, bracket and
iterations. Same pairs, same formulas and stopping rule as the numpy versions
(:func:`~wavepaths.bench.point_search.closed_form`,
:func:`~wavepaths.bench.point_search.newton_reduced`).
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def closed_form_compiled(e, r, origin, direction, length, t, on):
    """The seed's closed form (§2.3) pair by pair: ``t = (t_e d_r + t_r d_e) / (d_e + d_r)``
    from the 3-D points, the distances from the projected vectors as
    :func:`wavepaths.search.geometry.diffraction_point_parameter` takes them, then the on-edge
    test; into ``t`` and ``on`` (n,)."""
    for i in range(len(length)):
        w0, w1, w2 = direction[i, 0], direction[i, 1], direction[i, 2]
        a0, a1, a2 = e[i, 0] - origin[i, 0], e[i, 1] - origin[i, 1], e[i, 2] - origin[i, 2]
        b0, b1, b2 = r[i, 0] - origin[i, 0], r[i, 1] - origin[i, 1], r[i, 2] - origin[i, 2]
        te = a0 * w0 + a1 * w1 + a2 * w2
        tr = b0 * w0 + b1 * w1 + b2 * w2
        x0, x1, x2 = a0 - te * w0, a1 - te * w1, a2 - te * w2
        y0, y1, y2 = b0 - tr * w0, b1 - tr * w1, b2 - tr * w2
        de = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
        dr = math.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
        den = de + dr
        ti = (te * dr + tr * de) / den if den > 0.0 else 0.5 * (te + tr)
        t[i] = ti
        on[i] = 0.0 <= ti <= length[i]


@numba.njit(cache=True, nogil=True)
def newton_reduced_compiled(e, r, origin, direction, length, tol, max_iter, t, on):
    """The reduced Newton search pair by pair: ``dL/dt = 0`` for
    ``L(t) = sqrt((t - t_e)^2 + d_e^2) + sqrt((t - t_r)^2 + d_r^2)``, safeguarded by bisection
    on ``[0, |AB|]``, started between the projections, stopped when a step is below ``tol``;
    a pair whose slope has the same sign at both ends has no point on the edge. Returns the
    most iterations a pair took."""
    most = 0
    for i in range(len(length)):
        w0, w1, w2 = direction[i, 0], direction[i, 1], direction[i, 2]
        a0, a1, a2 = e[i, 0] - origin[i, 0], e[i, 1] - origin[i, 1], e[i, 2] - origin[i, 2]
        b0, b1, b2 = r[i, 0] - origin[i, 0], r[i, 1] - origin[i, 1], r[i, 2] - origin[i, 2]
        te = a0 * w0 + a1 * w1 + a2 * w2
        tr = b0 * w0 + b1 * w1 + b2 * w2
        de2 = max(a0 * a0 + a1 * a1 + a2 * a2 - te * te, 0.0)
        dr2 = max(b0 * b0 + b1 * b1 + b2 * b2 - tr * tr, 0.0)
        lo, hi = 0.0, length[i]
        g_lo = (lo - te) / math.sqrt((lo - te) ** 2 + de2) + (lo - tr) / math.sqrt((lo - tr) ** 2 + dr2)
        g_hi = (hi - te) / math.sqrt((hi - te) ** 2 + de2) + (hi - tr) / math.sqrt((hi - tr) ** 2 + dr2)
        if not (g_lo < 0.0 and g_hi > 0.0):
            t[i] = lo if g_lo >= 0.0 else hi
            on[i] = False
            continue
        on[i] = True
        ti = min(max(0.5 * (te + tr), lo), hi)
        it = 0
        while it < max_iter:
            it += 1
            xe, xr = ti - te, ti - tr
            le = math.sqrt(xe * xe + de2)
            lr = math.sqrt(xr * xr + dr2)
            g = xe / le + xr / lr
            h = de2 / (le * le * le) + dr2 / (lr * lr * lr)
            if g < 0.0:
                lo = ti
            elif g > 0.0:
                hi = ti
            new = ti - g / h if h > 0.0 else 0.5 * (lo + hi)
            if not lo < new < hi:
                new = 0.5 * (lo + hi)
            done = abs(new - ti) <= tol
            ti = new
            if done:
                break
        t[i] = ti
        most = max(most, it)
    return most


def run_compiled(inst, tol: float = 1e-11, max_iter: int = 100):
    """``(t, on)`` of both kernels and the Newton search's most iterations, for ``inst``
    (:class:`~wavepaths.bench.point_search.EdgeInstances`)."""
    n = len(inst)
    t_cf, on_cf = np.empty(n), np.empty(n, dtype=np.bool_)
    t_nw, on_nw = np.empty(n), np.empty(n, dtype=np.bool_)
    closed_form_compiled(inst.e, inst.r, inst.origin, inst.direction, inst.length, t_cf, on_cf)
    iters = newton_reduced_compiled(inst.e, inst.r, inst.origin, inst.direction, inst.length, tol, max_iter,
                                    t_nw, on_nw)
    return (t_cf, on_cf), (t_nw, on_nw, int(iters))
