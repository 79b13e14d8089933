"""The numba twins of :mod:`wavepaths.search.images`: the image trees' exact admissibility
tests (``images._admissible``) and the back-traces of the image method
(``images.backtrace``: the reflection points from the target back to the source, each
strictly inside its leg and inside its mirror polygon). Imported only when numba is
installed; the numpy functions named in each comment are the references."""

import numba

from ._numba_beams import _beam_meets


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
