"""The numba twins of the Embree caster's numpy set-up and confirmation (imported only when
numba is installed; the wrappers and the numpy reference are in
:mod:`wavepaths.raycast.embree`).

A segment's occlusion is decided by the float64 rule of :class:`ExactSegments`; Embree only
*finds* the face each half-ray meets first. The numpy form of the work around the Embree
call (canonical order, recentring, clipping to the scene's box, the float32 casts, then the
float64 test of each hit) made about a dozen passes over fresh arrays: some 190 ns per ray
on this machine, against about 110 ns for Embree's traversal. Here each is one pass.
"""

import math

import llvmlite.ir as ir
import numba
import numpy as np
from numba import types
from numba.extending import intrinsic


@numba.njit(cache=True, nogil=True, inline="always")
def _put_canonical(p0, p1, p2, q0, q1, q2, A, B, live, r):
    """Write the recentred ends ``p``, ``q`` in canonical order as row ``r`` of ``A``, ``B``, and
    whether they differ in ``live[r]``: lexicographic order, as canonical() (which compares
    the recentred ends)."""
    if q0 < p0 or (q0 == p0 and (q1 < p1 or (q1 == p1 and q2 < p2))):
        p0, p1, p2, q0, q1, q2 = q0, q1, q2, p0, p1, p2
    A[r, 0], A[r, 1], A[r, 2] = p0, p1, p2
    B[r, 0], B[r, 1], B[r, 2] = q0, q1, q2
    live[r] = p0 != q0 or p1 != q1 or p2 != q2


@numba.njit(cache=True, nogil=True)
def canonical_recentred(a, b, center):
    """(k, 3), (k, 3), (k,) bool: the ends in canonical order (wavepaths.raycast.canonical),
    minus ``center``; and whether the segment has length (its ends differ)."""
    k = a.shape[0]
    A = np.empty((k, 3))
    B = np.empty((k, 3))
    live = np.empty(k, dtype=np.bool_)
    for i in range(k):
        _put_canonical(a[i, 0] - center[0], a[i, 1] - center[1], a[i, 2] - center[2],
                       b[i, 0] - center[0], b[i, 1] - center[1], b[i, 2] - center[2], A, B, live, i)
    return A, B, live


@numba.njit(cache=True, nogil=True, inline="always")
def _clip_ray(o, t, lo, hi):
    """The ray ``o -> t`` (3-tuples) against the box ``[lo, hi]``: returns ``(u, t0, t_end)``,
    its unit direction (a 3-tuple) and the part of ``[0, |t - o|]`` inside the box (slab
    clipping; empty when ``t_end <= t0``). Tuples, not scratch arrays: they stay in registers
    (2.5x faster per ray than the same code on three length-3 arrays)."""
    d0, d1, d2 = t[0] - o[0], t[1] - o[1], t[2] - o[2]
    length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    den = length if length > 0 else 1.0
    u = (d0 / den, d1 / den, d2 / den)
    if (lo[0] <= o[0] <= hi[0] and lo[1] <= o[1] <= hi[1] and lo[2] <= o[2] <= hi[2]
            and lo[0] <= t[0] <= hi[0] and lo[1] <= t[1] <= hi[1] and lo[2] <= t[2] <= hi[2]):
        return u, 0.0, length
    tmin = -np.inf
    tmax = np.inf
    for c in range(3):
        if u[c] != 0:
            inv = 1.0 / u[c]
            t1 = (lo[c] - o[c]) * inv
            t2 = (hi[c] - o[c]) * inv
            tmin = max(tmin, min(t1, t2))
            tmax = min(tmax, max(t1, t2))
        elif not (lo[c] <= o[c] <= hi[c]):
            return u, 0.0, 0.0
    return u, max(tmin, 0.0), min(tmax, length)


@numba.njit(cache=True, nogil=True, inline="always")
def _add_ray(o, t, lo, hi, r, cnt, rows, start, unit, span):
    """Append the ray ``o -> t`` (3-tuples) clipped to the box (:func:`_clip_ray`) as row ``r``
    at position ``cnt`` of the float32 outputs, if its span is not empty; returns the new count."""
    u, t0, t_end = _clip_ray(o, t, lo, hi)
    if t_end > t0:
        rows[cnt] = r
        for c in range(3):
            start[cnt, c] = o[c] + t0 * u[c]
            unit[cnt, c] = u[c]
        span[cnt] = t_end - t0
        cnt += 1
    return cnt


