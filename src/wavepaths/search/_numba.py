"""The numba kernels behind :mod:`wavepaths.search.kernels` (imported only when numba is installed).

Each function is the compiled twin of a numpy reference named in its comment; the public
wrappers, with the documented shapes and units, are in :mod:`wavepaths.search.kernels`.
"""

import math

import numba
import numpy as np

ROWS = 64  # receiver images per parallel block


@numba.njit(cache=True, nogil=True)
def _receiver_row(i, buf, fm, fb, I, n, off, side, A, B, plane_tol, mirror, to_q, dist_q, radius_q, M, h, beam,
                  planes, aperture_tol, R, origin, direction, x_hat, y_hat, v_lo, lo, v_hi, hi, keller_tol,
                  window, counts):
    # end_sides._receiver_side's tests (numpy reference) for image i against every edge j. A, B,
    # M, origin, direction, x_hat, y_hat come transposed, (3, D): the first two stages run
    # over contiguous rows, branch-free (they vectorise), and the survivors are compacted
    # into `buf`; returns their count c (they are buf[:c]), counts[i] += the rejections by
    # the mirror side, beam, aperture and window
    D = A.shape[1]
    P = planes.shape[1]
    Ax, Ay, Az, Bx, By, Bz = A[0], A[1], A[2], B[0], B[1], B[2]
    Mx, My, Mz = M[0], M[1], M[2]
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
    return c


