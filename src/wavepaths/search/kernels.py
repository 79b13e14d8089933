"""Optional compiled kernels (numba) for the densest loops of the path search.

The numpy code is the reference. The loops here are outer products whose numpy form
materialises large temporaries per chunk (on this machine a fresh array costs about 12 ns
per element in page faults alone); here each runs pair by pair, with the same tests and
margins and an early exit:

* :func:`receiver_pairs`: the receiver side of the diffraction search, (receiver images x
  dihedra) (:func:`wavepaths.search.end_sides._receiver_side`; on ``etoile_crop`` at depth 3,
  600 M pairs at about 54 ns each in numpy, about 6 ns here), with one more test, the
  beams through the image's mirrors' rectangles (:func:`chain_side_planes`);
* :func:`reflection_pairs`: the reflection candidates, (receiver clusters x chain-beam
  tree) (:func:`wavepaths.search.beams.beams_reaching` and the per-receiver point test);
* :func:`reflection_pairs_flat`: the same candidates for scattered receivers, every
  (chain, receiver) pair with the point test alone (no tree);
* :func:`chains_meeting_edges`: (image chains x edge tree)
  (:func:`wavepaths.search.beams.chains_meeting_edges`).

More compiled loops, called from their modules with the numpy reference beside them:
the image trees' exact tests (``_numba.admissible``, :mod:`wavepaths.search.images`), the
receiver side's frame and sector lookup (``_numba.end_sides``,
:mod:`wavepaths.search.end_sides`; also the sector of the transmitter's (image, edge) pairs,
:mod:`wavepaths.search.context`), the images' aperture windows and the shadow intervals of
the visibility windows (:mod:`wavepaths.search._numba_windows`,
:mod:`wavepaths.search.visibility`), the join of the two sides with the closed-form
point (``_numba.joined_candidates``, :mod:`wavepaths.search.diffraction`), the Keller-cone
culling of the sources per chunk of receivers (``_numba.keller_cone_keep``, same module),
the back-traces of the image method (``_numba.backtrace``, :mod:`wavepaths.search.images`),
the proof that a mirror is hidden from a source (``_numba_mirrors.behind``,
:mod:`wavepaths.search.mirror_visibility`), and the tolerance of coverage maps: the
diffracted candidates' amplitude bounds (``_numba_tolerance.amplitude_bounds``,
:mod:`wavepaths.search.diffraction`) and the choice of those dropped
(``_numba_tolerance.tolerance_drop``, :mod:`wavepaths.coverage.solver`).

numba is an optional dependency (the ``fast`` extra). Without it, or with
``TraceOptions(compiled=False)``, the numpy reference runs and finds the same paths.
Kernel and reference agree pair for pair except where a quantity lands within rounding
(~1e-16 relative) of a test's margin (tests/search/test_kernels.py and
tests/stress/test_stress_compiled.py compare them). The numba code is in
:mod:`wavepaths.search._numba` (with the window loops in ``_numba_windows`` and the
hidden-mirror proofs in ``_numba_mirrors``), compiled on first use and cached by numba (once per
machine; :func:`warm_up` does it ahead).
"""

from __future__ import annotations

import threading
from functools import lru_cache
from typing import Callable, Iterator

import numpy as np


CACHE_LOCK = threading.RLock()
"""Held while a query builds a cache it shares with other tiles (the chain-beam trees and
the compiled queries' arrays, built on first use): :func:`wavepaths.search.trace` may run
tiles on several threads."""

PARALLEL_MIN_PAIRS = 1 << 17
"""Pairs below which a kernel runs on the calling thread: starting the threads costs more
than they save on small calls (the street-canyon map ran 1.3x slower with them at a few
thousand pairs per call; from 2^17 pairs, about 0.5 ms of work, they pay: etoile_crop's
Morton-ordered chunks of receiver images, most of them below the former 2^20)."""