@numba.njit(cache=True, nogil=True, inline="always")
def _ray_buffers(n):
    """The outputs of :func:`_add_ray` for up to ``n`` rays: rows (int64), float32 start
    points, unit directions and spans."""
    return (np.empty(n, dtype=np.int64), np.empty((n, 3), dtype=np.float32), np.empty((n, 3), dtype=np.float32),
            np.empty(n, dtype=np.float32))


@numba.njit(cache=True, nogil=True)
def half_rays(A, B, sel, second, lo, hi):
    """The half-rays of the segments ``sel`` for Embree (EmbreeRayCaster.occluded).

    The first half-ray starts at 1/4 of ``A -> B`` towards ``B``, the second at 3/4 towards
    ``A``; each is clipped to the box ``[lo, hi]``. Returns ``(rows, start, unit, span)``:
    the positions in ``sel`` of the rays with a non-empty span, and their float32 start
    points, unit directions and lengths.
    """
    n = sel.shape[0]
    rows, start, unit, span = _ray_buffers(n)
    cnt = 0
    for r in range(n):
        i = sel[r]
        a = (A[i, 0], A[i, 1], A[i, 2])
        b = (B[i, 0], B[i, 1], B[i, 2])
        if second:
            a, b = b, a  # from 3/4 of A -> B back to A
        o = (a[0] + 0.25 * (b[0] - a[0]), a[1] + 0.25 * (b[1] - a[1]), a[2] + 0.25 * (b[2] - a[2]))
        cnt = _add_ray(o, b, lo, hi, r, cnt, rows, start, unit, span)
    return rows[:cnt], start[:cnt], unit[:cnt], span[:cnt]


@numba.njit(cache=True, nogil=True)
def segment_rays(origin, target, lo, hi):
    """The rays ``origin -> target`` (recentred, float64) clipped to the box ``[lo, hi]``, for
    EmbreeRayCaster._nearest (its numpy reference). Returns ``(rows, start, unit, span)`` as
    :func:`half_rays`, the rows indexing ``origin``."""
    n = origin.shape[0]
    rows, start, unit, span = _ray_buffers(n)
    cnt = 0
    for r in range(n):
        o = (origin[r, 0], origin[r, 1], origin[r, 2])
        t = (target[r, 0], target[r, 1], target[r, 2])
        cnt = _add_ray(o, t, lo, hi, r, cnt, rows, start, unit, span)
    return rows[:cnt], start[:cnt], unit[:cnt], span[:cnt]


@numba.njit(cache=True, nogil=True)
def leg_canonical_recentred(V, alive, i, j, center):
    """:func:`canonical_recentred` of the legs ``V[alive, i] -> V[alive, j]`` without the gathered copies."""
    m = alive.shape[0]
    A = np.empty((m, 3))
    B = np.empty((m, 3))
    live = np.empty(m, dtype=np.bool_)
    for r in range(m):
        c = alive[r]
        _put_canonical(V[c, i, 0] - center[0], V[c, i, 1] - center[1], V[c, i, 2] - center[2],
                       V[c, j, 0] - center[0], V[c, j, 1] - center[1], V[c, j, 2] - center[2], A, B, live, r)
    return A, B, live


@numba.njit(cache=True, nogil=True)
def confirm_hits(A, B, seg, prim, second, normal, offset, tol, inward, inward_offset, edge_tol, box_lo, box_hi,
                 reached):
    """(k,) int8: the float64 verdict on each hit ``prim[r]`` of segment ``seg[r]``'s half-ray.

    0: the face does not block, contains the ray's target end in its plane and not the
    other end, and the ray met it at the target end (``reached[r]``: its float32 hit
    distance within the caster's reach tolerance of the ray's length): this half is clear;
    1: the face blocks the segment (ExactSegments.crosses); 2: neither (a float32 graze
    short of the target, or a segment lying in the face's plane: the segment is decided
    against the whole scene); 3: the segment crosses
    the face next to one of its edges (within the plane tolerance), where crosses() also
    checks for a graze along a coplanar face's boundary: left to the numpy reference.
    """
    k = seg.shape[0]
    out = np.empty(k, dtype=np.int8)
    for r in range(k):
        i = seg[r]
        out[r] = _confirm_one(A[i, 0], A[i, 1], A[i, 2], B[i, 0], B[i, 1], B[i, 2], prim[r], second, normal, offset, tol,
                              inward, inward_offset, edge_tol, box_lo, box_hi, reached[r])
    return out