@numba.njit(cache=True, nogil=True, parallel=True)
def receiver_pairs(I, n, off, side, A, B, plane_tol, mirror, to_q, dist_q, radius_q, M, h, beam,
                   planes, aperture_tol, R, origin, direction, x_hat, y_hat, v_lo, lo, v_hi, hi, keller_tol,
                   window, out_j, cnt, counts):
    # _receiver_row for every image, blocks of ROWS images in parallel
    E = I.shape[0]
    D = A.shape[1]
    for blk in numba.prange((E + ROWS - 1) // ROWS):
        buf = np.empty(D, dtype=np.int64)
        fm = np.ones(D, dtype=np.uint8)
        fb = np.ones(D, dtype=np.uint8)
        for i in range(blk * ROWS, min(E, blk * ROWS + ROWS)):
            c = _receiver_row(i, buf, fm, fb, I, n, off, side, A, B, plane_tol, mirror, to_q, dist_q, radius_q, M, h,
                              beam, planes, aperture_tol, R, origin, direction, x_hat, y_hat, v_lo, lo, v_hi, hi,
                              keller_tol, window, counts)
            out_j[i, :c] = buf[:c]
            cnt[i] = c


@numba.njit(cache=True, nogil=True)
def receiver_pairs_serial(I, n, off, side, A, B, plane_tol, mirror, to_q, dist_q, radius_q, M, h, beam,
                          planes, aperture_tol, R, origin, direction, x_hat, y_hat, v_lo, lo, v_hi, hi, keller_tol,
                          window, out_j, cnt, counts):
    # _receiver_row for every image, on the calling thread (small calls: no thread start-up)
    D = A.shape[1]
    buf = np.empty(D, dtype=np.int64)
    fm = np.ones(D, dtype=np.uint8)
    fb = np.ones(D, dtype=np.uint8)
    for i in range(I.shape[0]):
        c = _receiver_row(i, buf, fm, fb, I, n, off, side, A, B, plane_tol, mirror, to_q, dist_q, radius_q, M, h,
                          beam, planes, aperture_tol, R, origin, direction, x_hat, y_hat, v_lo, lo, v_hi, hi,
                          keller_tol, window, counts)
        out_j[i, :c] = buf[:c]
        cnt[i] = c


@numba.njit(cache=True, nogil=True, inline="always")
def _side_planes(a0, a1, a2, polys, quads, normal, offset, q, out):
    # one chain (mirrors `polys`, last image a): each mirror's rectangle mirrored forward across
    # the later mirrors (apertures.chain_apertures), then the four side planes from the apex
    # (apertures.quad_side_planes: inward unit normals, zero for a degenerate plane) into out (4k, 3)
    k = polys.shape[0]
    for j in range(k):
        p = polys[j]
        for c in range(4):
            for x in range(3):
                q[c, x] = quads[p, c, x]
        for i in range(j + 1, k):
            m = polys[i]
            n0, n1, n2, d = normal[m, 0], normal[m, 1], normal[m, 2], offset[m]
            for c in range(4):
                dist = q[c, 0] * n0 + q[c, 1] * n1 + q[c, 2] * n2 - d
                q[c, 0] -= 2.0 * dist * n0
                q[c, 1] -= 2.0 * dist * n1
                q[c, 2] -= 2.0 * dist * n2
        u0, u1, u2 = q[2, 0] - q[0, 0], q[2, 1] - q[0, 1], q[2, 2] - q[0, 2]
        w0, w1, w2 = q[3, 0] - q[1, 0], q[3, 1] - q[1, 1], q[3, 2] - q[1, 2]
        nq0, nq1, nq2 = u1 * w2 - u2 * w1, u2 * w0 - u0 * w2, u0 * w1 - u1 * w0
        sd = nq0 * (a0 - q[0, 0]) + nq1 * (a1 - q[0, 1]) + nq2 * (a2 - q[0, 2])
        sg = -1.0 if sd > 0 else (1.0 if sd < 0 else 0.0)
        for c in range(4):
            c1 = (c + 1) % 4
            r0, r1, r2 = q[c, 0] - a0, q[c, 1] - a1, q[c, 2] - a2
            s0, s1, s2 = q[c1, 0] - a0, q[c1, 1] - a1, q[c1, 2] - a2
            m0, m1, m2 = r1 * s2 - r2 * s1, r2 * s0 - r0 * s2, r0 * s1 - r1 * s0
            norm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
            f = sg / norm if norm > 0 else 0.0
            out[4 * j + c, 0] = m0 * f
            out[4 * j + c, 1] = m1 * f
            out[4 * j + c, 2] = m2 * f


@numba.njit(cache=True, nogil=True)
def chain_side_planes(apex, polys, quads, normal, offset, out):
    q = np.empty((4, 3))
    for e in range(polys.shape[0]):
        _side_planes(apex[e, 0], apex[e, 1], apex[e, 2], polys[e], quads, normal, offset, q, out[e])


@numba.njit(cache=True, nogil=True, inline="always")
def _beam_meets(a0, a1, a2, p0, p1, p2, pr, c0, c1, c2, cr, slack):
    # spheres.beam_meets_spheres for one pair: the caps of directions subtended from the apex
    # by the two spheres overlap (within `slack` rad), or the apex is inside either sphere
    t0, t1, t2 = p0 - a0, p1 - a1, p2 - a2
    dp = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    u0, u1, u2 = c0 - a0, c1 - a1, c2 - a2
    dq = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    if dp <= pr or dq <= cr:
        return True
    half_p = math.asin(min(max(pr / max(dp, 1e-300), 0.0), 1.0))
    half_q = math.asin(min(max(cr / max(dq, 1e-300), 0.0), 1.0))
    return _angle3(t0, t1, t2, u0, u1, u2) <= half_p + half_q + slack


@numba.njit(cache=True, nogil=True, inline="always")
def _angle3(a0, a1, a2, b0, b1, b2):
    # spheres.vector_angle for one pair: atan2(|a x b|, a . b), accurate near 0 and pi
    c0, c1, c2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
    return math.atan2(math.sqrt(c0 * c0 + c1 * c1 + c2 * c2), a0 * b0 + a1 * b1 + a2 * b2)


@numba.njit(cache=True, nogil=True, inline="always")
def _push_children(stack_l, stack_n, top, lvl, nd, level_off, branch):
    # a SphereTree node's children onto the descent stack (the first child on top); returns the new top
    n_next = level_off[lvl + 2] - level_off[lvl + 1]
    for b in range(branch - 1, -1, -1):
        child = nd * branch + b
        if child < n_next:
            stack_l[top] = lvl + 1
            stack_n[top] = child
            top += 1
    return top


@numba.njit(cache=True, nogil=True, inline="always")
def _append_pair(out_a, out_b, cnt, a, b):
    # append (a, b) to two growing int64 buffers (doubled when full); returns them and the new count
    if cnt == out_a.shape[0]:
        grow_a = np.empty(2 * cnt, np.int64)
        grow_b = np.empty(2 * cnt, np.int64)
        grow_a[:cnt] = out_a[:cnt]
        grow_b[:cnt] = out_b[:cnt]
        out_a, out_b = grow_a, grow_b
    out_a[cnt] = a
    out_b[cnt] = b
    return out_a, out_b, cnt + 1


@numba.njit(cache=True, nogil=True, inline="always")
def _point_in_beam(x0, x1, x2, s, planes, eps):
    # apertures.chain_beams_meet, point form, for one receiver: x is the receiver minus the
    # chain's last image, s its signed distance to the last mirror (positive on the image's
    # side); the receiver must lie beyond the mirror and inside every side plane (`planes`,
    # inward unit normals through the image), with a margin of 1e-9 of its distance to the
    # image plus eps
    far = 1e-9 * math.sqrt(x0 * x0 + x1 * x1 + x2 * x2) + eps
    if not s < far:
        return False
    for p in range(planes.shape[0]):
        if planes[p, 0] * x0 + planes[p, 1] * x1 + planes[p, 2] * x2 < -far:
            return False
    return True


@numba.njit(cache=True, nogil=True)
def reflection_pairs(t_centre, t_radius, members, start, rx, point_test, items, node_c, node_r, through_c,
                     through_r, level_off, leaf_size, branch, node_slack, last_image, polys, cen, rad, quads, normal,
                     offset, eps):
    # beams.beams_reaching (tree descent with the node test, then the per-pair sphere and
    # rectangle tests) and reflection_candidates' per-receiver point test, per target cluster
    depth = level_off.shape[0] - 1
    k = polys.shape[1]
    out_r = np.empty(1024, np.int64)
    out_c = np.empty(1024, np.int64)
    cnt = 0
    stack_l = np.empty(depth * branch + 1, np.int64)
    stack_n = np.empty(depth * branch + 1, np.int64)
    q = np.empty((4, 3))
    planes = np.empty((4 * k, 3))
    n_items = items.shape[0]
    for t in range(t_centre.shape[0]):
        tc0, tc1, tc2, tr = t_centre[t, 0], t_centre[t, 1], t_centre[t, 2], t_radius[t]
        stack_l[0] = 0
        stack_n[0] = 0
        top = 1
        while top > 0:
            top -= 1
            lvl = stack_l[top]
            nd = stack_n[top]
            g = level_off[lvl] + nd
            a0, a1, a2, rho = node_c[g, 0], node_c[g, 1], node_c[g, 2], node_r[g]
            ok = True
            for j in range(k - 1, -1, -1):  # the last mirror first: it prunes most
                if not _beam_meets(a0, a1, a2, through_c[j, g, 0], through_c[j, g, 1], through_c[j, g, 2],
                                   through_r[j, g] + rho, tc0, tc1, tc2, tr + rho, node_slack):
                    ok = False
                    break
            if not ok:
                continue
            if lvl < depth - 1:
                top = _push_children(stack_l, stack_n, top, lvl, nd, level_off, branch)
                continue
            for s in range(nd * leaf_size, min(nd * leaf_size + leaf_size, n_items)):
                c = items[s]
                b0, b1, b2 = last_image[c, 0], last_image[c, 1], last_image[c, 2]
                m = polys[c, k - 1]
                n0, n1, n2, d = normal[m, 0], normal[m, 1], normal[m, 2], offset[m]
                sd = b0 * n0 + b1 * n1 + b2 * n2 - d
                side = 1.0 if sd > 0 else (-1.0 if sd < 0 else 0.0)
                e0, e1, e2 = tc0 - b0, tc1 - b1, tc2 - b2
                far = 1e-9 * math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) + eps
                if not side * (tc0 * n0 + tc1 * n1 + tc2 * n2 - d) < tr + far:
                    continue
                ok = True
                for j in range(k - 1, -1, -1):
                    if not _beam_meets(b0, b1, b2, cen[c, j, 0], cen[c, j, 1], cen[c, j, 2], rad[c, j],
                                       tc0, tc1, tc2, tr, 1e-9):
                        ok = False
                        break
                if not ok:
                    continue
                # the rectangles (apertures.chain_beams_meet, sphere form)
                _side_planes(b0, b1, b2, polys[c], quads, normal, offset, q, planes)
                for p in range(4 * k):
                    if planes[p, 0] * e0 + planes[p, 1] * e1 + planes[p, 2] * e2 < -(tr + far):
                        ok = False
                        break
                if not ok:
                    continue
                # each receiver of the cluster as a point (chain_beams_meet, point form)
                for u in range(start[t], start[t + 1]):
                    r = members[u]
                    if point_test and not _point_in_beam(
                            rx[r, 0] - b0, rx[r, 1] - b1, rx[r, 2] - b2,
                            side * (rx[r, 0] * n0 + rx[r, 1] * n1 + rx[r, 2] * n2 - d), planes, eps):
                        continue
                    out_r, out_c, cnt = _append_pair(out_r, out_c, cnt, r, c)
    return out_r[:cnt], out_c[:cnt]


