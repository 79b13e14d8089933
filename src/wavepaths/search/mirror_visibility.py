"""Mirrors proven hidden from a group of source points: one convex occluder each.

A reflection path ``S -> X1 -> ...`` needs its first leg, from the source ``S`` to the
reflection point ``X1`` on the first mirror ``P``, to be unobstructed. When every point of
``P`` is hidden from ``S``, no path reflects first on ``P``, and no chain of an image
tree (:func:`~wavepaths.search.images.build_image_levels`) needs to start with ``P``. On a
city's street, a transmitter or receiver sees a few hundred of its tens of thousands of
walls; the rest still pass every test of the image tree (they face the source), and each
one otherwise costs a branch of the tree and, on the receiver side, a (receiver image,
edge) pair per diffracting edge.

What is proven (:func:`hidden_mirrors`). A group of sources (the receivers of a compact
part of a tile, or one transmitter) is bounded by its box ``B`` (corners ``b_i``); a mirror
``P`` by the convex hull of points ``p_j`` (its hull's corners when it is planar, else all its
corners, :attr:`PolygonHulls.points`). An occluder ``Q`` is a convex, planar polygon
of the scene. When ``B`` lies strictly on one side of ``Q``'s plane, ``P`` strictly on the
other, and every segment ``b_i -> p_j`` crosses that plane strictly inside ``Q``, then
*every* segment from a point of ``B`` to a point of ``P`` crosses ``Q``'s interior: for a
fixed end ``p`` the crossing points of the segments from ``B`` are the central projection
of ``B`` through ``p`` onto the plane, and a central projection maps the convex hull of
the corners onto the convex hull of their images (and likewise for a fixed ``b`` and the
points of ``P``), so all crossing points lie in the convex hull of the ``b_i -> p_j``
crossings, inside the convex ``Q``. Such a segment crosses a closed triangle of ``Q`` with
both ends off its plane, so the occlusion rule (:mod:`wavepaths.raycast`) blocks it. The
margins (``1e-9`` of the scene diagonal, off the plane and inside ``Q``'s sides) keep the
proof far above float64 rounding; only polygons whose corners lie within the plane
tolerance of their plane, and whose triangles cover their convex hull, serve as occluders.

The same proof with the corners of a mirror ``p`` in place of the box would decide a pair
of mirrors (no leg from ``p`` to ``q``). Tried on ``munich`` and dropped: from the
transmitter it decided 3.6 M pairs (26 s) to cull 4 % of the order-2 chains; one convex
occluder rarely covers every leg between two walls. What does pay is the same proof from
one *image* (:func:`hidden_after_mirror`): the leg from the previous mirror to the next one
lies on a segment from the parent image, so a point source again, with one more condition
(the leg's start, on the previous mirror, before the occluder). On munich it drops 19 % of
the transmitter's order-2 chains and a quarter of a strip's receiver order-2 chains.

The image trees use groups of one source (a transmitter, or one receiver: see
``RX_VISIBILITY_GROUP`` in :mod:`wavepaths.search.tile`): on munich, groups of one drop 96 %
of a 16-cell tile's order-1 receiver images, groups of sixteen (a 6 m box) 20 %.

Which occluder. One ray per (group, mirror) pair, from the group's centre to the mirror's
centre, cast by Embree (float32): the first polygon it meets is the candidate ``Q``, a hint
only; the test above decides in float64. A mirror behind two walls that each cover part of
it is not culled (conservative: it is traced as before).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..scene.polygon_shapes import MAX_HULL, PolygonHulls
from . import kernels

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene

GROUP_SIZE = 16
"""Sources per group (consecutive along a Morton curve): one box and one ray per mirror."""
PAIR_BLOCK = 1 << 14
"""(group, mirror) pairs tested at once (bounds the (pairs, 8, hull, hull) temporaries)."""
PILOT_STRIDE = 8
"""Groups per occluder hint in :func:`hidden_mirrors` (one pilot group casts, the next seven reuse)."""


def _kernel(name: str, compiled: bool | None, caller: str):
    """The compiled proof ``_numba_mirrors.<name>``, or ``None`` for the numpy reference: by default
    when numba is installed, never with ``compiled=False``; ``compiled=True`` without numba
    raises ``ImportError``."""
    if compiled is not False and kernels.available():
        from . import _numba_mirrors

        return getattr(_numba_mirrors, name)
    if compiled:
        raise ImportError(f"{caller}(compiled=True) needs numba (pip install 'wavepaths[fast]')")
    return None


def source_groups(sources: np.ndarray, size: int = GROUP_SIZE) -> np.ndarray:
    """(s,) int64: a group per source, ``size`` consecutive sources along a Morton curve each."""
    from .spheres import morton_order

    s = len(sources)
    group = np.empty(s, np.int64)
    group[morton_order(sources)] = np.arange(s) // max(size, 1)
    return group


def hidden_mirrors(scene: "Scene", sources: np.ndarray, group: np.ndarray, mirrors: np.ndarray,
                   candidates: np.ndarray | None = None, compiled: bool | None = None,
                   pilot_stride: int = PILOT_STRIDE) -> tuple[np.ndarray, int]:
    """Which (group, mirror) pairs are proven hidden: every point of the mirror from every source of the group.

    Parameters
    ----------
    scene : Scene
    sources : (s, 3) float64
        Source points [m].
    group : (s,) int64
        Group of each source (``0 .. g - 1``, see :func:`source_groups`).
    mirrors : (m,) int64
        Polygons to test.
    candidates : (g, m) bool, optional
        Only these pairs are tested (the others are reported not hidden); default all.
    compiled : bool, optional
        Run the proof pair by pair as a compiled loop (``_numba_mirrors.behind``, numba): by default
        when numba is installed; ``False`` runs the numpy reference (:func:`_behind`).
    pilot_stride : int
        Occluder hints are shared along the groups' Morton order: the groups ``0, s, 2s, ...``
        (the pilots) cast a ray per pair; the others first try, for each mirror, the occluder
        their pilot's ray named, and cast a ray only when that proof fails. Neighbouring
        receivers of a map are mostly hidden from a mirror by the same wall, so most rays
        are saved; a hint is only a candidate ``Q`` for the proof, which decides alone.
        ``1`` casts a ray for every pair.

    Returns
    -------
    hidden : (g, m) bool
        The proof of the module docstring holds for the pair.
    rays : int
        Rays cast to find the occluders.
    """
    sources = np.asarray(sources, dtype=np.float64).reshape(-1, 3)
    g = int(group.max()) + 1 if len(group) else 0
    m = len(mirrors)
    hidden = np.zeros((g, m), bool)
    if g == 0 or m == 0:
        return hidden, 0
    lo = np.full((g, 3), np.inf)
    hi = np.full((g, 3), -np.inf)
    np.minimum.at(lo, group, sources)
    np.maximum.at(hi, group, sources)
    # the box's distinct corners: 1 for single points, 4 for a flat tile of a map, at most 8
    flat = (hi == lo).all(axis=0)
    bits = np.array([[(i >> j) & 1 for j in range(3)] for i in range(8)], dtype=bool)
    bits = bits[~(bits & flat[None, :]).any(axis=1)]
    box = np.where(bits[None], hi[:, None, :], lo[:, None, :])  # (g, c, 3)
    centre = 0.5 * (lo + hi)
    hulls = scene.polygon_hulls
    margin = 1e-9 * scene.diagonal
    kernel = _kernel("behind", compiled, "hidden_mirrors")
    gi, mi = np.nonzero(candidates) if candidates is not None else np.divmod(np.arange(g * m), m)
    ok = hulls.num_points[mirrors[mi]] > 0
    gi, mi = gi[ok], mi[ok]

    def prove(G: np.ndarray, M: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """(k,) bool: the proof for pairs (G, M) with the candidate occluders Q (-1: none)."""
        P = mirrors[M]
        use = (Q >= 0) & (Q != P)
        use[use] = hulls.occluder[Q[use]]
        out = np.zeros(len(G), bool)
        idx = np.nonzero(use)[0]
        if len(idx) == 0:
            return out
        if kernel is None:
            out[idx] = _behind(scene, hulls, box[G[idx]], P[idx], Q[idx], margin)
        else:
            got = np.empty(len(idx), np.bool_)
            c = np.ascontiguousarray
            kernel(c(box[G[idx]]), c(P[idx], dtype=np.int64), c(Q[idx], dtype=np.int64), hulls.points,
                   hulls.num_points, scene.polygon_normal, scene.polygon_offset, hulls.edge_normal,
                   hulls.edge_offset, hulls.count, float(margin), got)
            out[idx] = got
        return out

    def cast(G: np.ndarray, M: np.ndarray) -> np.ndarray:
        """(k,) int64: the polygon a ray from the group's centre to the mirror's centre meets first."""
        tri = scene.raycaster.first_triangle(centre[G], hulls.centre[mirrors[M]])
        return np.where(tri >= 0, scene.triangle_polygon[np.maximum(tri, 0)], -1)

    stride = max(int(pilot_stride), 1)
    pilot = gi % stride == 0
    lead = np.nonzero(pilot)[0]
    hint = np.full((g + stride - 1) // stride * m if stride > 1 else 0, -1, np.int64)
    rays = 0
    # the pilots (every group when stride is 1): a ray per pair; their occluders become hints
    for s in range(0, len(lead), PAIR_BLOCK):
        sel = lead[s : s + PAIR_BLOCK]
        G, M = gi[sel], mi[sel]
        Q = cast(G, M)
        rays += len(G)
        hidden[G, M] = prove(G, M, Q)
        if stride > 1:
            hint[(G // stride) * m + M] = Q
    # the others: their pilot's occluder first, a ray when that proof fails
    rest = np.nonzero(~pilot)[0]
    for s in range(0, len(rest), PAIR_BLOCK):
        sel = rest[s : s + PAIR_BLOCK]
        G, M = gi[sel], mi[sel]
        Qh = hint[(G // stride) * m + M]
        done = prove(G, M, Qh)
        hidden[G[done], M[done]] = True
        G, M, Qh = G[~done], M[~done], Qh[~done]
        Q = cast(G, M)
        rays += len(G)
        again = Q != Qh  # the same occluder would fail the same proof
        hidden[G[again], M[again]] = prove(G[again], M[again], Q[again])
    return hidden, rays


def _behind(scene: "Scene", hulls: PolygonHulls, box: np.ndarray, P: np.ndarray, Q: np.ndarray,
            margin: float) -> np.ndarray:
    """(k,) bool: every segment from the box corners ``box`` (k, c, 3) to the hull of polygon
    ``P``'s points crosses the convex polygon ``Q``'s interior, with ``margin`` to spare (the
    module's proof).

    Pairs are taken by their point and corner counts, so the arrays hold no padding."""
    n = scene.polygon_normal[Q]
    d = scene.polygon_offset[Q]
    sb = np.einsum("kij,kj->ki", box, n) - d[:, None]  # (k, c)
    sign = np.sign(sb[:, 0])
    ok = (sign[:, None] * sb > margin).all(axis=1)
    cp, cq = hulls.num_points[P], hulls.count[Q]
    for a in np.unique(cp[ok]):
        for e in np.unique(cq[ok & (cp == a)]):
            idx = np.nonzero(ok & (cp == a) & (cq == e))[0]
            pc = hulls.points[P[idx], :a]  # (k, a, 3)
            sp = np.einsum("kij,kj->ki", pc, n[idx]) - d[idx, None]  # (k, a)
            beyond = (sign[idx, None] * sp < -margin).all(axis=1)
            ok[idx[~beyond]] = False
            idx, pc, sp = idx[beyond], pc[beyond], sp[beyond]
            if len(idx) == 0:
                continue
            b, s0 = box[idx], sb[idx]
            t = s0[:, :, None] / (s0[:, :, None] - sp[:, None, :])  # (k, c, a) in (0, 1)
            x = b[:, :, None, :] + t[..., None] * (pc[:, None, :, :] - b[:, :, None, :])  # (k, c, a, 3)
            en = hulls.edge_normal[Q[idx], :e]  # (k, e, 3)
            eo = hulls.edge_offset[Q[idx], :e]
            inside = np.einsum("kabj,kej->kabe", x, en) - eo[:, None, None, :]
            ok[idx] = (inside >= margin).all(axis=(1, 2, 3))
    return ok


AFTER_BLOCK = 1 << 18
"""(image, mirror) pairs of :func:`hidden_after_mirror` cast and proven at once."""


def hidden_after_mirror(scene: "Scene", images: np.ndarray, previous: np.ndarray, mirrors: np.ndarray,
                        compiled: bool | None = None) -> tuple[np.ndarray, int]:
    """Which (image, mirror) pairs of an image tree's order ``k >= 2`` are proven hidden.

    A chain ``... -> p -> q`` reflects on ``p`` at ``X_p`` and on ``q`` at ``X_q``; by the
    image method, ``X_p`` is where the segment from the parent image ``I`` (the image after
    reflecting on ``p``) to ``X_q`` crosses ``p``'s plane, and the path's leg is the part
    ``X_p -> X_q`` of that segment. It is blocked for every ``X_q`` of ``q`` when, for a
    convex, planar occluder ``Q`` (all by ``1e-9`` of the scene diagonal):

    1. the proof of the module docstring holds with the single point ``I`` as the box: ``I``
       strictly on one side of ``Q``'s plane, the points ``q_v`` of ``q`` strictly on the
       other, every segment ``I -> q_v`` crossing the plane inside ``Q``'s sides; then every
       segment ``I -> X_q`` crosses ``Q``'s plane once, at a point ``C`` inside ``Q``;
    2. ``I`` and the points ``q_v`` lie strictly on opposite sides of ``p``'s plane, and the
       central projections ``y_v`` of the ``q_v`` from ``I`` onto ``p``'s plane lie strictly
       on ``I``'s side of ``Q``'s plane. ``X_p`` is the central projection of ``X_q``, so it
       lies in the convex hull of the ``y_v`` (a central projection maps a convex hull onto
       the hull of the images), on ``I``'s side: before ``C`` on the segment.

    The leg ``X_p -> X_q`` then passes through ``Q`` with both ends off its plane: blocked
    by the rule of :mod:`wavepaths.raycast`. No path follows the chain, nor any chain that
    extends it. Nothing is assumed of where ``X_p`` lies in ``p`` (the back-trace's
    in-polygon tolerance does not enter).

    The candidate ``Q`` is the polygon an Embree ray meets first from just past where the
    line from ``I`` to ``q``'s centre crosses ``p``'s plane, to that centre (a float32 hint
    only).

    Parameters
    ----------
    scene : Scene
    images : (k, 3) float64
        Parent images ``I`` [m].
    previous : (k,) int64
        The parent's last mirror ``p``.
    mirrors : (k,) int64
        The new mirror ``q``.
    compiled : bool, optional
        The proof as a compiled loop (``_numba_mirrors.behind_after``): by default when numba is
        installed; ``False`` runs the numpy reference (:func:`_after_mirror_numpy`).

    Returns
    -------
    hidden : (k,) bool
    rays : int
        Rays cast for the hints.
    """
    images = np.asarray(images, dtype=np.float64).reshape(-1, 3)
    k = len(images)
    hidden = np.zeros(k, bool)
    hulls = scene.polygon_hulls
    margin = 1e-9 * scene.diagonal
    kernel = _kernel("behind_after", compiled, "hidden_after_mirror")
    idx_all = np.nonzero(hulls.num_points[mirrors] > 0)[0]
    rays = 0
    n_all, d_all = scene.polygon_normal, scene.polygon_offset
    for s in range(0, len(idx_all), AFTER_BLOCK):
        idx = idx_all[s : s + AFTER_BLOCK]
        I, p, q = images[idx], previous[idx], mirrors[idx]
        fI = np.einsum("ij,ij->i", I, n_all[p]) - d_all[p]
        # the hint ray, from just past where the line I -> centre(q) crosses p's plane, to that centre
        c = hulls.centre[q]
        den = fI - (np.einsum("ij,ij->i", c, n_all[p]) - d_all[p])
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(den != 0, fI / den, 0.0)
        t = np.clip(t, 0.0, 1.0)
        t += 1e-3 * (1.0 - t)  # just past p, so that Embree does not name p itself
        tri = scene.raycaster.first_triangle(I + t[:, None] * (c - I), c)
        rays += len(idx)
        Q = np.where(tri >= 0, scene.triangle_polygon[np.maximum(tri, 0)], -1)
        if kernel is not None:
            got = np.empty(len(idx), np.bool_)
            kernel(np.ascontiguousarray(I), np.ascontiguousarray(p, dtype=np.int64),
                   np.ascontiguousarray(q, dtype=np.int64), Q.astype(np.int64), hulls.occluder, hulls.points,
                   hulls.num_points, n_all, d_all, hulls.edge_normal, hulls.edge_offset, hulls.count, float(margin), got)
            hidden[idx] = got
            continue
        hidden[idx] = _after_mirror_numpy(scene, hulls, I, p, q, Q, fI, margin)
    return hidden, rays


def _after_mirror_numpy(scene: "Scene", hulls: PolygonHulls, I: np.ndarray, p: np.ndarray, q: np.ndarray,
                        Q: np.ndarray, fI: np.ndarray, margin: float) -> np.ndarray:
    """(k,) bool: the proof of :func:`hidden_after_mirror` for parent images ``I``, previous
    mirrors ``p``, mirrors ``q``, candidate occluders ``Q`` (-1: none) and ``fI``, the images'
    signed distances to ``p``'s plane; the numpy reference of ``_numba_mirrors.behind_after``."""
    n_all, d_all = scene.polygon_normal, scene.polygon_offset
    out = np.zeros(len(I), bool)
    use = (Q >= 0) & (Q != q) & (Q != p) & (fI != 0)
    use[use] = hulls.occluder[Q[use]]
    j = np.nonzero(use)[0]
    if len(j) == 0:
        return out
    I, p, q, Q, fI = I[j], p[j], q[j], Q[j], fI[j]
    # step 2: q's points on the far side of p's plane from I, and their central projections
    # from I onto p's plane on I's side of Q's plane
    pts = hulls.points[q]  # (b, MAX_HULL, 3)
    real = np.arange(MAX_HULL)[None, :] < hulls.num_points[q][:, None]
    fq = np.einsum("kaj,kj->ka", pts, n_all[p]) - d_all[p][:, None]
    ok = (~real | (np.sign(fI)[:, None] * fq < -margin)).all(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = fI[:, None] / (fI[:, None] - fq)  # in (0, 1) on the real points that passed
    y = I[:, None, :] + frac[..., None] * (pts - I[:, None, :])
    nq, dq = n_all[Q], d_all[Q]
    side = np.sign(np.einsum("ij,ij->i", I, nq) - dq)
    fy = np.einsum("kaj,kj->ka", y, nq) - dq[:, None]
    ok &= (~real | (side[:, None] * fy > margin)).all(axis=1) & (side != 0)
    k = np.nonzero(ok)[0]
    if len(k):
        # step 1: the module's proof with the single point I as the box
        out[j[k]] = _behind(scene, hulls, np.ascontiguousarray(I[k][:, None, :]), q[k], Q[k], margin)
    return out