# ---- occlusion in one compiled pass, casting through Embree's C entry point -----------------
_INVALID_ID = np.uint32(0xFFFFFFFF)


@intrinsic
def _call_intersect1(typingctx, fn, scene, rayhit):
    """Call ``void rtcIntersect1(RTCScene, RTCRayHit*, RTCIntersectArguments*)`` at address
    ``fn`` with the scene handle ``scene``, the record at address ``rayhit`` and no arguments
    (NULL). The addresses are passed at run time, so the cached machine code holds none."""
    sig = types.void(types.uint64, types.uint64, types.uint64)

    def codegen(context, builder, signature, args):
        p = ir.IntType(8).as_pointer()
        fnty = ir.FunctionType(ir.VoidType(), [p, p, p])
        f = builder.inttoptr(args[0], fnty.as_pointer())
        builder.call(f, [builder.inttoptr(args[1], p), builder.inttoptr(args[2], p), ir.Constant(p, None)])
        return context.get_dummy_value()

    return sig, codegen


@numba.njit(cache=True, nogil=True, inline="always")
def _confirm_one(a0, a1, a2, b0, b1, b2, f, second, normal, offset, tol, inward, inward_offset, edge_tol, box_lo,
                 box_hi, reached):
    """The verdict of :func:`confirm_hits` on one hit: face ``f`` met by the half-ray of the
    segment ``a -> b`` (the second half-ray if ``second``), ``reached`` its far end. The
    crossing test is ExactSegments.crosses' with its sums in the same order and its
    comparisons false on NaN, as numpy's are."""
    n0, n1, n2, d = normal[f, 0], normal[f, 1], normal[f, 2], offset[f]
    sa = a0 * n0 + a1 * n1 + a2 * n2 - d
    sb = b0 * n0 + b1 * n1 + b2 * n2 - d
    tl = tol[f]
    if (sa > tl and sb < -tl) or (sa < -tl and sb > tl):
        w = sa / (sa - sb)
        x0, x1, x2 = a0 + w * (b0 - a0), a1 + w * (b1 - a1), a2 + w * (b2 - a2)
        inside = True
        near = False
        for e in range(3):
            dist = inward[f, e, 0] * x0 + inward[f, e, 1] * x1 + inward[f, e, 2] * x2 - inward_offset[f, e]
            if not dist >= -edge_tol:
                inside = False
            elif dist <= tl:
                near = True
        if inside and ((x0 >= box_lo[f, 0]) & (x0 <= box_hi[f, 0]) & (x1 >= box_lo[f, 1]) & (x1 <= box_hi[f, 1])
                       & (x2 >= box_lo[f, 2]) & (x2 <= box_hi[f, 2])):
            return 3 if near else 1
    # the ray's target end: B for the first half-ray, A for the second. The face holds it and
    # not the other end: the ray reached the surface the target lies on, this half is clear.
    # A segment in the face's plane (both ends in it) may graze the face anywhere in float32,
    # short of a face that blocks it: decided in float64 (2)
    s_target, s_far = (sa, sb) if second else (sb, sa)
    return 0 if abs(s_target) <= tl and abs(s_far) > tl and reached else 2