@numba.njit(cache=True, nogil=True)
def chains_edges(apex, polys, p_centre, p_radius, normal, offset, quads, items, node_c, node_r, level_off, leaf_size,
                 branch, origin, direction, length, eps):
    # beams.chains_meeting_edges for a block of chains: per chain its 1 + 4k bounding planes
    # (beyond the last mirror, then the side planes of the beams through the apertures'
    # rectangles), a descent of the edge tree (a node goes when its sphere lies outside one
    # plane), then per edge the segment test on the same planes and the sphere cones
    m, k = polys.shape
    depth = level_off.shape[0] - 1
    n_items = items.shape[0]
    out_c = np.empty(1024, np.int64)
    out_e = np.empty(1024, np.int64)
    cnt = 0
    stack_l = np.empty(depth * branch + 1, np.int64)
    stack_n = np.empty(depth * branch + 1, np.int64)
    q = np.empty((4, 3))
    side_planes = np.empty((4 * k, 3))
    planes = np.empty((1 + 4 * k, 3))
    shift = np.zeros(1 + 4 * k)
    cen = np.empty((k, 3))
    rad = np.empty(k)
    for ci in range(m):
        a0, a1, a2 = apex[ci, 0], apex[ci, 1], apex[ci, 2]
        # the apertures' spheres mirrored forward across the later mirrors (apertures.chain_apertures)
        for j in range(k):
            pj = polys[ci, j]
            c0, c1, c2 = p_centre[pj, 0], p_centre[pj, 1], p_centre[pj, 2]
            for i in range(j + 1, k):
                mi = polys[ci, i]
                dist = c0 * normal[mi, 0] + c1 * normal[mi, 1] + c2 * normal[mi, 2] - offset[mi]
                c0 -= 2.0 * dist * normal[mi, 0]
                c1 -= 2.0 * dist * normal[mi, 1]
                c2 -= 2.0 * dist * normal[mi, 2]
            cen[j, 0], cen[j, 1], cen[j, 2] = c0, c1, c2
            rad[j] = p_radius[pj]
        last = polys[ci, k - 1]
        n0, n1, n2, d = normal[last, 0], normal[last, 1], normal[last, 2], offset[last]
        sd = a0 * n0 + a1 * n1 + a2 * n2 - d
        side = 1.0 if sd > 0 else (-1.0 if sd < 0 else 0.0)
        planes[0, 0], planes[0, 1], planes[0, 2] = -side * n0, -side * n1, -side * n2
        shift[0] = -abs(sd)
        _side_planes(a0, a1, a2, polys[ci], quads, normal, offset, q, side_planes)
        # the last aperture first, as the numpy query orders them (it prunes most)
        for j in range(k):
            jj = k - 1 - j
            for c in range(4):
                for x in range(3):
                    planes[1 + 4 * j + c, x] = side_planes[4 * jj + c, x]
        top = 1
        stack_l[0] = 0
        stack_n[0] = 0
        while top > 0:
            top -= 1
            lvl = stack_l[top]
            nd = stack_n[top]
            g = level_off[lvl] + nd
            r0, r1, r2 = node_c[g, 0] - a0, node_c[g, 1] - a1, node_c[g, 2] - a2
            far = 1e-9 * math.sqrt(r0 * r0 + r1 * r1 + r2 * r2) + eps
            ok = True
            for p in range(1 + 4 * k):
                if planes[p, 0] * r0 + planes[p, 1] * r1 + planes[p, 2] * r2 + shift[p] < -(node_r[g] + far):
                    ok = False
                    break
            if not ok:
                continue
            if lvl < depth - 1:
                top = _push_children(stack_l, stack_n, top, lvl, nd, level_off, branch)
                continue
            for s in range(nd * leaf_size, min(nd * leaf_size + leaf_size, n_items)):
                e = items[s]
                L = length[e]
                x0, x1, x2 = origin[e, 0] - a0, origin[e, 1] - a1, origin[e, 2] - a2
                y0, y1, y2 = x0 + L * direction[e, 0], x1 + L * direction[e, 1], x2 + L * direction[e, 2]
                far = 1e-9 * max(math.sqrt(x0 * x0 + x1 * x1 + x2 * x2), math.sqrt(y0 * y0 + y1 * y1 + y2 * y2)) + eps
                ok = True
                for p in range(1 + 4 * k):
                    da = planes[p, 0] * x0 + planes[p, 1] * x1 + planes[p, 2] * x2 + shift[p]
                    db = planes[p, 0] * y0 + planes[p, 1] * y1 + planes[p, 2] * y2 + shift[p]
                    if max(da, db) < -far:
                        ok = False
                        break
                if not ok:
                    continue
                half = 0.5 * L
                mid0 = origin[e, 0] + half * direction[e, 0]
                mid1 = origin[e, 1] + half * direction[e, 1]
                mid2 = origin[e, 2] + half * direction[e, 2]
                for j in range(k - 1, -1, -1):
                    if not _beam_meets(a0, a1, a2, cen[j, 0], cen[j, 1], cen[j, 2], rad[j],
                                       mid0, mid1, mid2, half * (1 + 1e-9) + eps, 1e-9):
                        ok = False
                        break
                if not ok:
                    continue
                out_c, out_e, cnt = _append_pair(out_c, out_e, cnt, ci, e)
    return out_c[:cnt], out_e[:cnt]


