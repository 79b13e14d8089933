"""The numba twins of the per-mirror reach lists (:func:`wavepaths.search.reach.mirror_reach`)
and of the receiver side restricted to them (:func:`wavepaths.search.end_sides._receiver_side`
with ``reach``), imported only when numba is installed; the numpy functions named in each
comment are the references."""

import math

import numba
import numpy as np

from ._numba import ROWS, _receiver_rows


@numba.njit(cache=True, nogil=True, inline="always")
def _reach_cosines(x0, x1, x2, w0, w1, w2, c0, c1, c2, r, slack):
    # reach._reach_cosines at one edge end X: cos(max(theta - delta, 0)) + slack and
    # cos(min(theta + delta, pi)) - slack, theta = angle(w, c - X), delta = the sphere's
    # angular radius from X (pi from inside it); the cosines of sums, no inverse functions
    v0, v1, v2 = c0 - x0, c1 - x1, c2 - x2
    dist = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    if dist <= r:
        return 1.0 + slack, -1.0 - slack
    ct = min(max((v0 * w0 + v1 * w1 + v2 * w2) / dist, -1.0), 1.0)
    st = math.sqrt(max(1.0 - ct * ct, 0.0))
    sd = r / dist
    cd = math.sqrt(max(1.0 - sd * sd, 0.0))
    lo = 1.0 if ct >= cd else ct * cd + st * sd
    hi = -1.0 if ct <= -cd else ct * cd - st * sd
    return lo + slack, hi - slack


@numba.njit(cache=True, nogil=True, inline="always")
def _polygon_reach(p, A, B, w, inv, cos_a, cos_b, centre, radius, slack, reach_a, reach_b, mark):
    # reach.mirror_reach for one polygon p: marks the distinct dihedra (rows of A) with a
    # source whose cone reaches p's sphere; returns how many
    u = A.shape[0]
    c0, c1, c2, r = centre[p, 0], centre[p, 1], centre[p, 2], radius[p]
    for j in range(u):
        reach_a[j], _ = _reach_cosines(A[j, 0], A[j, 1], A[j, 2], w[j, 0], w[j, 1], w[j, 2], c0, c1, c2, r, slack)
        _, reach_b[j] = _reach_cosines(B[j, 0], B[j, 1], B[j, 2], w[j, 0], w[j, 1], w[j, 2], c0, c1, c2, r, slack)
        mark[j] = 0
    n = 0
    for i in range(inv.shape[0]):
        j = inv[i]
        if mark[j] == 0 and cos_a[i] <= reach_a[j] and cos_b[i] >= reach_b[j]:
            mark[j] = 1
            n += 1
    return n