@numba.njit(cache=True, nogil=True, inline="always")
def _cast_one(fn, scene, buf, ids, address, start, u, span):
    """Cast one ray (float32 ``start``, unit ``u``, length ``span``) into the RTCRayHit ``buf``
    (``ids`` its uint32 view at ``address``) through ``rtcIntersect1``: tnear 0, every mask
    bit, as embreex's ``run(..., query="INTERSECT")``. Returns the primitive met, -1 if none."""
    buf[0] = start[0]
    buf[1] = start[1]
    buf[2] = start[2]
    buf[3] = 0.0
    buf[4] = u[0]
    buf[5] = u[1]
    buf[6] = u[2]
    buf[7] = 0.0
    buf[8] = span
    ids[9] = _INVALID_ID  # mask: every bit
    ids[10] = 0
    ids[11] = 0
    for c in range(17, 21):  # primID, geomID, instID[0], instPrimID[0]
        ids[c] = _INVALID_ID
    _call_intersect1(fn, scene, address)
    return -1 if ids[18] == _INVALID_ID else np.int64(ids[17])


@numba.njit(cache=True, nogil=True, inline="always")
def _rayhit_buffer():
    """A 16-byte aligned RTCRayHit (96 bytes) inside a fresh float32 array: its float32 and
    uint32 views (which hold the array) and its address; and two float32 3-vectors for a
    ray's start and direction (:func:`_cast_one`'s arguments)."""
    raw = np.empty(48, dtype=np.float32)
    o = ((16 - raw.ctypes.data % 16) % 16) // 4
    buf = raw[o:o + 24]
    return (buf, buf.view(np.uint32), np.uint64(buf.ctypes.data), np.empty(3, dtype=np.float32),
            np.empty(3, dtype=np.float32))


@numba.njit(cache=True, nogil=True)
def nearest_direct(origin, target, lo, hi, fn, scene):
    """:func:`segment_rays` and Embree's nearest hit in one pass (``rtcIntersect1``, see
    :func:`occluded_direct`): (k,) int64, the triangle each ray ``origin -> target``
    (recentred, clipped to the box ``[lo, hi]``, the same float32 rays) meets first, -1 if
    none or if no part of it lies in the box; and the number of rays cast."""
    k = origin.shape[0]
    prim = np.full(k, -1, dtype=np.int64)
    buf, ids, address, start, unit = _rayhit_buffer()
    rays = 0
    for r in range(k):
        o = (origin[r, 0], origin[r, 1], origin[r, 2])
        t = (target[r, 0], target[r, 1], target[r, 2])
        u, t0, t_end = _clip_ray(o, t, lo, hi)
        if not t_end > t0:
            continue
        for c in range(3):
            start[c] = o[c] + t0 * u[c]
            unit[c] = u[c]
        prim[r] = _cast_one(fn, scene, buf, ids, address, start, unit, np.float32(t_end - t0))
        rays += 1
    return prim, rays


@numba.njit(cache=True, nogil=True)
def occluded_direct(A, B, sel, lo, hi, reach_tol, fn, scene, normal, offset, tol, inward, inward_offset, edge_tol,
                    box_lo, box_hi):
    """The verdicts of :meth:`wavepaths.raycast.embree.EmbreeRayCaster._halves_core` for the
    segments ``A[sel] -> B[sel]`` (canonical, recentred, with length), in one pass: each
    segment's first half-ray (:func:`half_rays`), cast by ``rtcIntersect1`` (address ``fn``,
    scene handle ``scene``; see :mod:`wavepaths.raycast.embree_c`), its hit decided by
    :func:`confirm_hits`' rule, then, if that half is clear, the second.

    Returns ``(verdict, face, rays)``: (k,) int8, 0 clear, 1 blocked, 2 undecided (to the
    float64 test against the whole scene), 3 a crossing next to a face's edge (to the numpy
    ``crosses``, then the float64 test); (k,) int64, the face that gave a non-zero verdict;
    and the number of rays cast.
    """
    k = sel.shape[0]
    out = np.zeros(k, dtype=np.int8)
    face = np.full(k, -1, dtype=np.int64)
    buf, ids, address, start, unit = _rayhit_buffer()
    rays = 0
    for r in range(k):
        i = sel[r]
        a0, a1, a2 = A[i, 0], A[i, 1], A[i, 2]
        b0, b1, b2 = B[i, 0], B[i, 1], B[i, 2]
        for half in range(2):
            second = half == 1
            # from 1/4 of A -> B towards B; the second from 3/4 back towards A
            p = (b0, b1, b2) if second else (a0, a1, a2)
            q = (a0, a1, a2) if second else (b0, b1, b2)
            og = (p[0] + 0.25 * (q[0] - p[0]), p[1] + 0.25 * (q[1] - p[1]), p[2] + 0.25 * (q[2] - p[2]))
            u, t0, t_end = _clip_ray(og, q, lo, hi)
            if not t_end > t0:
                continue  # no part of this half inside the scene's box: nothing to meet
            span = np.float32(t_end - t0)
            for c in range(3):
                start[c] = og[c] + t0 * u[c]
                unit[c] = u[c]
            f = _cast_one(fn, scene, buf, ids, address, start, unit, span)
            rays += 1
            if f < 0:
                continue  # nothing on this half
            reached = buf[8] >= span - reach_tol  # the hit's distance, written over tfar
            v = _confirm_one(a0, a1, a2, b0, b1, b2, f, second, normal, offset, tol, inward, inward_offset, edge_tol,
                             box_lo, box_hi, reached)
            if v != 0:
                out[r] = v
                face[r] = f
                break
    return out, face, rays


