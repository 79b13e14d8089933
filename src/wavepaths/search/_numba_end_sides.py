"""The numba twins of :mod:`wavepaths.search.end_sides`: the receiver side's (receiver
image, dihedron) pair tests (:func:`wavepaths.search.end_sides._receiver_side`: the last
mirror's side, the bounding-sphere beam, the beams through the mirrors' rectangles, the
Keller window) and the frame and sector lookup of the end sides' pairs
(``end_sides._kept_pairs_end_side``, also run for the transmitter side by
:mod:`wavepaths.search.context`). Imported only when numba is installed; the numpy
functions named in each comment are the references."""

import math

import numba
import numpy as np

ROWS = 64  # receiver images per parallel block


@numba.njit(cache=True, nogil=True)
def _receiver_rows(order, r_lo, r_hi, buf, fm, fb, I, n, off, side, A, B, plane_tol, mirror, to_q, dist_q, radius_q, M,
                   h, beam, planes, aperture_tol, R, origin, direction, x_hat, y_hat, v_lo, lo, v_hi, hi, keller_tol,
                   window, counts, cnt, out_j, out_flat, start, cols, listed):
    # end_sides._receiver_side's tests (numpy reference) for the images i = order[r_lo:r_hi] against
    # every edge j. A, B, M, origin, direction, x_hat, y_hat come transposed, (3, D): the first
    # two stages run over contiguous rows, branch-free (they vectorise), and the survivors are
    # compacted into `buf`, their count c into cnt[i]; counts[i] += the rejections by the mirror
    # side, beam, aperture and window. The survivors go to out_j[i, :c] (listed < 0; out_flat,
    # start and cols unused), or for a group of _numba_reach._group (listed >= 0, out_j unused)
    # to out_flat[start[i]:start[i] + c] as cols[buf[:c]], with counts[i, 0] += listed - D and
    # counts[i, 4] += listed. The images are looped over
    # here, not by the callers: each array passed to a compiled call is reference-counted (two
    # atomic operations) at every call, some 80 per image with these arguments
    D = A.shape[1]
    P = planes.shape[1]
    Ax, Ay, Az, Bx, By, Bz = A[0], A[1], A[2], B[0], B[1], B[2]
    Mx, My, Mz = M[0], M[1], M[2]
    for r in range(r_lo, r_hi):
        i = order[r]
        cm = counts[i]
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
        cm[0] += D - pm
        cm[1] += pm - c
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
            cm[2] += c - c2
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
                rho = math.sqrt(x * x + y * y)
                buf[c2] = j
                c2 += (t - v_lo[j] - lo[j] * rho >= -keller_tol) and (t - v_hi[j] - hi[j] * rho <= keller_tol)
            cm[3] += c - c2
            c = c2
        if listed < 0:
            out_j[i, :c] = buf[:c]
        else:
            base = start[i]
            for k in range(c):
                out_flat[base + k] = cols[buf[k]]
            counts[i, 0] += listed - D
            counts[i, 4] += listed
        cnt[i] = c


@numba.njit(cache=True, nogil=True, parallel=True)
def receiver_pairs(I, n, off, side, A, B, plane_tol, mirror, to_q, dist_q, radius_q, M, h, beam,
                   planes, aperture_tol, R, origin, direction, x_hat, y_hat, v_lo, lo, v_hi, hi, keller_tol,
                   window, out_j, cnt, counts):
    # _receiver_rows for every image, blocks of ROWS images in parallel
    E = I.shape[0]
    D = A.shape[1]
    order = np.arange(E)
    for blk in numba.prange((E + ROWS - 1) // ROWS):
        buf = np.empty(D, dtype=np.int64)
        fm = np.ones(D, dtype=np.uint8)
        fb = np.ones(D, dtype=np.uint8)
        _receiver_rows(order, blk * ROWS, min(E, blk * ROWS + ROWS), buf, fm, fb, I, n, off, side, A, B, plane_tol,
                       mirror, to_q, dist_q, radius_q, M, h, beam, planes, aperture_tol, R, origin, direction, x_hat,
                       y_hat, v_lo, lo, v_hi, hi, keller_tol, window, counts, cnt, out_j, np.empty(0, np.int64), cnt, cnt, -1)


@numba.njit(cache=True, nogil=True)
def receiver_pairs_serial(I, n, off, side, A, B, plane_tol, mirror, to_q, dist_q, radius_q, M, h, beam,
                          planes, aperture_tol, R, origin, direction, x_hat, y_hat, v_lo, lo, v_hi, hi, keller_tol,
                          window, out_j, cnt, counts):
    # _receiver_rows for every image, on the calling thread (small calls: no thread start-up)
    D = A.shape[1]
    buf = np.empty(D, dtype=np.int64)
    fm = np.ones(D, dtype=np.uint8)
    fb = np.ones(D, dtype=np.uint8)
    _receiver_rows(np.arange(I.shape[0]), 0, I.shape[0], buf, fm, fb, I, n, off, side, A, B, plane_tol, mirror, to_q,
                   dist_q, radius_q, M, h, beam, planes, aperture_tol, R, origin, direction, x_hat, y_hat, v_lo, lo,
                   v_hi, hi, keller_tol, window, counts, cnt, out_j, np.empty(0, np.int64), cnt, cnt, -1)


@numba.njit(cache=True, nogil=True)
def end_sides(images, rows, d, origin, direction, x_hat, y_hat, angles, count, width_tab, face_tol, min_width,
              keep, sec_o, phi_o, t_o, rho_o):
    # end_sides._kept_pairs_end_side without a window (numpy reference: end_sides._edge_frame, then
    # topology.sectors.sector_lookup, then the width test), per pair (image row rows[i], edge
    # d[i]): the image's last point in the edge's frame, its sector and angle in it; the
    # pairs not on a face and in a sector wider than `min_width` are written at keep[:n],
    # with their sector, angle, t and rho; returns n
    last = images.shape[1] - 1
    m = angles.shape[1]
    n = 0
    two_pi = 2 * np.pi
    for i in range(rows.shape[0]):
        r = rows[i]
        j = d[i]
        v0 = images[r, last, 0] - origin[j, 0]
        v1 = images[r, last, 1] - origin[j, 1]
        v2 = images[r, last, 2] - origin[j, 2]
        x = v0 * x_hat[j, 0] + v1 * x_hat[j, 1] + v2 * x_hat[j, 2]
        y = v0 * y_hat[j, 0] + v1 * y_hat[j, 1] + v2 * y_hat[j, 2]
        t = v0 * direction[j, 0] + v1 * direction[j, 1] + v2 * direction[j, 2]
        theta = np.arctan2(y, x)
        if theta < 0:
            theta += two_pi
        below = 0
        for s in range(m):
            below += angles[j, s] <= theta
        sec = (below - 1) % count[j]
        width = width_tab[j, sec]
        phi = theta - angles[j, sec]
        if phi < 0:
            phi += two_pi
        if phi < face_tol or width - phi < face_tol or (x == 0 and y == 0) or not width > min_width:
            continue
        keep[n] = i
        sec_o[n] = sec
        phi_o[n] = phi
        t_o[n] = t
        rho_o[n] = math.sqrt(x * x + y * y)
        n += 1
    return n