@numba.njit(cache=True, nogil=True)
def admissible(k, images, polygons, source, chain, q, normal, offset, outward, poly_object, inside, centre, radius,
               tol, first_tol, out):
    # images._admissible (numpy reference) per candidate (parent chain `chain[i]`, mirror `q[i]`),
    # the same expressions in the same order: the parent image off q's plane, closed objects
    # reflect from outside only, and for k >= 2 the half-space of the parent's last mirror p,
    # not p nor coplanar with it, and the bounding-sphere beam from the parent through p
    last = images.shape[1] - 1
    for i in range(chain.shape[0]):
        c = chain[i]
        m = q[i]
        a0, a1, a2 = images[c, last, 0], images[c, last, 1], images[c, last, 2]
        n0, n1, n2 = normal[m, 0], normal[m, 1], normal[m, 2]
        side = a0 * n0 + a1 * n1 + a2 * n2 - offset[m]
        ok = abs(side) > (tol if k >= 2 else first_tol)
        if ok and outward[m] != 0 and not inside[source[c], poly_object[m]]:
            ok = outward[m] * side > 0
        if ok and k >= 2:
            p = polygons[c, polygons.shape[1] - 1]
            if p == m:
                ok = False
            else:
                p0, p1, p2, dp = normal[p, 0], normal[p, 1], normal[p, 2], offset[p]
                b = images[c, last - 1]
                s = b[0] * p0 + b[1] * p1 + b[2] * p2 - dp
                sg = 1.0 if s > 0 else (-1.0 if s < 0 else 0.0)
                cq0, cq1, cq2 = centre[m, 0], centre[m, 1], centre[m, 2]
                h = cq0 * p0 + cq1 * p1 + cq2 * p2 - dp
                same_plane = abs(p0 * n0 + p1 * n1 + p2 * n2) > 1 - 1e-12 and abs(h) <= tol
                ok = sg * h > -radius[m] and not same_plane
                if ok:
                    ok = _beam_meets(a0, a1, a2, centre[p, 0], centre[p, 1], centre[p, 2], radius[p], cq0, cq1, cq2,
                                     radius[m], 1e-9)
        out[i] = ok


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