# ---- occlusion through the float64 tree (wavepaths.raycast.bvh), no float32 step -------------
@numba.njit(cache=True, nogil=True)
def occluded_bvh(A, B, sel, box, first, count, right, rows, edge_tol, slack):
    """The exact rule's verdicts (ExactSegments.blocked) for the segments ``A[sel] -> B[sel]``
    (canonical, recentred), walking the tree of :class:`wavepaths.raycast.bvh.SegmentBVH`:
    each triangle whose padded box the segment meets is tested as ExactSegments.crosses does
    (:func:`_row_crossing`), and the walk stops at the first that blocks. The triangle that
    blocked the last blocked segment is tried before the walk: any triangle that blocks
    decides the verdict, so this changes no answer, and neighbouring legs (the search's are
    grouped by receiver) are often blocked by the same wall.

    The boxes are met by slabs computed in float64, whose rounding grows with the ends'
    distance from the scene's centre: where ``4e-15`` of the sum of the segment's coordinates'
    magnitudes (at least its largest) exceeds ``slack`` (``SegmentBVH.slack``: what the
    boxes' padding leaves beyond the crossing point's box), each box is grown by it, so that
    a segment with an end far away still meets the boxes of the triangles it crosses.

    Returns ``(verdict, row)``: (k,) int8, 0 clear, 1 blocked, 3 undecided here: a crossing
    next to a triangle's edge (within its plane tolerance, where crosses() also checks for a
    graze along a coplanar face's boundary) and no other triangle blocking, or a segment with
    an end that is not finite or ends whose difference overflows (row -1); (k,) int64, the
    tree's row of the first such crossing (``SegmentBVH.triangle`` maps rows to triangles).
    """
    k = sel.shape[0]
    out = np.zeros(k, dtype=np.int8)
    face = np.full(k, -1, dtype=np.int64)
    if box.shape[0] == 0:
        return out, face
    stack = np.empty(128, dtype=np.int64)
    last = -1  # the row that blocked the last blocked segment: tried first (any blocker decides)
    for r in range(k):
        i = sel[r]
        a0, a1, a2 = A[i, 0], A[i, 1], A[i, 2]
        b0, b1, b2 = B[i, 0], B[i, 1], B[i, 2]
        d0, d1, d2 = b0 - a0, b1 - a1, b2 - a2
        if not (math.isfinite(d0) and math.isfinite(d1) and math.isfinite(d2)):
            # an end that is not finite (then so is b - a), or b - a overflows: left to the
            # numpy reference
            out[r] = 3
            continue
        if last >= 0 and _row_crossing(rows, last, a0, a1, a2, b0, b1, b2, edge_tol) == 1:
            out[r] = 1
            continue
        # 4e-15 of the largest coordinate, bounded above by the sum of them all
        g = 4e-15 * ((abs(a0) + abs(a1) + abs(a2)) + (abs(b0) + abs(b1) + abs(b2)))
        grow = g > slack  # else the boxes' padding covers the slabs' rounding
        i0 = 1.0 / d0 if d0 != 0.0 else 0.0
        i1 = 1.0 / d1 if d1 != 0.0 else 0.0
        i2 = 1.0 / d2 if d2 != 0.0 else 0.0
        stack[0] = 0
        sp = 1
        verdict = 0
        while sp > 0:
            sp -= 1
            nd = stack[sp]
            # the part t in [0, 1] of a + t d inside the box (slab by slab; an axis the
            # segment runs parallel to: its coordinate within the slab)
            t0, t1 = 0.0, 1.0
            lo0, lo1, lo2, hi0, hi1, hi2 = box[nd, 0], box[nd, 1], box[nd, 2], box[nd, 3], box[nd, 4], box[nd, 5]
            if grow:
                lo0, lo1, lo2, hi0, hi1, hi2 = lo0 - g, lo1 - g, lo2 - g, hi0 + g, hi1 + g, hi2 + g
            if d0 != 0.0:
                u, v = (lo0 - a0) * i0, (hi0 - a0) * i0
                t0, t1 = max(t0, min(u, v)), min(t1, max(u, v))
            elif a0 < lo0 or a0 > hi0:
                continue
            if d1 != 0.0:
                u, v = (lo1 - a1) * i1, (hi1 - a1) * i1
                t0, t1 = max(t0, min(u, v)), min(t1, max(u, v))
            elif a1 < lo1 or a1 > hi1:
                continue
            if d2 != 0.0:
                u, v = (lo2 - a2) * i2, (hi2 - a2) * i2
                t0, t1 = max(t0, min(u, v)), min(t1, max(u, v))
            elif a2 < lo2 or a2 > hi2:
                continue
            if t0 > t1:
                continue
            c = count[nd]
            if c == 0:
                stack[sp] = nd + 1
                stack[sp + 1] = right[nd]
                sp += 2
                continue
            for q in range(first[nd], first[nd] + c):
                v = _row_crossing(rows, q, a0, a1, a2, b0, b1, b2, edge_tol)
                if v == 1:
                    verdict = 1
                    last = q
                    break
                if v == 3 and verdict == 0:
                    verdict = 3
                    face[r] = q  # a row of the tree: the caller maps it to its triangle
            if verdict == 1:
                break
        out[r] = verdict
    return out, face


