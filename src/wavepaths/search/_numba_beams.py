"""The numba twins of the beam queries of :mod:`wavepaths.search.beams` and
:mod:`wavepaths.search.apertures`: the side planes of the beams through a chain's mirrors'
rectangles (``apertures.chain_apertures`` then ``apertures.quad_side_planes``), the
reflection candidates per receiver cluster (tree descent) or per (chain, receiver) pair
(``beams.beams_reaching`` and the per-receiver point test), and the chains meeting the
edges (``beams.chains_meeting_edges``), with the sphere-cap test of
:mod:`wavepaths.search.spheres` they share. Imported only when numba is installed; the
numpy functions named in each comment are the references."""

import math

import numba
import numpy as np


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