@numba.njit(cache=True, nogil=True)
def joined_candidates(lo, hi, first, count, r_t, r_rho, r_phi, r_d, s_t, s_rho, s_phi, length, has_vis, v_lo, v_hi,
                      v_open0, v_open1, tau, lit_region, out_r, out_s, out_t, rejected):
    # diffraction._diffraction_prefilter (numpy reference) on the join of diffraction._join_chunks:
    # for each receiver-side row i in [lo, hi), each transmitter-side source j of the same
    # (dihedron, sector), the closed-form point t (geometry.diffraction_point_reduced, the same
    # expression), on the edge segment, not proven hidden (VisibilityWindows.may_see), and,
    # without the lit region, in the shadow (|phi - phi'| > pi); the survivors are written at
    # out_*[:n] (n returned), rejected[0..2] count the off-edge, hidden and lit-region ones
    n = 0
    for i in range(lo, hi):
        tr, dr, ph = r_t[i], r_rho[i], r_phi[i]
        L = length[r_d[i]]
        for j in range(first[i], first[i] + count[i]):
            te, de = s_t[j], s_rho[j]
            den = de + dr
            if den > 0:
                num = te * dr
                num += tr * de
                t = num / den
            else:
                t = 0.5 * (te + tr)
            if not (t >= 0 and t <= L):
                rejected[0] += 1
                continue
            if has_vis:
                if not ((t >= v_lo[j] - tau and t <= v_hi[j] + tau) or (v_open0[j] and t <= tau)
                        or (v_open1[j] and t >= L - tau)):
                    rejected[1] += 1
                    continue
            if not lit_region and not abs(ph - s_phi[j]) > np.pi:
                rejected[2] += 1
                continue
            out_r[n] = i
            out_s[n] = j
            out_t[n] = t
            n += 1
    return n


