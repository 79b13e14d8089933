"""The numba twins of :mod:`wavepaths.search.diffraction`'s candidate search: the join of
the two end sides with the closed-form diffraction point (seed §2.3) and the prefilter
(``diffraction._diffraction_prefilter``), the Keller-cone culling of the sources
(``diffraction.keller_cone_keep``), and the candidates' boundary flags, points on the
edges, back-traces and vertices (``diffraction._diffraction_candidates_numpy``). Imported
only when numba is installed; the numpy functions named in each comment are the
references."""

import math

import numba
import numpy as np

from ._numba_beams import _angle3
from ._numba_images import _trace_back


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