@numba.njit(cache=True, nogil=True, inline="always")
def _row_crossing(rows, q, a0, a1, a2, b0, b1, b2, edge_tol):
    """ExactSegments.crosses' test of the segment ``a -> b`` against the triangle of row ``q``
    of the tree (:func:`_confirm_one`'s crossing test, the same expressions, comparisons false
    on NaN): 0 no crossing, 1 a crossing inside the triangle, 3 a crossing inside it but
    within its plane tolerance of an edge (left to crosses(), which checks for a graze there)."""
    n0, n1, n2, off, tl = rows[q, 0], rows[q, 1], rows[q, 2], rows[q, 3], rows[q, 4]
    sa = a0 * n0 + a1 * n1 + a2 * n2 - off
    sb = b0 * n0 + b1 * n1 + b2 * n2 - off
    if not ((sa > tl and sb < -tl) or (sa < -tl and sb > tl)):
        return 0
    w = sa / (sa - sb)
    x0, x1, x2 = a0 + w * (b0 - a0), a1 + w * (b1 - a1), a2 + w * (b2 - a2)
    near = False
    for e in range(3):
        o = 5 + 4 * e
        dist = rows[q, o] * x0 + rows[q, o + 1] * x1 + rows[q, o + 2] * x2 - rows[q, o + 3]
        if not dist >= -edge_tol:
            return 0
        if dist <= tl:
            near = True
    # and within the triangle's box grown by edge_tol (ExactSegments, Notes 2.): tested last, as
    # it rejects only next to a sharp corner, in one expression of non-short-circuit ands (the
    # chained comparisons' branches made the walk 20-30 % slower, though it runs for crossings only)
    if not ((x0 >= rows[q, 17]) & (x0 <= rows[q, 20]) & (x1 >= rows[q, 18]) & (x1 <= rows[q, 21])
            & (x2 >= rows[q, 19]) & (x2 <= rows[q, 22])):
        return 0
    return 3 if near else 1