@numba.njit(cache=True, nogil=True)
def reflection_pairs_flat(rx, last_image, side, mirror, planes, normal, offset, eps, c_lo, c_hi):
    # reflection_pairs' per-receiver point test (_point_in_beam) alone, for every (chain,
    # receiver) pair of chains c_lo .. c_hi - 1 (no tree, no sphere tests), with the side
    # planes of the beams through the chain's mirrors' rectangles precomputed (`planes`,
    # kernels.chain_side_planes). Chain by chain over all receivers, so each chain's planes
    # are read once; the receivers' distances to the last mirror first, in a loop without
    # a branch
    R = rx.shape[0]
    out_r = np.empty(1024, np.int64)
    out_c = np.empty(1024, np.int64)
    cnt = 0
    s_r = np.empty(R)
    for c in range(c_lo, c_hi):
        m = mirror[c]
        sg = side[c]
        n0, n1, n2, d = normal[m, 0], normal[m, 1], normal[m, 2], offset[m]
        b0, b1, b2 = last_image[c, 0], last_image[c, 1], last_image[c, 2]
        for r in range(R):
            s_r[r] = sg * (rx[r, 0] * n0 + rx[r, 1] * n1 + rx[r, 2] * n2 - d)
        pc = planes[c]
        for r in range(R):
            if _point_in_beam(rx[r, 0] - b0, rx[r, 1] - b1, rx[r, 2] - b2, s_r[r], pc, eps):
                out_r, out_c, cnt = _append_pair(out_r, out_c, cnt, r, c)
    return out_r[:cnt], out_c[:cnt]


@numba.njit(cache=True, nogil=True, inline="always")
def _sphere_reach(x0, x1, x2, w0, w1, w2, c, r):
    # diffraction.keller_cone_keep's angle_range at one edge end X: the angle theta between
    # the edge direction and X -> c, and the sphere's angular radius delta seen from X
    v0, v1, v2 = c[0] - x0, c[1] - x1, c[2] - x2
    dist = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    th = _angle3(v0, v1, v2, w0, w1, w2)
    de = math.asin(min(max(r / max(dist, 1e-300), 0.0), 1.0)) if dist > r else math.pi
    return th, de


@numba.njit(cache=True, nogil=True)
def keller_cone_keep(A, B, w, inv, cos_a, cos_b, c, r, slack, keep):
    # diffraction.keller_cone_keep (numpy reference): the sphere's reach from each distinct
    # dihedron's ends, then source by source the cone cosines against it; writes keep,
    # returns the count
    u = A.shape[0]
    reach_a = np.empty(u)
    reach_b = np.empty(u)
    for j in range(u):
        th, de = _sphere_reach(A[j, 0], A[j, 1], A[j, 2], w[j, 0], w[j, 1], w[j, 2], c, r)
        reach_a[j] = math.cos(max(th - de, 0.0)) + slack
        th, de = _sphere_reach(B[j, 0], B[j, 1], B[j, 2], w[j, 0], w[j, 1], w[j, 2], c, r)
        reach_b[j] = math.cos(min(th + de, math.pi)) - slack
    n = 0
    for i in range(inv.shape[0]):
        j = inv[i]
        ok = cos_a[i] <= reach_a[j] and cos_b[i] >= reach_b[j]
        keep[i] = ok
        n += ok
    return n


