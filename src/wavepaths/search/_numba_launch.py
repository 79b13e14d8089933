"""Compiled kernels of :mod:`wavepaths.search.launch` (numba)."""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def _segment_points(k, start, end, r0, r1, s0, s1, across, points, lo, h, dims, bstart, order, out_pt,
                    write):  # pragma: no cover
    """Points of segment k's tube, each once: the segment is cut into slices of length ``h``;
    a slice owns the points whose closest parameter falls in it and finds them among the
    grid buckets within its largest radius plus ``h`` of its middle. Writes them to
    ``out_pt`` when ``write`` (from index 0); returns how many.

    The tube's cross-section is an ellipse: semi-axis ``r`` (r0 to r1) along the unit
    vector ``across[k]`` and ``s`` (s0 to s1) along the other direction normal to the
    segment; ``across[k] = 0`` and ``s = r`` give a round tube. A point at offset ``q``
    from its closest point is in when ``|q| <= max(r, s)`` and
    ``c / r^2 + (|q|^2 - c) / s^2 <= 1`` with ``c = (q . a)^2 + (q . d)^2`` (``d`` the
    segment's unit direction: past a clamped end, the cap is as long as ``r``)."""
    sx, sy, sz = start[k, 0], start[k, 1], start[k, 2]
    dx, dy, dz = end[k, 0] - sx, end[k, 1] - sy, end[k, 2] - sz
    L2 = dx * dx + dy * dy + dz * dz
    L = np.sqrt(L2)
    ax_, ay_, az_ = across[k, 0], across[k, 1], across[k, 2]
    # an elliptic tube: the unit direction n and b = n x a, for the slices' boxes
    elliptic = ax_ * ax_ + ay_ * ay_ + az_ * az_ > 0.25 and L > 0.0
    nx_, ny_, nz_ = (dx / L, dy / L, dz / L) if L > 0.0 else (0.0, 0.0, 0.0)
    bx_ = ny_ * az_ - nz_ * ay_
    by_ = nz_ * ax_ - nx_ * az_
    bz_ = nx_ * ay_ - ny_ * ax_
    rmax = max(max(r0[k], r1[k]), max(s0[k], s1[k]))
    # clip [0, 1] to the points' box grown by rmax (slabs)
    u0, u1 = 0.0, 1.0
    hi0 = lo[0] + dims[0] * h
    hi1 = lo[1] + dims[1] * h
    hi2 = lo[2] + dims[2] * h
    for ax in range(3):
        s = sx if ax == 0 else (sy if ax == 1 else sz)
        d = dx if ax == 0 else (dy if ax == 1 else dz)
        a = lo[ax] - rmax
        b = (hi0 if ax == 0 else (hi1 if ax == 1 else hi2)) + rmax
        if d == 0.0:
            if s < a or s > b:
                return 0
        else:
            ta = (a - s) / d
            tb = (b - s) / d
            if ta > tb:
                ta, tb = tb, ta
            u0 = max(u0, ta)
            u1 = min(u1, tb)
    if u0 > u1:
        return 0
    n = 0
    # slices of about h, no more than the grid is wide (longer slices query wider spheres:
    # still every point once, only slower; a grid of one bucket needs one slice)
    nslice = max(1, min(int(np.ceil((u1 - u0) * L / h)), 2 * (dims[0] + dims[1] + dims[2]) + 2))
    du = (u1 - u0) / nslice
    for j in range(nslice):
        ua = u0 + j * du
        ub = u0 + (j + 1) * du
        um = 0.5 * (ua + ub)
        mx, my, mz = sx + um * dx, sy + um * dy, sz + um * dz
        rm = max(r0[k] + ua * (r1[k] - r0[k]), r0[k] + ub * (r1[k] - r0[k]))
        sm = max(s0[k] + ua * (s1[k] - s0[k]), s0[k] + ub * (s1[k] - s0[k]))
        if elliptic:
            # the box of the slice's piece of elliptic cylinder (semi-axes rm along a, sm along
            # b) and, at the segment's ends, of its cap (rm along the segment too): per axis
            # half the slice's length along it plus the ellipse's (or ellipsoid's) half extent
            cap = rm if (j == 0 or j == nslice - 1) else 0.0
            grow = 1.0 + 1e-5  # float32 frames are unit and normal to 1e-7
            hx = 0.5 * du * abs(dx) + np.sqrt((rm * ax_) ** 2 + (sm * bx_) ** 2 + (cap * nx_) ** 2) * grow + 1e-9
            hy = 0.5 * du * abs(dy) + np.sqrt((rm * ay_) ** 2 + (sm * by_) ** 2 + (cap * ny_) ** 2) * grow + 1e-9
            hz = 0.5 * du * abs(dz) + np.sqrt((rm * az_) ** 2 + (sm * bz_) ** 2 + (cap * nz_) ** 2) * grow + 1e-9
        else:
            hx = max(rm, sm) + 0.5 * du * L + 1e-9
            hy = hx
            hz = hx
        i0 = max(0, int(np.floor((mx - hx - lo[0]) / h)))
        i1 = min(dims[0] - 1, int(np.floor((mx + hx - lo[0]) / h)))
        j0 = max(0, int(np.floor((my - hy - lo[1]) / h)))
        j1 = min(dims[1] - 1, int(np.floor((my + hy - lo[1]) / h)))
        k0 = max(0, int(np.floor((mz - hz - lo[2]) / h)))
        k1 = min(dims[2] - 1, int(np.floor((mz + hz - lo[2]) / h)))
        for iz in range(k0, k1 + 1):
            for iy in range(j0, j1 + 1):
                for ix in range(i0, i1 + 1):
                    cell = ix + dims[0] * (iy + dims[1] * iz)
                    for q in range(bstart[cell], bstart[cell + 1]):
                        p = order[q]
                        px = points[p, 0] - sx
                        py = points[p, 1] - sy
                        pz = points[p, 2] - sz
                        u = (px * dx + py * dy + pz * dz) / L2 if L2 > 0.0 else 0.0
                        u = min(max(u, 0.0), 1.0)
                        # the slice that owns u (the first and last own the clamped ends)
                        if (u < ua and j > 0) or (u >= ub and j < nslice - 1):
                            continue
                        if j == 0 and u < u0 and u0 > 0.0:
                            continue
                        if j == nslice - 1 and u > u1 and u1 < 1.0:
                            continue
                        qx = px - u * dx
                        qy = py - u * dy
                        qz = pz - u * dz
                        r = r0[k] + u * (r1[k] - r0[k])
                        sr = s0[k] + u * (s1[k] - s0[k])
                        qq = qx * qx + qy * qy + qz * qz
                        rm = max(r, sr)
                        if qq > rm * rm:
                            continue
                        c = qx * ax_ + qy * ay_ + qz * az_
                        # past a clamped end, q runs along the segment too: that part counts
                        # against r (a cap as wide as the fan's spacing, not the samples')
                        e = (qx * dx + qy * dy + qz * dz) / L if L > 0.0 else 0.0
                        c = c * c + e * e
                        if c * sr * sr + (qq - c) * r * r <= r * r * sr * sr:
                            if write:
                                out_pt[n] = p
                            n += 1
    return n