@numba.njit(cache=True, nogil=True, parallel=True)
def mirror_reach_counts(A, B, w, inv, cos_a, cos_b, centre, radius, slack, counts):
    # pass 1 of reach.mirror_reach: the length of every polygon's list
    u = A.shape[0]
    P = centre.shape[0]
    for blk in numba.prange((P + ROWS - 1) // ROWS):
        reach_a, reach_b, mark = np.empty(u), np.empty(u), np.empty(u, np.uint8)
        for p in range(blk * ROWS, min(P, blk * ROWS + ROWS)):
            counts[p] = _polygon_reach(p, A, B, w, inv, cos_a, cos_b, centre, radius, slack, reach_a, reach_b, mark)


@numba.njit(cache=True, nogil=True, parallel=True)
def mirror_reach_fill(A, B, w, inv, cos_a, cos_b, centre, radius, slack, dihedra, ptr, out):
    # pass 2: every polygon's dihedra (ascending, as `dihedra` is) at out[ptr[p]:ptr[p + 1]]
    u = A.shape[0]
    P = centre.shape[0]
    for blk in numba.prange((P + ROWS - 1) // ROWS):
        reach_a, reach_b, mark = np.empty(u), np.empty(u), np.empty(u, np.uint8)
        for p in range(blk * ROWS, min(P, blk * ROWS + ROWS)):
            _polygon_reach(p, A, B, w, inv, cos_a, cos_b, centre, radius, slack, reach_a, reach_b, mark)
            k = ptr[p]
            for j in range(u):
                if mark[j]:
                    out[k] = dihedra[j]
                    k += 1


@numba.njit(cache=True, nogil=True)
def _group(g, order, gstart, gq, I, n, off, side, A, B, plane_tol, mirror, to_q, dist_q, radius_q, M, h, beam, planes,
           aperture_tol, R, origin, direction, x_hat, y_hat, v_lo, lo, v_hi, hi, keller_tol, window, ptr, idx, col_of,
           start, out_j, cnt, counts):
    # the images order[gstart[g]:gstart[g + 1]], which share their last mirror gq[g] and the
    # side of their previous images: the edges of the mirror's reach list that are among the
    # chunk's columns, and (with `mirror`) on that side, the mirror-side test of
    # _numba._receiver_rows once per edge for the whole group (its expression, with the first
    # image's plane, which every image of the group shares), are gathered into contiguous
    # arrays; then _receiver_rows runs over them, image by image (the other tests, in the same
    # order, vectorised); the survivors, mapped back to the chunk's columns, end at
    # out_j[start[i]:start[i] + cnt[i]], and counts[i, 4] += the listed pairs
    q = gq[g]
    i0 = order[gstart[g]]
    s = side[i0]
    n0, n1, n2, o = s * n[i0, 0], s * n[i0, 1], s * n[i0, 2], s * off[i0]  # s = +-1: exact
    cols = np.empty(ptr[q + 1] - ptr[q], np.int64)
    m = 0
    listed = 0
    for k in range(ptr[q], ptr[q + 1]):
        j = col_of[idx[k]]
        if j < 0:
            continue
        listed += 1
        if mirror and not (max(n0 * A[0, j] + n1 * A[1, j] + n2 * A[2, j],
                               n0 * B[0, j] + n1 * B[1, j] + n2 * B[2, j]) - o > -plane_tol):
            continue
        cols[m] = j
        m += 1
    Ag, Bg, Mg = np.empty((3, m)), np.empty((3, m)), np.empty((3, m))
    og, dg, xg, yg = np.empty((3, m)), np.empty((3, m)), np.empty((3, m)), np.empty((3, m))
    hg, vlo_g, lo_g, vhi_g, hi_g = np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m)
    for k in range(m):
        j = cols[k]
        for x in range(3):
            Ag[x, k] = A[x, j]
            Bg[x, k] = B[x, j]
            Mg[x, k] = M[x, j]
            og[x, k] = origin[x, j]
            dg[x, k] = direction[x, j]
            xg[x, k] = x_hat[x, j]
            yg[x, k] = y_hat[x, j]
        hg[k] = h[j]
        vlo_g[k] = v_lo[j]
        lo_g[k] = lo[j]
        vhi_g[k] = v_hi[j]
        hi_g[k] = hi[j]
    buf = np.empty(m, np.int64)
    fm = np.ones(m, np.uint8)
    fb = np.ones(m, np.uint8)
    _receiver_rows(order, gstart[g], gstart[g + 1], buf, fm, fb, I, n, off, side, Ag, Bg, plane_tol, False, to_q,
                   dist_q, radius_q, Mg, hg, beam, planes, aperture_tol, R, og, dg, xg, yg, vlo_g, lo_g, vhi_g, hi_g,
                   keller_tol, window, counts, cnt, np.empty((0, 0), np.int64), out_j, start, cols, listed)


@numba.njit(cache=True, nogil=True, parallel=True)
def receiver_pairs_listed(I, n, off, side, A, B, plane_tol, mirror, to_q, dist_q, radius_q, M, h, beam, planes,
                          aperture_tol, R, origin, direction, x_hat, y_hat, v_lo, lo, v_hi, hi, keller_tol, window,
                          order, gstart, gq, ptr, idx, col_of, start, out_j, cnt, counts):
    # _group for every group of images with one last mirror, groups in parallel
    for g in numba.prange(gq.shape[0]):
        _group(g, order, gstart, gq, I, n, off, side, A, B, plane_tol, mirror, to_q, dist_q, radius_q, M, h, beam,
               planes, aperture_tol, R, origin, direction, x_hat, y_hat, v_lo, lo, v_hi, hi, keller_tol, window, ptr,
               idx, col_of, start, out_j, cnt, counts)


@numba.njit(cache=True, nogil=True)
def receiver_pairs_listed_serial(I, n, off, side, A, B, plane_tol, mirror, to_q, dist_q, radius_q, M, h, beam,
                                 planes, aperture_tol, R, origin, direction, x_hat, y_hat, v_lo, lo, v_hi, hi,
                                 keller_tol, window, order, gstart, gq, ptr, idx, col_of, start, out_j, cnt, counts):
    for g in range(gq.shape[0]):
        _group(g, order, gstart, gq, I, n, off, side, A, B, plane_tol, mirror, to_q, dist_q, radius_q, M, h, beam,
               planes, aperture_tol, R, origin, direction, x_hat, y_hat, v_lo, lo, v_hi, hi, keller_tol, window, ptr,
               idx, col_of, start, out_j, cnt, counts)
