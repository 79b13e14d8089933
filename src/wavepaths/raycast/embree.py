"""Segment occlusion through Embree (embreex), float32 on recentred coordinates, every hit checked in float64."""

from __future__ import annotations

import threading
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from . import canonical
from .numpy_caster import ExactSegments

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene


@lru_cache(maxsize=1)
def _compiled():
    """The compiled set-up and confirmation kernels, or ``None`` when numba is not installed."""
    try:
        from . import _numba
    except ImportError:
        return None
    return _numba


THREAD_MIN_SEGMENTS = 1 << 15
"""Segments per thread below which an occlusion query stays on the calling thread."""

_COUNT_LOCK = threading.Lock()


class EmbreeRayCaster:
    """Occlusion queries against a scene with Embree, decided by the float64 rule.

    Parameters
    ----------
    scene : Scene
    batch : int
        Rays per Embree call (bounds the float32 temporaries).

    Notes
    -----
    float32 enters here and only here, and only to *find* faces:

    1. vertices and rays are expressed relative to ``scene.center`` before the cast, so
       positions resolve to ~6e-8 of the scene's half-size whatever their absolute
       coordinates (city scenes sit near 1e6 m);
    2. each ray is clipped, in float64, to the scene's bounding box (a transmitter 20 km
       away gives a ray no longer than the scene), because a float32 direction misplaces
       the far end of a ray by ~6e-8 of its length;
    3. a segment ``a -> b`` (canonical order) is covered by two rays, from its point at 1/4
       towards ``b`` and from its point at 3/4 towards ``a``; they overlap, so a face
       through the middle is inside both. Embree returns the nearest face along each ray.
       That face either blocks the segment by the float64 rule (blocked), or contains the
       ray's target end in its plane and not the other end, and Embree met it at the ray's
       far end (its hit distance within ``_reach_tol`` of the ray's length: the ray reached
       the surface the end point lies on, nothing nearer blocks, this half is clear), or
       neither (a float32 graze, or a segment lying in or nearly in the face's plane, which
       the ray may graze short of its end: the segment is decided in float64 against the
       whole scene).

    No end is pulled in or lifted: a face within any distance of an end point is seen
    (down to float32 resolution), and an end lying on a face does not hit it.

    ``compiled``: with numba installed (``None``, the default, or ``True``) the work
    around each Embree call (steps 1-3, and the float64 test of each hit) runs as one
    compiled pass per ray (:mod:`wavepaths.raycast._numba`) instead of a dozen numpy
    passes; ``False`` runs the numpy reference. Both decide by the same float64 rule.

    ``direct``: with the compiled kernels, occlusion queries cast through Embree's C entry
    point from inside the compiled pass (:mod:`wavepaths.raycast.embree_c`,
    :func:`wavepaths.raycast._numba.occluded_direct`): both half-rays of a segment, their
    hits and verdicts in one loop, without the GIL. ``None`` (default): when Embree's
    library is found (embreex ships it); ``False``: through embreex's calls. The same
    verdicts, ray counts and fallbacks either way. On ``simple_street_canyon``, 96 ns per
    segment against 144-162 ns (300,000 random segments, one thread).

    ``bvh``: with the compiled kernels, occlusion queries walk a float64 tree of the scene's
    triangles instead (:mod:`wavepaths.raycast.bvh`,
    :func:`wavepaths.raycast._numba.occluded_bvh`): each segment is decided by the float64
    rule against the triangles whose padded boxes it meets, with no float32 step at all
    (a crossing next to a triangle's edge is decided as a half-ray's hit there is: by
    ``crosses`` on that triangle, then by the float64 test against the whole scene). ``None`` (default): for scenes of at most
    :data:`~wavepaths.raycast.bvh.BVH_MAX_TRIANGLES` (131,072) triangles, where the float32
    rays' misses are worth avoiding (the street canyon's path legs: 83 ns per segment against
    170 ns; munich's 285 ns against 370 ns, long segments across it 633 against 458 ns); ``True``: always;
    ``False``: never. Embree still answers :meth:`first_triangle` and :meth:`first_hits`
    (float32 hints, proved in float64 by their callers).
    """

    def __init__(self, scene: "Scene", batch: int = 1 << 20, compiled: bool | None = None,
                 direct: bool | None = None, bvh: bool | None = None) -> None:
        self._center = scene.center.copy()
        self._kernels = _compiled() if compiled is not False else None
        if compiled and self._kernels is None:
            raise ImportError("EmbreeRayCaster(compiled=True) needs numba (pip install 'wavepaths[fast]')")
        self._exact = ExactSegments(scene)
        self._batch = batch
        lo, hi = scene.bounds - self._center
        pad = 1e-6 * scene.diagonal + 1e-9
        self._lo, self._hi = lo - pad, hi + pad
        # how far short of a ray's end a hit may lie and still be "at the end": 64 float32
        # steps of the largest recentred coordinate
        self._reach_tol = np.float32(64 * np.finfo(np.float32).eps * max(float(np.abs(self._lo).max()),
                                                                          float(np.abs(self._hi).max()), 1e-9))
        self._scene = rtcore_scene.EmbreeScene()
        corners = (scene.vertices[scene.triangles] - self._center).astype(np.float32)
        self._mesh = TriangleMesh(self._scene, corners)
        # the occlusion queries' own scene, cast into from the compiled kernel (embree_c)
        self._direct = None
        if self._kernels is not None and direct is not False:
            from .embree_c import direct_scene

            self._direct = direct_scene(corners)
        if direct and self._direct is None:
            raise ImportError("EmbreeRayCaster(direct=True) needs numba and Embree's C library (embreex ships it)")
        # occlusion in float64 through a tree of the triangles (wavepaths.raycast.bvh)
        from .bvh import BVH_MAX_TRIANGLES, build_segment_bvh

        if bvh and self._kernels is None:
            raise ImportError("EmbreeRayCaster(bvh=True) needs numba (pip install 'wavepaths[fast]')")
        use_bvh = bvh if bvh is not None else len(scene.triangles) <= BVH_MAX_TRIANGLES
        self._bvh = build_segment_bvh(self._exact) if use_bvh and self._kernels is not None else None
        self._rays = 0
        self.exact_fallbacks = 0  # segments Embree (or the tree) could not decide, decided in float64

    def _threads(self, k: int) -> int:
        """Threads for an occlusion query of ``k`` segments: numba's thread count (1 in the
        coverage pool's workers, see :func:`wavepaths.search.kernels.set_threads`), one per
        ``THREAD_MIN_SEGMENTS`` segments; 1 off the main thread (tiles traced on several
        threads already share the cores)."""
        if (self._kernels is None or k < 2 * THREAD_MIN_SEGMENTS
                or threading.current_thread() is not threading.main_thread()):
            return 1  # (without numba, the parts run one after the other)
        from ..search import kernels

        return max(1, min(kernels.threads(), k // THREAD_MIN_SEGMENTS))

    @property
    def rays_cast(self) -> int:
        return self._rays

    @property
    def exact(self) -> ExactSegments:
        """The float64 rule this caster decides by (triangle planes, tolerances; recentred coordinates)."""
        return self._exact

    def first_triangle(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(k,) int64: the triangle Embree meets first on the way from ``a`` to ``b`` (metres), -1 if none.

        A float32 *hint*, not a decision: the face may merely graze the segment, touch
        its end, or a face within float32 resolution of ``a`` may be missed. Callers
        must prove whatever they conclude from it in float64 (see
        :mod:`wavepaths.search.visibility`).
        """
        a = np.asarray(a, dtype=np.float64).reshape(-1, 3) - self._center
        b = np.asarray(b, dtype=np.float64).reshape(-1, 3) - self._center
        prim = np.full(len(a), -1, dtype=np.int64)
        live = np.nonzero((a != b).any(axis=1))[0]
        if len(live):
            prim[live] = self._nearest(a[live], b[live])
        return prim

    def first_hits(self, origin: np.ndarray, direction: np.ndarray, far: float) -> np.ndarray:
        """(k,) int64: the triangle each ray ``origin + s direction``, ``0 < s <= far``, meets
        first, -1 if none (a float32 hint, like :meth:`first_triangle`, for ray launching:
        :mod:`wavepaths.search.launch`). Origins inside the scene's box; ``direction`` unit."""
        start = np.asarray(origin, dtype=np.float64).reshape(-1, 3) - self._center
        unit = np.ascontiguousarray(direction, dtype=np.float32).reshape(-1, 3)
        k = len(start)
        start32 = start.astype(np.float32)
        n = self._threads(k)

        def part(lo: int, hi: int) -> np.ndarray:
            prim = np.empty(hi - lo, dtype=np.int64)
            for s in range(lo, hi, self._batch):
                e = min(hi, s + self._batch)
                prim[s - lo:e - lo] = self._scene.run(start32[s:e], unit[s:e], dists=np.full(e - s, far, np.float32),
                                                      query="INTERSECT")
            return prim

        with _COUNT_LOCK:
            self._rays += k
        if n <= 1:
            return part(0, k)
        from concurrent.futures import ThreadPoolExecutor

        cuts = np.linspace(0, k, n + 1).astype(int)
        with ThreadPoolExecutor(max_workers=n) as pool:
            return np.concatenate(list(pool.map(lambda i: part(cuts[i], cuts[i + 1]), range(n))))

    def occluded(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        a = np.asarray(a, dtype=np.float64).reshape(-1, 3)
        b = np.asarray(b, dtype=np.float64).reshape(-1, 3)
        k = len(a)
        blocked = np.zeros(k, dtype=bool)
        if k == 0:
            return blocked
        if self._kernels is not None:
            n = self._threads(k)
            if n <= 1:
                return self._occluded_compiled(a, b)
            # Embree and the compiled set-up release the GIL: contiguous slices on n threads
            from concurrent.futures import ThreadPoolExecutor

            cuts = np.linspace(0, k, n + 1).astype(int)
            with ThreadPoolExecutor(max_workers=n) as pool:
                parts = list(pool.map(lambda i: self._occluded_compiled(a[cuts[i] : cuts[i + 1]],
                                                                        b[cuts[i] : cuts[i + 1]]), range(n)))
            return np.concatenate(parts)
        a, b, _ = canonical(a - self._center, b - self._center)
        d = b - a
        uncertain = np.zeros(k, dtype=bool)
        todo = np.nonzero((d != 0).any(axis=1))[0]
        for origin, target in ((a + 0.25 * d, b), (b - 0.25 * d, a)):
            sel = todo[~blocked[todo] & ~uncertain[todo]]
            if len(sel) == 0:
                break
            prim, reached = self._nearest(origin[sel], target[sel], with_reach=True)
            h = sel[prim >= 0]
            p, reached = prim[prim >= 0], reached[prim >= 0]
            confirmed = self._exact.crosses(a[h], b[h], p)
            blocked[h[confirmed]] = True
            h, p, reached = h[~confirmed], p[~confirmed], reached[~confirmed]
            # clear up to the target end only where the face holds the target end and not the
            # other one (a segment lying in the face's plane may graze it anywhere), and the
            # ray met it at the target end (a nearly coplanar one may graze it short of it)
            far = b if target is a else a
            clear = self._exact.in_plane(target[h], p) & ~self._exact.in_plane(far[h], p) & reached
            uncertain[h[~clear]] = True
        return self._decide_exact(a, b, np.nonzero(uncertain & ~blocked)[0], blocked)

    def occluded_legs(self, V: np.ndarray, alive: np.ndarray, i: int, j: int) -> np.ndarray:
        """:meth:`occluded` of the legs ``V[alive, i] -> V[alive, j]`` of chains ``V`` (k, s, 3).

        The same answers as ``occluded(V[alive, i], V[alive, j])``; with the compiled kernels
        on one thread, the ends are read from ``V`` where they are put in canonical order and
        recentred (:func:`wavepaths.raycast._numba.leg_canonical_recentred`), without the two
        gathered copies.
        """
        if self._kernels is None or self._threads(len(alive)) > 1:
            return self.occluded(V[alive, i], V[alive, j])
        if len(alive) == 0:
            return np.zeros(0, dtype=bool)
        V = np.ascontiguousarray(V, dtype=np.float64)
        alive = np.ascontiguousarray(alive, dtype=np.int64)
        return self._halves_core(*self._kernels.leg_canonical_recentred(V, alive, i, j, self._center))

    def _embree_first(self, start: np.ndarray, unit: np.ndarray, span: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n,) int32 and (n,) bool: the nearest triangle on each float32 ray (-1: none), and
        whether the ray met it at its far end (hit distance within ``_reach_tol`` of ``span``);
        in batches; counted."""
        prim = np.full(len(start), -1, dtype=np.int32)
        reached = np.zeros(len(start), dtype=bool)
        for s in range(0, len(start), self._batch):
            sl = slice(s, s + self._batch)
            # (embreex writes the hit distances into the `dists` buffer: a copy goes in)
            res = self._scene.run(start[sl], unit[sl], dists=span[sl].copy(), query="INTERSECT", output=1)
            prim[sl] = res["primID"]
            reached[sl] = res["tfar"] >= span[sl] - self._reach_tol
        with _COUNT_LOCK:
            self._rays += len(start)
        return prim, reached

    def _occluded_compiled(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """:meth:`occluded` with the set-up and the float64 confirmation compiled (same steps)."""
        return self._halves_core(*self._kernels.canonical_recentred(np.ascontiguousarray(a), np.ascontiguousarray(b),
                                                                     self._center))

    def _halves_core(self, A: np.ndarray, B: np.ndarray, live: np.ndarray) -> np.ndarray:
        """:meth:`_occluded_compiled` from the canonical, recentred ends ``A``, ``B`` and ``live``
        (the segments with length)."""
        if self._bvh is not None:
            return self._tree_core(A, B, live)
        if self._direct is not None:
            return self._halves_direct(A, B, live)
        K, ex = self._kernels, self._exact
        k = len(A)
        blocked = np.zeros(k, dtype=bool)
        uncertain = np.zeros(k, dtype=bool)
        todo = np.nonzero(live)[0]
        for second in (False, True):
            sel = todo[~blocked[todo] & ~uncertain[todo]] if second else todo
            if len(sel) == 0:
                break
            rows, start, unit, span = K.half_rays(A, B, sel, second, self._lo, self._hi)
            prim, reached = self._embree_first(start, unit, span)
            hit = prim >= 0
            seg, p = sel[rows[hit]], prim[hit].astype(np.int64)
            verdict = K.confirm_hits(A, B, seg, p, second, ex.normal, ex.offset, ex.tol, ex.inward,
                                     ex.inward_offset, ex.edge_tol, ex.box_lo, ex.box_hi, reached[hit])
            blocked[seg[verdict == 1]] = True
            uncertain[seg[verdict == 2]] = True
            near = verdict == 3  # a crossing next to a face's edge: the numpy test, with its graze check
            if near.any():
                s3, p3 = seg[near], p[near]
                confirmed = ex.crosses(A[s3], B[s3], p3)
                blocked[s3[confirmed]] = True
                s3, p3 = s3[~confirmed], p3[~confirmed]
                target, far = (A, B) if second else (B, A)
                uncertain[s3[~(ex.in_plane(target[s3], p3) & ~ex.in_plane(far[s3], p3))]] = True
        return self._decide_exact(A, B, np.nonzero(uncertain & ~blocked)[0], blocked)

    def _tree_core(self, A: np.ndarray, B: np.ndarray, live: np.ndarray) -> np.ndarray:
        """:meth:`_halves_core` through the float64 tree (``bvh``): the verdicts of
        :func:`wavepaths.raycast._numba.occluded_bvh`; a crossing next to a triangle's edge
        decided by ``crosses`` on that triangle, then, if it does not block, by the float64
        test against the whole scene (also a segment with an end that is not finite)."""
        t = self._bvh
        blocked = np.zeros(len(A), dtype=bool)
        sel = np.nonzero(live)[0]
        if len(sel) == 0:
            return blocked
        verdict, row = self._kernels.occluded_bvh(A, B, sel, t.box, t.first, t.count, t.right, t.rows, t.edge_tol,
                                                  t.slack)
        blocked[sel[verdict == 1]] = True
        near = (verdict == 3) & (row >= 0)  # a crossing next to a triangle's edge, as the half-rays' 3
        return self._decide_edges(A, B, sel[near], t.triangle[row[near]], sel[(verdict == 3) & (row < 0)], blocked)

    def _halves_direct(self, A: np.ndarray, B: np.ndarray, live: np.ndarray) -> np.ndarray:
        """:meth:`_halves_core` in one compiled pass that casts through Embree's C entry point
        (:func:`wavepaths.raycast._numba.occluded_direct`): the same half-rays, hits and
        float64 verdicts, without the GIL and without the float32 buffers and the second
        pass's selection. A crossing next to a face's edge (verdict 3) goes to the numpy
        ``crosses`` as in :meth:`_halves_core`; if that does not confirm it, both ends lie
        off the face's plane, so the segment is undecided there too: to the float64 test."""
        ex, d = self._exact, self._direct
        blocked = np.zeros(len(A), dtype=bool)
        sel = np.nonzero(live)[0]
        if len(sel) == 0:
            return blocked
        verdict, face, rays = self._kernels.occluded_direct(
            A, B, sel, self._lo, self._hi, self._reach_tol, np.uint64(d.intersect), np.uint64(d.scene), ex.normal,
            ex.offset, ex.tol, ex.inward, ex.inward_offset, ex.edge_tol, ex.box_lo, ex.box_hi)
        with _COUNT_LOCK:
            self._rays += int(rays)
        blocked[sel[verdict == 1]] = True
        return self._decide_edges(A, B, sel[verdict == 3], face[verdict == 3], sel[verdict == 2], blocked)

    def _decide_edges(self, A: np.ndarray, B: np.ndarray, seg: np.ndarray, face: np.ndarray, rest: np.ndarray,
                      blocked: np.ndarray) -> np.ndarray:
        """``blocked`` with the segments ``seg``, each crossing triangle ``face`` next to one of
        its edges, decided by the numpy ``crosses`` on that triangle (with its graze check), and
        those it does not confirm, with ``rest``, by :meth:`_decide_exact`."""
        if len(seg):
            confirmed = self._exact.crosses(A[seg], B[seg], face)
            blocked[seg[confirmed]] = True
            rest = np.concatenate([rest, seg[~confirmed]])
        return self._decide_exact(A, B, rest, blocked)

    def _decide_exact(self, A: np.ndarray, B: np.ndarray, rest: np.ndarray, blocked: np.ndarray) -> np.ndarray:
        """``blocked`` with the segments ``rest`` (that Embree's hits left undecided) decided
        in float64 against the whole scene, and counted."""
        if len(rest):
            with _COUNT_LOCK:
                self.exact_fallbacks += len(rest)
            blocked[rest] = self._exact.blocked(A[rest], B[rest])
        return blocked

    def _nearest_compiled(self, origin: np.ndarray, target: np.ndarray) -> np.ndarray:
        """:meth:`_nearest` with the clipping compiled (:func:`wavepaths.raycast._numba.segment_rays`),
        on numba's threads for large queries (see :meth:`occluded`); with the direct scene, the
        rays are cast from the compiled pass too (:func:`wavepaths.raycast._numba.nearest_direct`:
        the same float32 rays, the same triangles)."""
        k = len(origin)
        n = self._threads(k)
        origin = np.ascontiguousarray(origin, dtype=np.float64)
        target = np.ascontiguousarray(target, dtype=np.float64)
        d = self._direct

        def part(lo: int, hi: int) -> np.ndarray:
            if d is not None:
                prim, rays = self._kernels.nearest_direct(origin[lo:hi], target[lo:hi], self._lo, self._hi,
                                                          np.uint64(d.intersect), np.uint64(d.scene))
                with _COUNT_LOCK:
                    self._rays += int(rays)
                return prim
            rows, start, unit, span = self._kernels.segment_rays(origin[lo:hi], target[lo:hi], self._lo, self._hi)
            prim = np.full(hi - lo, -1, dtype=np.int64)
            for s in range(0, len(rows), self._batch):
                res = self._scene.run(start[s : s + self._batch], unit[s : s + self._batch],
                                      dists=span[s : s + self._batch], query="INTERSECT")
                prim[rows[s : s + self._batch]] = res
            with _COUNT_LOCK:
                self._rays += len(rows)
            return prim

        if n <= 1:
            return part(0, k)
        from concurrent.futures import ThreadPoolExecutor

        cuts = np.linspace(0, k, n + 1).astype(int)
        with ThreadPoolExecutor(max_workers=n) as pool:
            return np.concatenate(list(pool.map(lambda i: part(cuts[i], cuts[i + 1]), range(n))))

    def _nearest(self, origin: np.ndarray, target: np.ndarray, with_reach: bool = False):
        """(k,) int: the triangle Embree hits first on the way from ``origin`` to ``target`` (recentred), -1 if none.

        ``with_reach``: also (k,) bool, whether the hit lies at ``target`` (its float32 distance
        within ``_reach_tol`` of the clipped ray's length; numpy form only)."""
        if self._kernels is not None and not with_reach:
            return self._nearest_compiled(origin, target)
        d = target - origin
        length = np.sqrt(np.einsum("ij,ij->i", d, d))
        unit = d / np.where(length > 0, length, 1.0)[:, None]
        t0 = np.zeros(len(origin))
        t_end = length.copy()
        # slab clipping of [0, length] against the box, for the rays with an end outside it
        # (interaction points lie on the scene's faces: most rays need none)
        outside = ~(((origin >= self._lo) & (origin <= self._hi)).all(axis=1)
                    & ((target >= self._lo) & (target <= self._hi)).all(axis=1))
        if outside.any():
            o, u = origin[outside], unit[outside]
            with np.errstate(divide="ignore", invalid="ignore"):
                inv = 1.0 / u
                t1 = (self._lo - o) * inv
                t2 = (self._hi - o) * inv
            near_t, far_t = np.minimum(t1, t2), np.maximum(t1, t2)
            tmin = np.max(np.where(np.isfinite(near_t), near_t, -np.inf), axis=1)
            tmax = np.min(np.where(np.isfinite(far_t), far_t, np.inf), axis=1)
            inside_box = (((o >= self._lo) & (o <= self._hi)) | (u != 0)).all(axis=1)
            t0[outside] = np.where(inside_box, np.maximum(tmin, 0.0), 0.0)
            t_end[outside] = np.where(inside_box, np.minimum(tmax, length[outside]), 0.0)
        live = np.nonzero(t_end > t0)[0]
        prim = np.full(len(origin), -1, dtype=np.int64)
        reached = np.zeros(len(origin), dtype=bool)
        start = origin + t0[:, None] * unit
        span = t_end - t0
        for s in range(0, len(live), self._batch):
            sel = live[s : s + self._batch]
            span32 = span[sel].astype(np.float32)
            res = self._scene.run(
                start[sel].astype(np.float32),
                unit[sel].astype(np.float32),
                dists=span32.copy(),  # embreex writes the hit distances into it
                query="INTERSECT",
                output=1,
            )
            prim[sel] = np.asarray(res["primID"], dtype=np.int64)
            reached[sel] = res["tfar"] >= span32 - self._reach_tol
        self._rays += len(live)
        return (prim, reached) if with_reach else prim

    def __getstate__(self) -> dict:  # Embree handles do not pickle: rebuild on the worker
        raise TypeError("EmbreeRayCaster is rebuilt per process from its Scene; pickle the Scene instead")