@nb.njit(parallel=True, cache=True)
def tube_counts(start, end, r0, r1, s0, s1, across, points, lo, h, dims, bstart, order,
                counts):  # pragma: no cover - compiled
    """counts[k]: the points in segment k's tube (:func:`_segment_points`)."""
    dummy = np.empty(0, np.int64)
    for k in nb.prange(start.shape[0]):
        counts[k] = _segment_points(k, start, end, r0, r1, s0, s1, across, points, lo, h, dims, bstart, order, dummy,
                                    False)


@nb.njit(parallel=True, cache=True)
def tube_fill(start, end, r0, r1, s0, s1, across, points, lo, h, dims, bstart, order, ptr,
              out_pt):  # pragma: no cover - compiled
    """The points of :func:`tube_counts`, segment k's at ``out_pt[ptr[k]:ptr[k + 1]]``."""
    for k in nb.prange(start.shape[0]):
        _segment_points(k, start, end, r0, r1, s0, s1, across, points, lo, h, dims, bstart, order,
                        out_pt[ptr[k]:ptr[k + 1]], True)


@nb.njit(cache=True)
def _branches_of(i, poly, x, u, radius, origin, ptr, dih, other, d_origin, d_dir, d_len, p_normal, p_offset,
                 p_centre, fmax, out_q, out_step, write):  # pragma: no cover - compiled
    """The branches of hit i (:func:`wavepaths.search.launch._neighbour_branches`, the same
    expressions); writes them from index 0 when ``write``; returns how many."""
    p = poly[i]
    n0, n1, n2 = p_normal[p, 0], p_normal[p, 1], p_normal[p, 2]
    cos_i = abs(u[i, 0] * n0 + u[i, 1] * n1 + u[i, 2] * n2)
    foot = radius[i] * min(1.0 / max(cos_i, 1e-12), fmax)
    cnt = 0
    for j in range(ptr[p], ptr[p + 1]):
        d, q = dih[j], other[j]
        v0 = x[i, 0] - d_origin[d, 0]
        v1 = x[i, 1] - d_origin[d, 1]
        v2 = x[i, 2] - d_origin[d, 2]
        t = v0 * d_dir[d, 0] + v1 * d_dir[d, 1] + v2 * d_dir[d, 2]
        t = min(max(t, 0.0), d_len[d])
        w0 = v0 - t * d_dir[d, 0]
        w1 = v1 - t * d_dir[d, 1]
        w2 = v2 - t * d_dir[d, 2]
        if w0 * w0 + w1 * w1 + w2 * w2 > foot * foot:
            continue
        m0, m1, m2, off = p_normal[q, 0], p_normal[q, 1], p_normal[q, 2], p_offset[q]
        side_o = m0 * origin[i, 0] + m1 * origin[i, 1] + m2 * origin[i, 2] - off
        side_p = m0 * p_centre[p, 0] + m1 * p_centre[p, 1] + m2 * p_centre[p, 2] - off
        if side_o * side_p >= 0.0:
            continue
        den = m0 * u[i, 0] + m1 * u[i, 1] + m2 * u[i, 2]
        if abs(den) <= 1e-9:
            continue
        if write:
            out_q[cnt] = q
            out_step[cnt] = (off - (m0 * x[i, 0] + m1 * x[i, 1] + m2 * x[i, 2])) / den
        cnt += 1
    return cnt


@nb.njit(parallel=True, cache=True)
def branch_counts(poly, x, u, radius, origin, ptr, dih, other, d_origin, d_dir, d_len, p_normal, p_offset, p_centre,
                  fmax, counts):  # pragma: no cover - compiled
    dq = np.empty(0, np.int64)
    ds = np.empty(0)
    for i in nb.prange(poly.shape[0]):
        counts[i] = _branches_of(i, poly, x, u, radius, origin, ptr, dih, other, d_origin, d_dir, d_len, p_normal,
                                 p_offset, p_centre, fmax, dq, ds, False)


@nb.njit(parallel=True, cache=True)
def branch_fill(poly, x, u, radius, origin, ptr, dih, other, d_origin, d_dir, d_len, p_normal, p_offset, p_centre,
                fmax, start, out_q, out_step):  # pragma: no cover - compiled
    for i in nb.prange(poly.shape[0]):
        _branches_of(i, poly, x, u, radius, origin, ptr, dih, other, d_origin, d_dir, d_len, p_normal, p_offset,
                     p_centre, fmax, out_q[start[i]:start[i + 1]], out_step[start[i]:start[i + 1]], True)
