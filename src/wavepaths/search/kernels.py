"""Optional compiled kernels (numba) for the densest loops of the path search.

The numpy code in :mod:`wavepaths.search.tile` is the reference. Where a test is an outer
product over (receiver images x dihedra), numpy materialises a dozen (E, D) temporaries
per chunk; on ``etoile_crop`` at depth 3 that is 596 M pairs at about 54 ns each, the
largest single cost of the query (``docs/benchmarks.md``). The kernels here evaluate the
same tests, with the same margins, pair by pair with an early exit, and write one boolean
per pair.

numba is an optional dependency (the ``fast`` extra). Without it, or with
``TraceOptions(compiled=False)``, the numpy reference runs. Results agree pair for pair
except where a quantity lands within rounding (~1e-16 relative) of a test's margin: the
kernels compute a pair's distances directly, the numpy code by expanded matrix products
(tests/search/test_kernels.py compares them).

The kernels are compiled on first use (``cache=True``: once per machine, then loaded from
numba's cache).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np


@lru_cache(maxsize=1)
def _compiled():
    """The compiled kernels, or ``None`` when numba is not installed."""
    try:
        import numba
    except ImportError:
        return None

    @numba.njit(cache=True, nogil=True)
    def receiver_pairs(I, n, off, side, A, B, plane_tol, mirror, to_q, dist_q, radius_q, M, h, beam,
                       R, origin, direction, x_hat, y_hat, v_lo, lo, v_hi, hi, keller_tol, window, ok):
        E = I.shape[0]
        D = A.shape[0]
        n_mirror = 0
        n_beam = 0
        n_window = 0
        for i in range(E):
            # (without the mirror or beam test, its arrays are zeros of the right shape)
            s = side[i]
            n0, n1, n2, o = n[i, 0], n[i, 1], n[i, 2], off[i]
            q0, q1, q2 = to_q[i, 0], to_q[i, 1], to_q[i, 2]
            dq = dist_q[i]
            sin_q = min(max(radius_q[i] / max(dq, 1e-300), 0.0), 1.0)
            cos_q = np.sqrt(1.0 - sin_q * sin_q)
            q_inside = dq <= radius_q[i]
            i0, i1, i2 = I[i, 0], I[i, 1], I[i, 2]
            r0, r1, r2 = R[i, 0], R[i, 1], R[i, 2]
            for j in range(D):
                ok[i, j] = False
                if mirror:
                    sa = s * (n0 * A[j, 0] + n1 * A[j, 1] + n2 * A[j, 2] - o)
                    sb = s * (n0 * B[j, 0] + n1 * B[j, 1] + n2 * B[j, 2] - o)
                    if not max(sa, sb) > -plane_tol:
                        n_mirror += 1
                        continue
                if beam:
                    m0, m1, m2 = M[j, 0] - i0, M[j, 1] - i1, M[j, 2] - i2
                    dm = np.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
                    if not (q_inside or dm <= h[j]):
                        c = (q0 * m0 + q1 * m1 + q2 * m2) / max(dq * dm, 1e-300)
                        sin_m = min(max(h[j] / max(dm, 1e-300), 0.0), 1.0)
                        cos_m = np.sqrt(1.0 - sin_m * sin_m)
                        cos_sum = cos_q * cos_m - sin_q * sin_m
                        sin_sum = sin_q * cos_m + cos_q * sin_m
                        if not c >= cos_sum - 1e-9 * sin_sum - 1e-12:
                            n_beam += 1
                            continue
                if window:
                    v0, v1, v2 = r0 - origin[j, 0], r1 - origin[j, 1], r2 - origin[j, 2]
                    x = v0 * x_hat[j, 0] + v1 * x_hat[j, 1] + v2 * x_hat[j, 2]
                    y = v0 * y_hat[j, 0] + v1 * y_hat[j, 1] + v2 * y_hat[j, 2]
                    t = v0 * direction[j, 0] + v1 * direction[j, 1] + v2 * direction[j, 2]
                    rho = np.hypot(x, y)
                    if not ((t - v_lo[j] - lo[j] * rho >= -keller_tol) and (t - v_hi[j] - hi[j] * rho <= keller_tol)):
                        n_window += 1
                        continue
                ok[i, j] = True
        return n_mirror, n_beam, n_window

    return {"receiver_pairs": receiver_pairs}


def available() -> bool:
    """Whether the compiled kernels can run (numba is installed)."""
    return _compiled() is not None


def receiver_pairs(
    I: np.ndarray,
    mirror: tuple[np.ndarray, np.ndarray, np.ndarray, float] | None,
    A: np.ndarray,
    B: np.ndarray,
    beam: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None,
    R: np.ndarray,
    frame: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    window: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float] | None,
) -> tuple[np.ndarray, int, int, int]:
    """The dense receiver-side tests of :func:`wavepaths.search.tile._receiver_side`, fused per pair.

    Parameters
    ----------
    I : (E, 3) float64
        The receiver images, recentred on the scene centre [m].
    mirror : (n (E, 3), off (E,), side (E,), plane_tol) or None
        The images' last mirror planes (recentred offsets) and the side of the previous
        image: a pair passes if an edge end lies on that side, within ``plane_tol`` [m].
    A, B : (D, 3) float64
        The edges' ends, recentred [m].
    beam : (to_q (E, 3), dist_q (E,), radius_q (E,), M (D, 3), h (D,)) or None
        The bounding-sphere beam: from each image to its last mirror's sphere (centre
        offset ``to_q``, distance, radius) against each edge's sphere (recentred midpoint
        ``M``, half-length ``h``); the angular test with a 1e-9 rad margin.
    R : (E, 3) float64
        The same images in scene coordinates [m] (for the Keller window, in the edge frame).
    frame : (origin, direction, x_hat, y_hat), each (D, 3)
        The edges' frames (:func:`wavepaths.search.tile._edge_frame`).
    window : (v_lo, lo, v_hi, hi (D,), keller_tol) or None
        The Keller window of each edge (:func:`wavepaths.search.tile._keller_window`,
        indexed by these D edges) and its margin [m].

    Returns
    -------
    ok : (E, D) bool
        The pairs that pass every test given.
    rejected_mirror_side, rejected_beam, rejected_keller_window : int
        How many pairs each test rejected (each pair counted by the first test it fails).
    """
    k = _compiled()["receiver_pairs"]
    E, D = len(I), len(A)
    z1 = np.zeros(D)
    if mirror is None:
        n, off, side, plane_tol = np.zeros((E, 3)), np.zeros(E), np.zeros(E), 0.0
    else:
        n, off, side, plane_tol = mirror
    to_q, dist_q, radius_q, M, h = beam if beam is not None else (np.zeros((E, 3)), np.zeros(E), np.zeros(E),
                                                                   np.zeros((D, 3)), np.zeros(D))
    v_lo, lo, v_hi, hi, keller_tol = window if window is not None else (z1, z1, z1, z1, 0.0)
    origin, direction, x_hat, y_hat = frame
    ok = np.empty((E, D), dtype=np.bool_)
    c = np.ascontiguousarray
    counts = k(c(I), c(n), c(off), c(side), c(A), c(B), float(plane_tol), mirror is not None,
               c(to_q), c(dist_q), c(radius_q), c(M), c(h), beam is not None,
               c(R), c(origin), c(direction), c(x_hat), c(y_hat), c(v_lo), c(lo), c(v_hi), c(hi),
               float(keller_tol), window is not None, ok)
    return ok, int(counts[0]), int(counts[1]), int(counts[2])