@lru_cache(maxsize=1)
def _compiled():
    """The compiled kernels, or ``None`` when numba is not installed."""
    try:
        from . import _numba
    except ImportError:
        return None

    from . import _numba_reach

    return {"receiver_pairs": _numba.receiver_pairs, "receiver_pairs_serial": _numba.receiver_pairs_serial,
            "receiver_pairs_listed": _numba_reach.receiver_pairs_listed,
            "receiver_pairs_listed_serial": _numba_reach.receiver_pairs_listed_serial,
            "mirror_reach_counts": _numba_reach.mirror_reach_counts, "mirror_reach_fill": _numba_reach.mirror_reach_fill,
            "chain_side_planes": _numba.chain_side_planes, "reflection_pairs": _numba.reflection_pairs,
            "chains_edges": _numba.chains_edges, "reflection_pairs_flat": _numba.reflection_pairs_flat}


def threads() -> int:
    """How many threads the compiled kernels may use (numba's setting; 1 without numba)."""
    if _compiled() is None:
        return 1
    import numba

    return int(numba.get_num_threads())


def set_threads(n: int) -> None:
    """Let the compiled kernels use ``n`` threads (e.g. 1 in each worker of a process pool)."""
    if _compiled() is not None:
        import numba

        numba.set_num_threads(max(1, min(int(n), numba.config.NUMBA_NUM_THREADS)))


def in_threads(fn: Callable, items: list, n: int) -> Iterator:
    """``fn(item)`` for each item, in order, on up to ``n`` threads (for kernels that release
    the GIL); at most ``2 n`` results are computed ahead of the consumer."""
    if n <= 1 or len(items) <= 1:
        for it in items:
            yield fn(it)
        return
    from collections import deque
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=n) as pool:
        pending: deque = deque()
        for it in items:
            pending.append(pool.submit(fn, it))
            if len(pending) >= 2 * n:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()


def warm_up() -> bool:
    """Compile every kernel now (numba caches them: once per machine), so that the first
    query does not pay for it (about 12 s). ``scripts/setup.sh`` calls it. Returns whether
    numba is installed."""
    if _compiled() is None:
        return False
    from ..scene import load_scene
    from .options import TraceOptions
    from .trace import trace

    scene = load_scene("street_canyon")
    rx = np.array([[20.0, 0.0, 1.5], [60.0, 5.0, 1.5], [-20.0, 30.0, 1.5]])
    opts = TraceOptions(max_reflections=2, diffraction=True, diffraction_reflections=2)
    trace(scene, np.array([[-60.0, 0.0, 10.0]]), rx, opts)  # scattered receivers: the flat reflection query
    g = np.linspace(-2.0, 2.0, 8)
    grid = np.stack(np.meshgrid(g + 20.0, g, [1.5], indexing="ij"), axis=-1).reshape(-1, 3)
    trace(scene, np.array([[-60.0, 0.0, 10.0]]), grid, opts)  # clustered receivers: the tree query
    z3 = np.zeros((2, 3))
    frame = (z3, z3, z3, z3)
    receiver_pairs(z3, None, z3, z3, None, None, z3, frame, None, parallel=True)
    one = np.zeros(2, np.int64)  # two images on polygon 0, whose list holds dihedron 0 (column 0)
    receiver_pairs(z3, None, z3, z3, None, None, z3, frame, None, parallel=True,
                   listed=(one, np.array([0, 1]), np.zeros(1, np.int64), np.zeros(1, np.int64)))
    # the tolerance of coverage maps (TraceOptions.tolerance_db): the candidates' amplitude
    # bounds and the choice of the dropped ones
    from . import _numba_tolerance

    z = np.zeros(2)
    _numba_tolerance.amplitude_bounds(z, z, z + 1.5, z, z + 1.0, z, z + 1.0, z, 1.0, 1e-6, 1e-6)
    _numba_tolerance.tolerance_drop(one, z.copy(), z.copy(), 0.1, 1)
    return True


def available() -> bool:
    """Whether the compiled kernels can run (numba is installed)."""
    return _compiled() is not None


