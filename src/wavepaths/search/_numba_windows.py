"""The numba twins of the window loops of :mod:`wavepaths.search.visibility` and
:mod:`wavepaths.search.aperture_windows` (imported only when numba is installed; the numpy
functions named in each comment are the references)."""

import math

import numba
import numpy as np


@numba.njit(cache=True, nogil=True, inline="always")
def _half_line(alpha, beta, lo, hi):
    # the t with alpha + beta t >= 0 intersected with [lo, hi]; bad: no t at all (beta = 0)
    if beta > 0:
        return max(lo, -alpha / beta), hi, False
    if beta < 0:
        return lo, min(hi, -alpha / beta), False
    return lo, hi, alpha < 0


@numba.njit(cache=True, nogil=True)
def windows_through(ptr, N, O, eps, valid, whole, I, center, image, d, origin, direction, length, tau, lo, hi):
    # aperture_windows.windows_through (numpy reference), pair by pair: for pair i (image row
    # image[i] of the planes, dihedron d[i]) the hull over the image's mirror triangles of the
    # t in [0, L] meeting their four half-spaces alpha + beta t >= 0, widened by tau
    for i in range(len(d)):
        g, e = image[i], d[i]
        L = length[e]
        if whole[g]:
            lo[i] = 0.0
            hi[i] = L
            continue
        a0, a1, a2 = origin[e, 0] - center[0], origin[e, 1] - center[1], origin[e, 2] - center[2]
        w0, w1, w2 = direction[e, 0], direction[e, 1], direction[e, 2]
        b0, b1, b2 = a0 + L * w0, a1 + L * w1, a2 + L * w2
        i0, i1, i2 = I[g, 0], I[g, 1], I[g, 2]
        D = max(math.sqrt((a0 - i0) ** 2 + (a1 - i1) ** 2 + (a2 - i2) ** 2),
                math.sqrt((b0 - i0) ** 2 + (b1 - i1) ** 2 + (b2 - i2) ** 2))
        w_lo, w_hi = np.inf, -np.inf
        for r in range(ptr[g], ptr[g + 1]):
            if not valid[r]:
                continue
            t_lo, t_hi = 0.0, L
            bad = False
            for k in range(4):
                alpha = N[r, k, 0] * a0 + N[r, k, 1] * a1 + N[r, k, 2] * a2 + O[r, k]
                if k > 0:
                    alpha -= eps[r] * D
                beta = N[r, k, 0] * w0 + N[r, k, 1] * w1 + N[r, k, 2] * w2
                t_lo, t_hi, none = _half_line(alpha, beta, t_lo, t_hi)
                bad |= none
            if bad:
                continue
            w_lo = min(w_lo, t_lo)
            w_hi = max(w_hi, t_hi)
        lo[i] = max(w_lo - tau, 0.0)
        hi[i] = min(w_hi + tau, L)
    return lo, hi


@numba.njit(cache=True, nogil=True)
def shadow_intervals(corners, normal, offset, tol, edge_tol, S, tri, A, w, L, s_lo, s_hi, n_lo, n_hi):
    # visibility.shadow_intervals (numpy reference) in both modes at once, pair by pair:
    # (s_lo, s_hi) the proven interval, (n_lo, n_hi) the nominal one (no margin inside the
    # sides); empty intervals are (inf, -inf)
    for i in range(len(tri)):
        f = tri[i]
        n0, n1, n2, off, tl = normal[f, 0], normal[f, 1], normal[f, 2], offset[f], tol[f]
        x0, x1, x2 = S[i, 0], S[i, 1], S[i, 2]
        a0, a1, a2 = A[i, 0], A[i, 1], A[i, 2]
        w0, w1, w2 = w[i, 0], w[i, 1], w[i, 2]
        Li = L[i]
        s_s = n0 * x0 + n1 * x1 + n2 * x2 - off
        sigma = 1.0 if s_s > 0 else (-1.0 if s_s < 0 else 0.0)
        valid = abs(s_s) > 4 * tl
        b0, b1, b2 = a0 + Li * w0, a1 + Li * w1, a2 + Li * w2
        dmax = max(math.sqrt((a0 - x0) ** 2 + (a1 - x1) ** 2 + (a2 - x2) ** 2),
                   math.sqrt((b0 - x0) ** 2 + (b1 - x1) ** 2 + (b2 - x2) ** 2))
        eps = max(1e-9, 2 * (tl + edge_tol) / abs(s_s)) if s_s != 0 else np.inf
        # the plane's half-line, shared by both modes
        alpha0 = -sigma * (n0 * a0 + n1 * a1 + n2 * a2 - off) - 2 * tl
        beta0 = -sigma * (n0 * w0 + n1 * w1 + n2 * w2)
        p_lo, p_hi, bad_p = _half_line(alpha0, beta0, 0.0, Li)
        q_lo, q_hi, bad_q = p_lo, p_hi, bad_p
        for s in range(3):
            u, v, z = s, (s + 1) % 3, (s + 2) % 3
            c0, c1, c2 = corners[f, u, 0] - x0, corners[f, u, 1] - x1, corners[f, u, 2] - x2
            d0, d1, d2 = corners[f, v, 0] - x0, corners[f, v, 1] - x1, corners[f, v, 2] - x2
            m0, m1, m2 = c1 * d2 - c2 * d1, c2 * d0 - c0 * d2, c0 * d1 - c1 * d0
            norm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
            if norm > 0:
                m0, m1, m2 = m0 / norm, m1 / norm, m2 / norm
            k0, k1, k2 = corners[f, z, 0] - x0, corners[f, z, 1] - x1, corners[f, z, 2] - x2
            o = m0 * k0 + m1 * k1 + m2 * k2
            orient = 1.0 if o > 0 else (-1.0 if o < 0 else 0.0)
            if not (norm > 0 and orient != 0):
                valid = False
            m0, m1, m2 = orient * m0, orient * m1, orient * m2
            base = m0 * (a0 - x0) + m1 * (a1 - x1) + m2 * (a2 - x2)
            beta = m0 * w0 + m1 * w1 + m2 * w2
            p_lo, p_hi, none_p = _half_line(base - eps * dmax, beta, p_lo, p_hi)
            q_lo, q_hi, none_q = _half_line(base, beta, q_lo, q_hi)  # nominal: no margin inside the sides
            bad_p |= none_p
            bad_q |= none_q
        ok_p = valid and not bad_p and math.isfinite(p_lo) and math.isfinite(p_hi)
        ok_q = valid and not bad_q and math.isfinite(q_lo) and math.isfinite(q_hi)
        s_lo[i] = p_lo if ok_p else np.inf
        s_hi[i] = p_hi if ok_p else -np.inf
        n_lo[i] = q_lo if ok_q else np.inf
        n_hi[i] = q_hi if ok_q else -np.inf
