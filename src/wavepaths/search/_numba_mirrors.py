"""The numba twins of :mod:`wavepaths.search.mirror_visibility`'s proofs (imported only when
numba is installed; the numpy functions named in each comment are the references)."""

import numba


@numba.njit(cache=True, nogil=True)
def behind(box, P, Q, points, num_points, normal, offset, edge_normal, edge_offset, count, margin, out):
    # mirror_visibility._behind (numpy reference), pair by pair with an early exit: the box's
    # corners strictly on one side of Q's plane, P's points strictly on the other, and every
    # (corner, point) segment crossing the plane inside Q's sides, all by `margin`
    k, c = box.shape[0], box.shape[1]
    for i in range(k):
        p, q = P[i], Q[i]
        n0, n1, n2, d = normal[q, 0], normal[q, 1], normal[q, 2], offset[q]
        s0 = (box[i, 0, 0] * n0 + box[i, 0, 1] * n1 + box[i, 0, 2] * n2) - d
        sign = 1.0 if s0 > 0 else (-1.0 if s0 < 0 else 0.0)
        ok = True
        for u in range(c):
            su = (box[i, u, 0] * n0 + box[i, u, 1] * n1 + box[i, u, 2] * n2) - d
            if not sign * su > margin:
                ok = False
                break
        a = num_points[p]
        if ok:
            for v in range(a):
                sv = (points[p, v, 0] * n0 + points[p, v, 1] * n1 + points[p, v, 2] * n2) - d
                if not sign * sv < -margin:
                    ok = False
                    break
        e = count[q]
        u = 0
        while ok and u < c:
            b0, b1, b2 = box[i, u, 0], box[i, u, 1], box[i, u, 2]
            su = (b0 * n0 + b1 * n1 + b2 * n2) - d
            for v in range(a):
                sv = (points[p, v, 0] * n0 + points[p, v, 1] * n1 + points[p, v, 2] * n2) - d
                t = su / (su - sv)
                x0 = b0 + t * (points[p, v, 0] - b0)
                x1 = b1 + t * (points[p, v, 1] - b1)
                x2 = b2 + t * (points[p, v, 2] - b2)
                for f in range(e):
                    if not (x0 * edge_normal[q, f, 0] + x1 * edge_normal[q, f, 1] + x2 * edge_normal[q, f, 2])\
                            - edge_offset[q, f] >= margin:
                        ok = False
                        break
                if not ok:
                    break
            u += 1
        out[i] = ok
    return out


@numba.njit(cache=True, nogil=True)
def behind_after(I, P, Qm, O, occluder, points, num_points, normal, offset, edge_normal, edge_offset, count, margin,
                 out):
    # mirror_visibility.hidden_after_mirror's proof (numpy reference there), pair by pair: the
    # parent image I[i], its last mirror P[i], the new mirror Qm[i], the candidate occluder O[i]
    for i in range(len(P)):
        p, q, o = P[i], Qm[i], O[i]
        out[i] = False
        if o < 0 or o == q or o == p or not occluder[o] or num_points[q] == 0:
            continue
        i0, i1, i2 = I[i, 0], I[i, 1], I[i, 2]
        fI = i0 * normal[p, 0] + i1 * normal[p, 1] + i2 * normal[p, 2] - offset[p]
        n0, n1, n2, d = normal[o, 0], normal[o, 1], normal[o, 2], offset[o]
        sI = i0 * n0 + i1 * n1 + i2 * n2 - d
        if fI == 0 or sI == 0:
            continue
        sp = 1.0 if fI > 0 else -1.0
        side = 1.0 if sI > 0 else -1.0
        ok = side * sI > margin
        a = num_points[q]
        e = count[o]
        v = 0
        while ok and v < a:
            x0, x1, x2 = points[q, v, 0], points[q, v, 1], points[q, v, 2]
            # step 2: q's point beyond p's plane from I, its projection onto p's plane on I's side
            fq = x0 * normal[p, 0] + x1 * normal[p, 1] + x2 * normal[p, 2] - offset[p]
            if not sp * fq < -margin:
                ok = False
                break
            frac = fI / (fI - fq)
            y0, y1, y2 = i0 + frac * (x0 - i0), i1 + frac * (x1 - i1), i2 + frac * (x2 - i2)
            if not side * (y0 * n0 + y1 * n1 + y2 * n2 - d) > margin:
                ok = False
                break
            # step 1: q's point beyond the occluder's plane, the segment from I crossing it inside
            sv = x0 * n0 + x1 * n1 + x2 * n2 - d
            if not side * sv < -margin:
                ok = False
                break
            t = sI / (sI - sv)
            c0, c1, c2 = i0 + t * (x0 - i0), i1 + t * (x1 - i1), i2 + t * (x2 - i2)
            for f in range(e):
                if not (c0 * edge_normal[o, f, 0] + c1 * edge_normal[o, f, 1] + c2 * edge_normal[o, f, 2])\
                        - edge_offset[o, f] >= margin:
                    ok = False
                    break
            v += 1
        out[i] = ok
    return out