@numba.njit(cache=True, nogil=True, inline="always")
def _trace_back(y0, y1, y2, images, polygons, c, normal, offset, ptr, polygon_tris, triangles, vertices, dual, eps,
                eps_poly, out, base, step, i, rejected):
    # one candidate of backtrace(): writes reflection j's point at out[i, base + step * j];
    # returns whether the chain is valid (a rejection is counted in rejected[0] or [1])
    k = polygons.shape[1]
    for j in range(k - 1, -1, -1):
        q = polygons[c, j]
        n0, n1, n2, d = normal[q, 0], normal[q, 1], normal[q, 2], offset[q]
        b0, b1, b2 = images[c, j + 1, 0], images[c, j + 1, 1], images[c, j + 1, 2]
        da = y0 * n0 + y1 * n1 + y2 * n2 - d
        db = b0 * n0 + b1 * n1 + b2 * n2 - d
        den = da - db
        t = da / den if abs(den) > 0 else -1.0
        if not (t > eps and t < 1 - eps):
            rejected[0] += 1
            return False
        x0, x1, x2 = y0 + t * (b0 - y0), y1 + t * (b1 - y1), y2 + t * (b2 - y2)
        inside = False
        for s in range(ptr[q], ptr[q + 1]):
            tr = polygon_tris[s]
            o = triangles[tr, 0]
            r0, r1, r2 = x0 - vertices[o, 0], x1 - vertices[o, 1], x2 - vertices[o, 2]
            v = dual[tr, 0, 0] * r0 + dual[tr, 0, 1] * r1 + dual[tr, 0, 2] * r2
            w = dual[tr, 1, 0] * r0 + dual[tr, 1, 1] * r1 + dual[tr, 1, 2] * r2
            if v >= -eps_poly and w >= -eps_poly and v + w <= 1 + eps_poly:
                inside = True
                break
        if not inside:
            rejected[1] += 1
            return False
        p = base + step * j
        out[i, p, 0], out[i, p, 1], out[i, p, 2] = x0, x1, x2
        y0, y1, y2 = x0, x1, x2
    return True


@numba.njit(cache=True, nogil=True)
def backtrace(target, images, polygons, chain, normal, offset, ptr, polygon_tris, triangles, vertices, dual, eps,
              eps_poly, keep, points, rejected):
    # images.backtrace (numpy reference), candidate by candidate with an early exit: from the
    # target back to the source, where the leg toward each image crosses its mirror's plane
    # (geometry.segment_plane_intersection), strictly inside the leg (eps) and inside the
    # mirror polygon (scene._numba.points_in_polygons' test, margin eps_poly); the survivors'
    # input rows go to keep[:n] and their points, in path order, to points[:n] (n returned);
    # rejected[0], [1] count the segment and outside-polygon rejections
    n = 0
    for i in range(chain.shape[0]):
        if _trace_back(target[i, 0], target[i, 1], target[i, 2], images, polygons, chain[i], normal, offset, ptr,
                       polygon_tris, triangles, vertices, dual, eps, eps_poly, points, 0, 1, n, rejected):
            keep[n] = i
            n += 1
    return n


@numba.njit(cache=True, nogil=True)
def diffraction_vertices(rows, src_rows, t, r_row, r_dih, r_sec, r_phi, r_t, r_rho, s_row, s_phi, s_t, s_rho, width,
                         origin, direction, near_tol, rx_images, rx_polygons, rx_source, rx, tx_images, tx_polygons,
                         normal, offset, ptr, polygon_tris, triangles, vertices, dual, eps, eps_poly, near, keep,
                         verts, rejected):
    # diffraction._diffraction_candidates' steps up to the vertices (numpy reference): per
    # candidate, whether it lies within the float32 uncertainty of a shadow or reflection
    # boundary (near, for every input row), the point P on the edge, the back-trace through
    # the receiver images (reflections after P), then through the transmitter images
    # (before P), and the path's vertices [tx, pre..., P, post reversed..., rx] written at
    # verts[n]; keep[:n] the surviving input rows (n returned), rejected as backtrace()
    a = tx_polygons.shape[1]
    b = rx_polygons.shape[1]
    n = 0
    for i in range(rows.shape[0]):
        ri, si, ti = rows[i], src_rows[i], t[i]
        dd = r_dih[ri]
        ph, pp = r_phi[ri], s_phi[si]
        wedge = width[dd, r_sec[ri]]
        a_t, b_t = s_t[si] - ti, r_t[ri] - ti
        leg = math.sqrt(min(a_t * a_t + s_rho[si] * s_rho[si], b_t * b_t + r_rho[ri] * r_rho[ri]))
        offs = min(abs(abs(ph - pp) - np.pi), abs(ph + pp - np.pi))
        offs = min(offs, abs(ph + pp - (2 * wedge - np.pi)))
        near[i] = offs * leg < near_tol
        p0 = origin[dd, 0] + ti * direction[dd, 0]
        p1 = origin[dd, 1] + ti * direction[dd, 1]
        p2 = origin[dd, 2] + ti * direction[dd, 2]
        e = r_row[ri]
        # reflections after P, the receiver chain's order: point j of the chain goes to a + 1 + b - j
        if not _trace_back(p0, p1, p2, rx_images, rx_polygons, e, normal, offset, ptr, polygon_tris, triangles,
                           vertices, dual, eps, eps_poly, verts, a + 1 + b, -1, n, rejected):
            continue
        if not _trace_back(p0, p1, p2, tx_images, tx_polygons, s_row[si], normal, offset, ptr, polygon_tris,
                           triangles, vertices, dual, eps, eps_poly, verts, 1, 1, n, rejected):
            continue
        c = s_row[si]
        for x in range(3):
            verts[n, 0, x] = tx_images[c, 0, x]
        verts[n, a + 1, 0], verts[n, a + 1, 1], verts[n, a + 1, 2] = p0, p1, p2
        r = rx_source[e]
        for x in range(3):
            verts[n, a + b + 2, x] = rx[r, x]
        keep[n] = i
        n += 1
    return n