def chain_side_planes(apex: np.ndarray, polys: np.ndarray, quads: np.ndarray, normal: np.ndarray,
                      offset: np.ndarray) -> np.ndarray:
    """(E, 4k, 3) float64: the side planes of the beams from each chain's last image through its mirrors' rectangles.

    :func:`wavepaths.search.apertures.chain_apertures` (each rectangle mirrored forward across
    the later mirrors) then :func:`wavepaths.search.apertures.quad_side_planes` (inward unit
    normals; a zero normal for a degenerate plane), per chain without temporaries.

    Parameters
    ----------
    apex : (E, 3) float64
        The chains' last images [m].
    polys : (E, k) int64
        The chains' mirrors, in chain order.
    quads : (p, 4, 3) float64, normal : (p, 3) float64, offset : (p,) float64
        The scene's polygon rectangles (:func:`wavepaths.search.apertures.polygon_quads`) and planes.
    """
    E, k = polys.shape
    out = np.empty((E, 4 * k, 3))
    c = np.ascontiguousarray
    _compiled()["chain_side_planes"](c(apex, dtype=np.float64), c(polys, dtype=np.int64), c(quads), c(normal),
                                     c(offset), out)
    return out


def flat_beams(level, beams) -> dict:
    """The arrays of a :class:`~wavepaths.search.beams.ChainBeams` tree as the compiled query
    reads them (node levels concatenated), built once and kept in ``beams.flat``."""
    flat = beams.flat
    with CACHE_LOCK:
        if "polys" not in flat:
            flat["node_c"], flat["node_r"], flat["level_off"] = tree_arrays(beams.apex)
            flat["through_c"] = np.ascontiguousarray(np.stack([np.concatenate(t.centre) for t in beams.through]))
            flat["through_r"] = np.ascontiguousarray(np.stack([np.concatenate(t.radius) for t in beams.through]))
            flat["last_image"] = np.ascontiguousarray(level.images[:, -1])
            flat["polys"] = np.ascontiguousarray(level.polygons, dtype=np.int64)  # set last: the others are ready
    return flat


