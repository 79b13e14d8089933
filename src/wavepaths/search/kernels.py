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
                       planes, aperture_tol, R, origin, direction, x_hat, y_hat, v_lo, lo, v_hi, hi, keller_tol,
                       window, ok):
        # A, B, M, origin, direction, x_hat, y_hat come transposed, (3, D): the first two
        # stages run over contiguous rows, branch-free, and compact the survivors into `buf`
        E = I.shape[0]
        D = A.shape[1]
        P = planes.shape[1]
        n_mirror = 0
        n_beam = 0
        n_aperture = 0
        n_window = 0
        buf = np.empty(D, dtype=np.int64)
        fm = np.ones(D, dtype=np.uint8)
        fb = np.ones(D, dtype=np.uint8)
        Ax, Ay, Az, Bx, By, Bz = A[0], A[1], A[2], B[0], B[1], B[2]
        Mx, My, Mz = M[0], M[1], M[2]
        for i in range(E):
            i0, i1, i2 = I[i, 0], I[i, 1], I[i, 2]
            # 1. mirror side: an edge end on the previous image's side of the last mirror, and
            # 2. bounding-sphere beam (angle to the mirror's sphere + to the edge's sphere):
            # evaluated over all edges into flags (a loop without branches, which vectorises),
            # then the survivors compacted into `buf`; a pair is counted by the first it fails
            if mirror:
                s = side[i]
                n0, n1, n2, o = s * n[i, 0], s * n[i, 1], s * n[i, 2], s * off[i]  # s = +-1: exact
                for j in range(D):
                    fm[j] = max(n0 * Ax[j] + n1 * Ay[j] + n2 * Az[j], n0 * Bx[j] + n1 * By[j] + n2 * Bz[j]) - o > -plane_tol
            if beam:
                q0, q1, q2 = to_q[i, 0], to_q[i, 1], to_q[i, 2]
                dq = dist_q[i]
                sin_q = min(max(radius_q[i] / max(dq, 1e-300), 0.0), 1.0)
                cos_q = np.sqrt(1.0 - sin_q * sin_q)
                q_inside = dq <= radius_q[i]
                for j in range(D):
                    m0, m1, m2 = Mx[j] - i0, My[j] - i1, Mz[j] - i2
                    dm = np.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
                    cs = (q0 * m0 + q1 * m1 + q2 * m2) / max(dq * dm, 1e-300)
                    sin_m = min(max(h[j] / max(dm, 1e-300), 0.0), 1.0)
                    cos_m = np.sqrt(1.0 - sin_m * sin_m)
                    cos_sum = cos_q * cos_m - sin_q * sin_m
                    sin_sum = sin_q * cos_m + cos_q * sin_m
                    fb[j] = q_inside or dm <= h[j] or cs >= cos_sum - 1e-9 * sin_sum - 1e-12
            pm = 0
            c = 0
            for j in range(D):  # (without a test its flags stay 1)
                pm += fm[j]
                buf[c] = j
                c += fm[j] & fb[j]
            n_mirror += D - pm
            n_beam += pm - c
            # 3. the beams through the mirrors' rectangles (early exit per pair)
            if P > 0:
                c2 = 0
                for k in range(c):
                    j = buf[k]
                    a0, a1, a2 = Ax[j] - i0, Ay[j] - i1, Az[j] - i2
                    b0, b1, b2 = Bx[j] - i0, By[j] - i1, Bz[j] - i2
                    # 1e-9 of the distance to the apex (bounded above by the 1-norm) plus the tolerance
                    far = 1e-9 * max(abs(a0) + abs(a1) + abs(a2), abs(b0) + abs(b1) + abs(b2)) + aperture_tol
                    inside = True
                    for p in range(P):
                        p0, p1, p2 = planes[i, p, 0], planes[i, p, 1], planes[i, p, 2]
                        if max(p0 * a0 + p1 * a1 + p2 * a2, p0 * b0 + p1 * b1 + p2 * b2) < -far:
                            inside = False
                            break
                    buf[c2] = j
                    c2 += inside
                n_aperture += c - c2
                c = c2
            # 4. Keller window, in the edge frame from the image's scene coordinates
            if window:
                r0, r1, r2 = R[i, 0], R[i, 1], R[i, 2]
                c2 = 0
                for k in range(c):
                    j = buf[k]
                    v0, v1, v2 = r0 - origin[0, j], r1 - origin[1, j], r2 - origin[2, j]
                    x = v0 * x_hat[0, j] + v1 * x_hat[1, j] + v2 * x_hat[2, j]
                    y = v0 * y_hat[0, j] + v1 * y_hat[1, j] + v2 * y_hat[2, j]
                    t = v0 * direction[0, j] + v1 * direction[1, j] + v2 * direction[2, j]
                    rho = np.hypot(x, y)
                    buf[c2] = j
                    c2 += (t - v_lo[j] - lo[j] * rho >= -keller_tol) and (t - v_hi[j] - hi[j] * rho <= keller_tol)
                n_window += c - c2
                c = c2
            for k in range(c):
                ok[i, buf[k]] = True
        return n_mirror, n_beam, n_aperture, n_window

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
    aperture: tuple[np.ndarray, float] | None,
    R: np.ndarray,
    frame: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    window: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float] | None,
) -> tuple[np.ndarray, int, int, int, int]:
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
    aperture : (planes (E, P, 3), tol) or None
        The side planes of the beams through the images' mirrors' rectangles
        (:func:`wavepaths.search.beams.quad_side_planes`, inward unit normals through the
        image): a pair passes unless both edge ends lie outside one plane by more than
        ``1e-9`` of their distance to the image plus ``tol`` [m]
        (:func:`wavepaths.search.beams.chain_beams_meet`'s segment test).
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
    rejected_mirror_side, rejected_beam, rejected_aperture, rejected_keller_window : int
        How many pairs each test rejected (each pair counted by the first test it fails, in
        this order).
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
    planes, aperture_tol = aperture if aperture is not None else (np.zeros((E, 0, 3)), 0.0)
    v_lo, lo, v_hi, hi, keller_tol = window if window is not None else (z1, z1, z1, z1, 0.0)
    origin, direction, x_hat, y_hat = frame
    ok = np.zeros((E, D), dtype=np.bool_)
    c = np.ascontiguousarray

    def t(x):  # per-edge arrays transposed, (3, D)
        return np.ascontiguousarray(np.asarray(x).T)

    counts = k(c(I), c(n), c(off), c(side), t(A), t(B), float(plane_tol), mirror is not None,
               c(to_q), c(dist_q), c(radius_q), t(M), c(h), beam is not None, c(planes), float(aperture_tol),
               c(R), t(origin), t(direction), t(x_hat), t(y_hat), c(v_lo), c(lo), c(v_hi), c(hi),
               float(keller_tol), window is not None, ok)
    return ok, int(counts[0]), int(counts[1]), int(counts[2]), int(counts[3])