@numba.njit(cache=True, nogil=True)
def degenerate_chains(vertices, weld, plane_tol):
    """(k,) bool: :func:`wavepaths.search.chains.occluded_chains`' degenerate chains, one pass.

    A segment joining two interactions no longer than ``weld``, or (for chains with at least
    one interaction) a first or last segment no longer than ``plane_tol``; the same lengths
    (``sqrt`` of the summed squared differences) and comparisons as the numpy form.
    """
    k, s = vertices.shape[0], vertices.shape[1]
    out = np.zeros(k, dtype=np.bool_)
    for i in range(k):
        for j in range(s - 1):
            inner = 0 < j < s - 2
            end = s > 2 and (j == 0 or j == s - 2)
            if not (inner or end):
                continue
            d0 = vertices[i, j + 1, 0] - vertices[i, j, 0]
            d1 = vertices[i, j + 1, 1] - vertices[i, j, 1]
            d2 = vertices[i, j + 1, 2] - vertices[i, j, 2]
            length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if (inner and length <= weld) or (end and length <= plane_tol):
                out[i] = True
                break
    return out


@numba.njit(cache=True, nogil=True, inline="always")
def _counting_sort(key, n_keys):
    """A stable counting sort of ``key`` (``0 <= key < n_keys``): ``(start, order)``, the rows of
    key ``b`` being ``order[start[b]:start[b + 1]]`` in their original order."""
    n = key.size
    start = np.zeros(n_keys + 1, np.int64)
    for i in range(n):
        start[key[i] + 1] += 1
    for b in range(n_keys):
        start[b + 1] += start[b]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        b = key[i]
        order[fill[b]] = i
        fill[b] += 1
    return start, order


@numba.njit(cache=True, nogil=True)
def key_length_order(key, lengths, n_keys):
    """``np.lexsort((lengths, key))`` for ``0 <= key < n_keys``: a stable counting sort on
    ``key``, then each key's rows by length (insertion sort, stable; numba's merge sort,
    stable too, for a key holding more than 32 rows). Returns ``(order, tie)``: ``tie`` is True when two
    rows share both key and length (the caller then sorts on the whole key).
    Lengths must not be NaN (the caller checks)."""
    start, order = _counting_sort(key, n_keys)
    tie = False
    for b in range(n_keys):
        lo, hi = start[b], start[b + 1]
        if hi - lo > 32:
            part = order[lo:hi].copy()
            sub = np.argsort(lengths[part], kind="mergesort")
            for j in range(hi - lo):
                order[lo + j] = part[sub[j]]
        else:
            for j in range(lo + 1, hi):
                v = order[j]
                x = lengths[v]
                m = j - 1
                while m >= lo and lengths[order[m]] > x:
                    order[m + 1] = order[m]
                    m -= 1
                order[m + 1] = v
        for j in range(lo + 1, hi):
            if lengths[order[j]] == lengths[order[j - 1]]:
                tie = True
    return order, tie