def reflection_pairs(scene, level, beams, apertures, clusters, rx: np.ndarray, first: int, last: int,
                     point_test: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(receiver, chain) pairs of clusters ``first .. last - 1`` whose chains' last legs can reach them.

    The compiled :func:`wavepaths.search.beams.beams_reaching` followed by the per-receiver
    point test of :func:`wavepaths.search.beams.reflection_candidates`: the descent of the
    :class:`~wavepaths.search.beams.ChainBeams` tree with the same node test, then per
    (cluster, chain) the beyond-the-mirror test, the sphere beams and the rectangles'
    planes, then each of the cluster's receivers as a point; the same margins.

    Parameters
    ----------
    scene : Scene
    level : ImageLevel
        The chains (order >= 1) ``beams`` was built from.
    beams : ChainBeams
    apertures : Apertures
    clusters : (members (n,), start (g + 1,), centre (g, 3), radius (g,))
        :func:`wavepaths.search.beams.point_clusters` of ``rx``.
    rx : (n, 3) float64
        Receivers [m].
    first, last : int
        The clusters to query.
    point_test : bool
        Test each receiver as a point (else every receiver of a passing cluster is kept).

    Returns
    -------
    receivers, chains : (k,) int64
        Rows of ``rx`` and of ``level``, grouped by cluster.
    """
    from .spheres import NODE_ANGLE_SLACK

    members, start, centre, radius = clusters
    flat = flat_beams(level, beams)
    c = np.ascontiguousarray
    return _compiled()["reflection_pairs"](
        c(centre[first:last]), c(radius[first:last]), c(members, dtype=np.int64), c(start[first:last + 1], dtype=np.int64),
        c(rx, dtype=np.float64), bool(point_test), c(beams.apex.items, dtype=np.int64), flat["node_c"], flat["node_r"],
        flat["through_c"], flat["through_r"], flat["level_off"], int(beams.apex.leaf_size), int(beams.apex.branch),
        float(NODE_ANGLE_SLACK), flat["last_image"], flat["polys"], c(beams.centre), c(beams.radius), c(apertures.quads),
        c(scene.polygon_normal), c(scene.polygon_offset), float(scene.length_tolerance(1e-9)),
    )


def reflection_pairs_flat(scene, level, lazy, apertures, rx: np.ndarray, first: int,
                          last: int) -> tuple[np.ndarray, np.ndarray]:
    """(receiver, chain) pairs of chains ``first .. last - 1`` whose last legs can reach them, without the tree.

    The per-receiver point test of :func:`reflection_pairs` alone, over every (chain,
    receiver) pair: the receiver beyond the chain's last mirror and inside the side planes
    of the beams through its mirrors' rectangles, with the same margins. For receivers too
    scattered to share a tree query, it costs about 11 ns per pair against some 20 ms per
    receiver for the descent of a 660 k-chain tree (``etoile_crop``, order 3). It keeps a
    superset of :func:`reflection_pairs`'s pairs (that one also tests bounding spheres); the
    back-trace decides both alike.

    The chains' side planes, last images and last mirrors' sides are computed once per
    level and kept in ``lazy.flat`` (the level's :class:`~wavepaths.search.beams.LazyChainBeams`).

    Returns
    -------
    receivers, chains : (k,) int64
        Rows of ``rx`` and of ``level``, grouped by chain.
    """
    flat = flat_chain_planes(scene, level, lazy, apertures)
    return _compiled()["reflection_pairs_flat"](
        np.ascontiguousarray(rx, dtype=np.float64), flat["last_image"], flat["side"], flat["mirror"], flat["planes"],
        np.ascontiguousarray(scene.polygon_normal), np.ascontiguousarray(scene.polygon_offset),
        float(scene.length_tolerance(1e-9)), int(first), int(last))


def flat_chain_planes(scene, level, lazy, apertures) -> dict:
    """The per-chain arrays of :func:`reflection_pairs_flat` (last images (E, 3), last mirrors
    (E,), the side of the last image on them (E,), the side planes (E, 4k, 3)), built once per
    level and kept in ``lazy.flat``; call it before threads read them."""
    flat = lazy.flat
    with CACHE_LOCK:
        if "planes" not in flat:
            last = np.ascontiguousarray(level.images[:, -1])
            mirror = np.ascontiguousarray(level.polygons[:, -1], dtype=np.int64)
            n, d = scene.polygon_normal[mirror], scene.polygon_offset[mirror]
            flat["side"] = np.sign(np.einsum("ij,ij->i", last, n) - d)
            flat["mirror"] = mirror
            flat["last_image"] = last
            flat["planes"] = chain_side_planes(last, level.polygons, apertures.quads, scene.polygon_normal,
                                               scene.polygon_offset)  # set last: the others are ready
    return flat


def chains_meeting_edges(scene, level, apertures, tree, rows: np.ndarray,
                         tree_flat: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(chain, dihedron) pairs of chains ``rows`` of ``level`` (order >= 1) whose last leg can end on the edge.

    The compiled :func:`wavepaths.search.beams.chains_meeting_edges` for one block of
    chains: per chain its bounding planes (beyond the last mirror, the side planes of the
    beams through its apertures' rectangles), one descent of the edge tree ``tree`` with the
    same node test, then per edge the segment test on the planes and the cones through the
    apertures' spheres; the same margins.

    ``tree_flat``: :func:`tree_arrays` of ``tree``, when the caller queries it block by block.

    Returns
    -------
    chains : (b,) int64
        Rows of ``level`` (from ``rows``).
    dihedra : (b,) int64
        The tree's items (dihedron ids).
    """
    c = np.ascontiguousarray
    if tree_flat is None:
        tree_flat = tree_arrays(tree)
    dih = scene.dihedra
    ci, e = _compiled()["chains_edges"](
        c(level.last[rows]), c(level.polygons[rows], dtype=np.int64), c(apertures.centre), c(apertures.radius),
        c(scene.polygon_normal), c(scene.polygon_offset), c(apertures.quads), c(tree.items, dtype=np.int64),
        tree_flat[0], tree_flat[1], tree_flat[2], int(tree.leaf_size), int(tree.branch),
        c(dih.origin), c(dih.direction), c(dih.length), float(scene.length_tolerance(1e-9)),
    )
    return rows[ci], e


def tree_arrays(tree) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A :class:`~wavepaths.search.spheres.SphereTree`'s node levels concatenated: centres
    (N, 3), radii (N,) and each level's first node (depth + 1,)."""
    return (np.ascontiguousarray(np.concatenate(tree.centre)), np.ascontiguousarray(np.concatenate(tree.radius)),
            np.concatenate([[0], np.cumsum([len(r) for r in tree.radius])]).astype(np.int64))


def receiver_pairs(
    I: np.ndarray,
    mirror: tuple[np.ndarray, np.ndarray, np.ndarray, float] | None,
    A: np.ndarray,
    B: np.ndarray,
    beam: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None,
    aperture: tuple[np.ndarray, float] | None,
    R: np.ndarray,
    frame: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    window: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float] | None,
    parallel: bool | None = None,
    listed: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, int, int, int, int, int]:
    """The dense receiver-side tests of :func:`wavepaths.search.end_sides._receiver_side`, fused per pair.

    Parameters
    ----------
    I : (E, 3) float64
        The receiver images, recentred on the scene centre [m].
    mirror : (n (E, 3), off (E,), side (E,), plane_tol) or None
        The images' last mirror planes (recentred offsets) and the side of the previous
        image: a pair passes if an edge end lies on that side, within ``plane_tol`` [m].
    A, B : (D, 3) float64
        The edges' ends, recentred [m].
    beam : (to_q (E, 3), dist_q (E,), radius_q (E,), M (D, 3), h (D,)) or None
        The bounding-sphere beam: from each image to its last mirror's sphere (centre
        offset ``to_q``, distance, radius) against each edge's sphere (recentred midpoint
        ``M``, half-length ``h``); the angular test with a 1e-9 rad margin.
    aperture : (planes (E, P, 3), tol) or None
        The side planes of the beams through the images' mirrors' rectangles
        (:func:`wavepaths.search.apertures.quad_side_planes`, inward unit normals through the
        image): a pair passes unless both edge ends lie outside one plane by more than
        ``1e-9`` of their distance to the image plus ``tol`` [m]
        (:func:`wavepaths.search.apertures.chain_beams_meet`'s segment test).
    R : (E, 3) float64
        The same images in scene coordinates [m] (for the Keller window, in the edge frame).
    frame : (origin, direction, x_hat, y_hat), each (D, 3)
        The edges' frames (:func:`wavepaths.search.end_sides._edge_frame`).
    window : (v_lo, lo, v_hi, hi (D,), keller_tol) or None
        The Keller window of each edge (:func:`wavepaths.search.end_sides._keller_window`,
        indexed by these D edges) and its margin [m].
    parallel : bool, optional
        Run blocks of images on the kernels' threads; default: for calls of at least
        :data:`PARALLEL_MIN_PAIRS` pairs when there are threads.
    listed : (q (E,), ptr, dihedra, col_of) or None
        Test each image only against the edges of its last mirror's reach list
        (:class:`~wavepaths.search.reach.MirrorReach`: ``dihedra[ptr[q]:ptr[q + 1]]``),
        those of them that are among the D edges (``col_of`` maps a dihedron to its column,
        -1 for none); the same tests, in the same order, on those pairs: the images grouped
        by last mirror and side of it, the mirror-side test once per group and edge, the
        edges that pass gathered once per group
        (:func:`wavepaths.search._numba_reach.receiver_pairs_listed`).

    Returns
    -------
    rows, cols : (k,) int64
        The pairs (image row, edge column) that pass every test given, row by row.
    rejected_mirror_side, rejected_beam, rejected_aperture, rejected_keller_window : int
        How many pairs each test rejected (each pair counted by the first test it fails, in
        this order).
    tested : int
        How many pairs the tests saw: ``E * D``, or with ``listed`` the listed ones.
    """
    E, D = len(I), len(A)
    if listed is not None:
        size = listed[1][listed[0] + 1] - listed[1][listed[0]]  # each image's list length
    if parallel is None:
        # numba's default threading layer (workqueue) must not be entered from two threads at
        # once: only the main thread starts the parallel kernel (a Dask worker's task threads
        # run the serial one)
        work = E * D if listed is None else int(size.sum())
        parallel = (work >= PARALLEL_MIN_PAIRS and threads() > 1
                    and threading.current_thread() is threading.main_thread())
    name = "receiver_pairs" if listed is None else "receiver_pairs_listed"
    k = _compiled()[name if parallel else name + "_serial"]
    z1 = np.zeros(D)
    if mirror is None:
        n, off, side, plane_tol = np.zeros((E, 3)), np.zeros(E), np.zeros(E), 0.0
    else:
        n, off, side, plane_tol = mirror
    to_q, dist_q, radius_q, M, h = beam if beam is not None else (np.zeros((E, 3)), np.zeros(E), np.zeros(E),
                                                                   np.zeros((D, 3)), np.zeros(D))
    planes, aperture_tol = aperture if aperture is not None else (np.zeros((E, 0, 3)), 0.0)
    v_lo, lo, v_hi, hi, keller_tol = window if window is not None else (z1, z1, z1, z1, 0.0)
    origin, direction, x_hat, y_hat = frame
    cnt = np.empty(E, dtype=np.int64)
    counts = np.zeros((E, 5), dtype=np.int64)
    c = np.ascontiguousarray

    def t(x):  # per-edge arrays transposed, (3, D)
        return np.ascontiguousarray(np.asarray(x).T)

    args = (c(I), c(n), c(off), c(side), t(A), t(B), float(plane_tol), mirror is not None,
            c(to_q), c(dist_q), c(radius_q), t(M), c(h), beam is not None, c(planes), float(aperture_tol),
            c(R), t(origin), t(direction), t(x_hat), t(y_hat), c(v_lo), c(lo), c(v_hi), c(hi),
            float(keller_tol), window is not None)
    if listed is None:
        out_j = np.empty((E, D), dtype=np.int32)
        k(*args, out_j, cnt, counts)
        rows = np.repeat(np.arange(E), cnt)
        cols = out_j[rows, np.arange(len(rows)) - np.repeat(np.cumsum(cnt) - cnt, cnt)].astype(np.int64)
        tested = E * D
    else:
        q, ptr, idx, col_of = listed
        start = np.cumsum(size) - size
        out_j = np.empty(max(int(size.sum()), 1), dtype=np.int32)
        # the images in groups of one last mirror and one side of it (side = +-1: the image
        # trees keep a parent image only off its mirror's plane)
        key = 2 * q + (np.asarray(side) < 0) if mirror is not None else 2 * q
        order = np.argsort(key, kind="stable")
        gkey, gfirst = np.unique(key[order], return_index=True)
        gq = gkey // 2
        gstart = np.append(gfirst, E)
        # (numba's default static split of the groups between threads: handing them out four at
        # a time made no difference on munich's strip, 4.6-5.3 s either way)
        k(*args, order.astype(np.int64), gstart.astype(np.int64), c(gq, dtype=np.int64), c(ptr, dtype=np.int64),
          c(idx, dtype=np.int64), c(col_of, dtype=np.int64), start.astype(np.int64), out_j, cnt, counts)
        rows = np.repeat(np.arange(E), cnt)
        cols = out_j[start[rows] + np.arange(len(rows)) - np.repeat(np.cumsum(cnt) - cnt, cnt)].astype(np.int64)
        tested = int(counts[:, 4].sum())
    n = counts.sum(axis=0)
    return rows, cols, int(n[0]), int(n[1]), int(n[2]), int(n[3]), tested
