"""Beam culling per receiver tile: which chains, receivers and edges a reflected chain's last leg can reach.

Built on :mod:`wavepaths.search.spheres` (bounding-sphere beams and trees) and
:mod:`wavepaths.search.apertures` (the mirrors' rectangles). Uses:

* per receiver tile (:func:`reflection_candidates`): the chains whose last leg can reach
  a cluster of receivers, from a tree over the chains' beams (:class:`ChainBeams`), then
  per receiver; the last leg must pass through the rectangles of all the chain's mirrors,
  unfolded (:func:`~wavepaths.search.apertures.chain_apertures`,
  :func:`~wavepaths.search.apertures.chain_beams_meet`);
* diffraction after reflections (:func:`chains_meeting_edges`): the edges a chain's last
  leg can end on, from a tree over the edges (:func:`edge_tree`).

The image tree (:func:`~wavepaths.search.images.build_image_levels`) queries a
:class:`~wavepaths.search.spheres.SphereTree` of the mirrors with the same beams.
Every test keeps a margin above rounding, so none drops a valid path.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Iterator

import numpy as np

from . import kernels
from .apertures import Apertures, chain_apertures, chain_beams_meet, quad_side_planes
from .spheres import NODE_ANGLE_SLACK, SphereTree, beam_meets_spheres, build_sphere_tree, morton_order, query_tree

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene
    from .context import TxContext
    from .images import ImageLevel


# ---- trees over the beams of image chains --------------------------------------------


@dataclass(frozen=True)
class ChainBeams:
    """A tree over the last-leg beams of one order's image chains.

    The chains are laid out in (6-D) Morton order of their last image and their last
    mirror's centre; ``apex`` bounds the last images of the chains below each node and
    ``through[j]`` their ``j``-th apertures' spheres, with one node structure.

    Attributes
    ----------
    apex : SphereTree
        Items are chain rows of the level; item spheres have radius 0.
    through : list of SphereTree
        One per aperture ``j = 0 .. k - 1`` (``k - 1``: the last mirror itself).
    centre : (m, k, 3) float64, radius : (m, k) float64
        Per chain (level row), its apertures' spheres (:func:`chain_apertures`) [m], kept
        for the per-pair tests of :func:`beams_reaching`.
    """

    apex: SphereTree
    through: list[SphereTree]
    centre: np.ndarray
    radius: np.ndarray
    flat: dict = field(default_factory=dict, compare=False, repr=False)  # the compiled query's flat arrays, built once


@dataclass
class LazyChainBeams:
    """The :class:`ChainBeams` of one reflection order, built on first use.

    The tree costs about as much to build as a few hundred tree queries save: a query of
    scattered receivers (:data:`FLAT_MAX_CLUSTER_SIZE`) tests every chain instead and never
    builds it (``etoile_crop`` at order 3: 1.0 s of the context). ``flat`` holds the
    flat query's arrays (:func:`~wavepaths.search.kernels.flat_chain_planes`), built once;
    the tree's compiled arrays are in the tree's own ``flat``.
    """

    tree: ChainBeams | None = None
    flat: dict = field(default_factory=dict, compare=False, repr=False)

    def get(self, scene: "Scene", level: "ImageLevel", apertures: Apertures) -> ChainBeams:
        """The tree, built now if it was not (the same one for every later call, from any thread)."""
        with kernels.CACHE_LOCK:
            if self.tree is None:
                self.tree = build_chain_beams(scene, level, apertures.centre, apertures.radius)
        return self.tree


def build_chain_beams(
    scene: "Scene", level: "ImageLevel", centre: np.ndarray, radius: np.ndarray, block: int = 1 << 20
) -> ChainBeams:
    """The :class:`ChainBeams` of ``level`` (order >= 1), from the polygon spheres ``centre``, ``radius``."""
    m, k = len(level), level.order
    cen = np.empty((m, k, 3))
    rad = np.empty((m, k))
    for s in range(0, m, block):
        rows = np.arange(s, min(m, s + block))
        cen[rows], rad[rows], _ = chain_apertures(scene, level, rows, centre, radius)
    # nearby chains: close last images and close last mirrors (6-D Morton order)
    order = morton_order(np.concatenate([level.last, cen[:, -1]], axis=1))
    ids = np.arange(m, dtype=np.int64)
    apex = build_sphere_tree(level.last, np.zeros(m), ids, order=order)
    # one node structure: the aperture trees share the apex tree's item array
    through = [replace(build_sphere_tree(cen[:, j], rad[:, j], ids, order=order), items=apex.items) for j in range(k)]
    return ChainBeams(apex, through, cen, rad)


def beams_reaching(
    scene: "Scene", level: "ImageLevel", beams: ChainBeams, apertures: Apertures, centre: np.ndarray,
    radius: np.ndarray, budget: int = 1 << 16,
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """(target, chain) pairs whose last leg can reach the target sphere ``(centre, radius)``.

    Parameters
    ----------
    scene : Scene
    level : ImageLevel
        The chains (order >= 1) that ``beams`` was built from.
    beams : ChainBeams
    apertures : Apertures
    centre : (t, 3) float64, radius : (t,) float64
        Target spheres [m] (e.g. clusters of receivers).
    budget : int
        (target, node) pairs tested at once.

    Yields
    ------
    targets : (b,) int64, chains : (b,) int64
        Blocks of pairs that pass, in order of cost: the target reaches beyond the last
        mirror; it meets the cone from the last image through each aperture's sphere
        (:func:`beam_meets_spheres`); :func:`chain_beams_meet` (rectangles).

    Notes
    -----
    A node whose chains have last images within ``rho`` of ``a0`` is tested by moving every
    chain's apex to ``a0``: a ray from an apex ``a`` through the apertures to the target,
    translated by ``a0 - a`` (at most ``rho``), starts at ``a0`` and passes within ``rho`` of
    each aperture sphere and of the target. So the node passes
    :func:`beam_meets_spheres` from ``a0`` with every aperture sphere (the node's) and the
    target grown by ``rho`` whenever one of its chains has such a ray; the pairs below a
    rejected node cannot carry a leg to the target.
    """
    t = len(centre)
    if t == 0 or len(beams.apex) == 0:
        return
    n = scene.polygon_normal
    d = scene.polygon_offset
    eps = scene.length_tolerance(1e-9)

    def node_test(rows: np.ndarray, lvl: int, nodes: np.ndarray) -> np.ndarray:
        a0 = beams.apex.centre[lvl][nodes]
        rho = beams.apex.radius[lvl][nodes]
        ok = np.ones(len(rows), bool)
        for tr in beams.through[::-1]:  # the last mirror first: it prunes most
            i = np.nonzero(ok)[0]
            if len(i) == 0:
                break
            ni = nodes[i]
            ok[i] = beam_meets_spheres(a0[i], tr.centre[lvl][ni], tr.radius[lvl][ni] + rho[i], centre[rows[i]],
                                       radius[rows[i]] + rho[i], NODE_ANGLE_SLACK)
        return ok

    for r, c in query_tree(beams.apex, np.arange(t, dtype=np.int64), node_test, budget):
        # beyond the last mirror (as in chain_beams_meet, with its margin)
        apex = level.images[c, -1]
        q = level.polygons[c, -1]
        side = np.sign(np.einsum("ij,ij->i", apex, n[q]) - d[q])
        far = 1e-9 * np.linalg.norm(centre[r] - apex, axis=1) + eps
        i = np.nonzero(side * (np.einsum("ij,ij->i", centre[r], n[q]) - d[q]) < radius[r] + far)[0]
        r, c, apex = r[i], c[i], apex[i]
        cen, rad = beams.centre[c], beams.radius[c]
        for j in range(level.order - 1, -1, -1):
            i = np.nonzero(beam_meets_spheres(apex, cen[:, j], rad[:, j], centre[r], radius[r]))[0]
            r, c, apex, cen, rad = r[i], c[i], apex[i], cen[i], rad[i]
        keep = chain_beams_meet(scene, level, c, apertures.quads, centre[r], radius[r])
        if keep.any():
            yield r[keep], c[keep]


def point_clusters(
    points: np.ndarray, size: int, max_radius: float = np.inf
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Groups of at most ``size`` nearby points (consecutive along a Morton curve).

    A group whose bounding sphere is wider than ``max_radius`` [m] is halved (along the
    curve) until it is not, or holds one point: a wide sphere culls poorly, and scattered
    points are then better queried one by one.

    Returns
    -------
    members : (n,) int64
        Point rows grouped by cluster.
    start : (g + 1,) int64
        Cluster ``i`` holds ``members[start[i]:start[i + 1]]``.
    centre : (g, 3) float64, radius : (g,) float64
        A sphere around each cluster's points [m].
    """
    n = len(points)
    members = morton_order(points)
    p = points[members]
    scale = float(np.abs(points).max()) if n else 0.0

    def spheres(st: np.ndarray):
        if len(st) == 1:
            return np.zeros((0, 3)), np.zeros(0)
        owner = np.repeat(np.arange(len(st) - 1), np.diff(st))
        centre = np.add.reduceat(p, st[:-1], axis=0) / np.diff(st)[:, None]
        dist = np.linalg.norm(p - centre[owner], axis=1)
        return centre, np.maximum.reduceat(dist, st[:-1]) * (1 + 1e-9) + 1e-12 * scale

    start = np.append(np.arange(0, n, size, dtype=np.int64), n)
    centre, radius = spheres(start)
    while True:
        split = (radius > max_radius) & (np.diff(start) > 1)
        if not split.any():
            break
        mid = (start[:-1] + start[1:]) // 2
        start = np.sort(np.concatenate([start, mid[split]]))
        centre, radius = spheres(start)
    return members, start, centre, radius


RX_CLUSTER = 8  # receivers per cluster in the reflection beam culling
COMPILED_CLUSTERS = 256  # clusters per call of the compiled query
# receivers per cluster (on average) below which the compiled search tests every (chain,
# receiver) pair instead of descending the tree once per cluster: etoile_crop's 100 random
# receivers (one per cluster) at order 3, 660 k chains, 2.1 s -> 0.7 s plus 0.3 s for the
# chains' side planes, and the tree's 1.0 s build is saved (the tree is for
# receivers that share their queries, as a coverage map's do)
FLAT_MAX_CLUSTER_SIZE = 2.0
FLAT_MAX_PAIRS = 1 << 30  # and at most this many pairs (about 12 s at 11 ns)
POINT_TEST = True  # also test each receiver of a cluster (as a point) before back-tracing


def reflection_candidates(
    scene: "Scene", ctx: "TxContext", order: int, rx: np.ndarray, stats, budget: int
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Blocks of (receiver, chain) candidates of reflection order ``order`` for receivers ``rx``.

    Without beams in the context, every pair (receivers x chains, in blocks of ``budget``).
    With them: the receivers are grouped in clusters of up to ``RX_CLUSTER`` (Morton order,
    no wider than the 75th percentile of the mirrors' bounding radii); the
    chains whose last-leg beams can reach a cluster's sphere are found in the context's
    :class:`ChainBeams` tree (:func:`beams_reaching`); each of the cluster's receivers is
    then tested as a point (:func:`chain_beams_meet`). Both tests only drop pairs no leg
    from the chain can reach, so no path is lost. ``stats`` counts the dropped pairs as
    ``reflection_order_{order}_culled_beam``. With ``ctx.options.compiled`` and numba, the
    same tests run compiled (:func:`_reflection_candidates_compiled`).
    """
    lv = ctx.levels[order]
    c, n = len(lv), len(rx)
    if c == 0 or n == 0:
        return
    beams = ctx.beams[order] if order < len(ctx.beams) else None
    if beams is None or "reflection_beam" in ctx.options.disable_culling:
        step = max(1, budget // c)
        for s in range(0, n, step):
            r = np.arange(s, min(n, s + step))
            yield np.repeat(r, c), np.tile(np.arange(c), len(r))
        return
    # scattered receivers are queried one by one: a cluster may be as wide as a typical mirror
    members, start, centre, radius = point_clusters(rx, RX_CLUSTER, float(np.percentile(ctx.apertures.radius, 75)))
    if ctx.options.compiled and kernels.available():
        yield from _reflection_candidates_compiled(scene, ctx, order, rx, stats, budget,
                                                   (members, start, centre, radius))
        return
    beams = beams.get(scene, lv, ctx.apertures)
    size = np.diff(start)
    kept = 0
    buf_r: list[np.ndarray] = []
    buf_c: list[np.ndarray] = []
    held = 0
    for cl, ch in beams_reaching(scene, lv, beams, ctx.apertures, centre, radius, max(1, budget // 32)):
        cnt = size[cl]
        ri = members[np.repeat(start[cl], cnt) + (np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt))]
        owner = np.repeat(np.arange(len(ch)), cnt)
        ci = ch[owner]
        ok = chain_beams_meet(scene, lv, ch, ctx.apertures.quads, rx[ri], owner=owner) if POINT_TEST \
            else np.ones(len(ri), bool)
        buf_r.append(ri[ok])
        buf_c.append(ci[ok])
        held += int(ok.sum())
        if held >= budget:
            r_, c_ = np.concatenate(buf_r), np.concatenate(buf_c)
            kept += len(r_)
            yield r_, c_
            buf_r, buf_c, held = [], [], 0
    if held:
        r_, c_ = np.concatenate(buf_r), np.concatenate(buf_c)
        kept += len(r_)
        yield r_, c_
    stats[f"reflection_order_{order}_culled_beam"] += n * c - kept


def _reflection_candidates_compiled(scene: "Scene", ctx: "TxContext", order: int, rx: np.ndarray, stats, budget: int,
                                    clusters) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """:func:`reflection_candidates` through the compiled query (:func:`~wavepaths.search.kernels.reflection_pairs`):
    blocks of clusters, on the kernels' threads when the call is large, yielded in blocks of
    about ``budget`` pairs; the same pairs and the same ``culled_beam`` count.

    Receivers too scattered to share the tree's descent (fewer than
    ``FLAT_MAX_CLUSTER_SIZE`` per cluster on average) are tested against every chain instead
    (:func:`~wavepaths.search.kernels.reflection_pairs_flat`: the point test alone, a
    superset of the tree's pairs, which the back-trace decides alike)."""
    lv = ctx.levels[order]
    lazy = ctx.beams[order]
    g = len(clusters[2])
    if POINT_TEST and len(rx) < FLAT_MAX_CLUSTER_SIZE * g and len(rx) * len(lv) <= FLAT_MAX_PAIRS:
        # scattered receivers: every (chain, receiver) pair, blocks of chains
        kernels.flat_chain_planes(scene, lv, lazy, ctx.apertures)  # built once, before any thread reads it
        nt = kernels.threads() if len(rx) * len(lv) >= kernels.PARALLEL_MIN_PAIRS else 1
        step = max(1, -(-len(lv) // (4 * nt)))
        items = list(range(0, len(lv), step))

        def block(s: int):
            return kernels.reflection_pairs_flat(scene, lv, lazy, ctx.apertures, rx, s, min(len(lv), s + step))
    else:
        beams = lazy.get(scene, lv, ctx.apertures)
        kernels.flat_beams(lv, beams)  # built once, before any thread reads it
        nt = kernels.threads() if g * len(lv) >= kernels.PARALLEL_MIN_PAIRS else 1
        step = max(1, min(COMPILED_CLUSTERS, -(-g // (4 * nt))))
        items = list(range(0, g, step))

        def block(s: int):
            return kernels.reflection_pairs(scene, lv, beams, ctx.apertures, clusters, rx, s, min(g, s + step),
                                            POINT_TEST)

    kept = 0
    held_r: list[np.ndarray] = []
    held_c: list[np.ndarray] = []
    held = 0
    for r_, c_ in kernels.in_threads(block, items, nt):
        kept += len(r_)
        held_r.append(r_)
        held_c.append(c_)
        held += len(r_)
        if held >= budget:
            r_, c_ = np.concatenate(held_r), np.concatenate(held_c)
            for b in range(0, len(r_), budget):
                yield r_[b : b + budget], c_[b : b + budget]
            held_r, held_c, held = [], [], 0
    if held:
        yield np.concatenate(held_r), np.concatenate(held_c)
    stats[f"reflection_order_{order}_culled_beam"] += len(rx) * len(lv) - kept


# ---- image beams and edges (diffraction after reflections) ---------------------------


def edge_tree(scene: "Scene", dihedra: np.ndarray) -> SphereTree:
    """A :class:`SphereTree` over the edges of ``dihedra`` (ids), each in the sphere on its segment."""
    dih = scene.dihedra
    half = 0.5 * dih.length[dihedra]
    return build_sphere_tree(dih.origin[dihedra] + half[:, None] * dih.direction[dihedra], half, dihedra)


def chains_meeting_edges(
    scene: "Scene", level: "ImageLevel", apertures: Apertures, tree: SphereTree, chunk: int = 1 << 14,
    budget: int = 1 << 17, compiled: bool = False,
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """(chain, dihedron) pairs of ``level`` (order >= 1) whose last leg can end on the dihedron's edge.

    A diffracted path with reflections before the diffraction leaves its last mirror along
    the last leg of a chain and ends on the edge, so the edge must reach beyond the last
    mirror and into each of the chain's beams through its apertures' rectangles (see
    :func:`chain_beams_meet`). The tree over the edges (:func:`edge_tree`) is queried with,
    for each chain, these bounding planes (the half-space beyond the last mirror and four
    side planes per aperture): a node is dropped when its sphere lies entirely outside one
    of them, a test that is monotone in the sphere, which contains the edges below it. The
    edges found are tested as segments against the same planes (both ends outside one
    plane), then as spheres against the cones from the last image through the apertures'
    bounding spheres (:func:`beam_meets_spheres`). Every test only drops an edge no leg of
    the chain can reach, so no diffracted path is lost.

    Parameters
    ----------
    scene : Scene
    level : ImageLevel
    apertures : Apertures
    tree : SphereTree
        Over the candidate dihedra (items are dihedron ids).
    chunk : int
        Chains queried together.
    budget : int
        (chain, node) pairs tested at once.
    compiled : bool
        Run the compiled query (:func:`wavepaths.search.kernels.chains_meeting_edges`, the
        same tests) when numba is installed.

    Yields
    ------
    chains : (b,) int64, dihedra : (b,) int64
    """
    k = level.order
    if len(tree) == 0 or len(level) == 0:
        return
    if compiled and kernels.available():
        # the same tests compiled (kernels.chains_meeting_edges), blocks of chains on threads
        blocks = [np.arange(s0, min(len(level), s0 + chunk), dtype=np.int64) for s0 in range(0, len(level), chunk)]
        nt = kernels.threads() if len(level) * len(tree) >= kernels.PARALLEL_MIN_PAIRS else 1
        flat = kernels.tree_arrays(tree)
        for ch, e in kernels.in_threads(
                lambda rows: kernels.chains_meeting_edges(scene, level, apertures, tree, rows, flat), blocks, nt):
            if len(ch):
                yield ch, e
        return
    dih = scene.dihedra
    eps = scene.length_tolerance(1e-9)
    for s0 in range(0, len(level), chunk):
        rows = np.arange(s0, min(len(level), s0 + chunk), dtype=np.int64)
        apex = level.last[rows]
        q = level.polygons[rows, -1]
        n, d = scene.polygon_normal[q], scene.polygon_offset[q]
        side = np.sign(np.einsum("ij,ij->i", apex, n) - d)
        # (m, 1 + 4k, 3) inward normals through the apex (the first: beyond the last mirror), unit
        cen, rad, qd = chain_apertures(scene, level, rows, apertures.centre, apertures.radius, apertures.quads)
        planes = np.concatenate([-(side[:, None] * n)[:, None, :]] +
                                [quad_side_planes(apex, qd[:, j]) for j in range(k - 1, -1, -1)], axis=1)
        # the mirror plane does not pass through the apex: its offset from it
        shift = np.zeros((len(rows), planes.shape[1]))
        shift[:, 0] = -np.abs(np.einsum("ij,ij->i", apex, n) - d)

        def node_test(r: np.ndarray, lvl: int, nodes: np.ndarray) -> np.ndarray:
            i = r - s0
            c, rr = tree.centre[lvl][nodes], tree.radius[lvl][nodes]
            rel = c - apex[i]
            far = 1e-9 * np.linalg.norm(rel, axis=1) + eps
            dist = np.einsum("ikj,ij->ik", planes[i], rel) + shift[i]
            return (dist >= -(rr + far)[:, None]).all(axis=1)

        for r, e in query_tree(tree, rows, node_test, budget):
            i = r - s0
            a = dih.origin[e] - apex[i]
            b = a + dih.length[e][:, None] * dih.direction[e]
            far = 1e-9 * np.maximum(np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)) + eps
            da = np.einsum("ikj,ij->ik", planes[i], a) + shift[i]
            db = np.einsum("ikj,ij->ik", planes[i], b) + shift[i]
            keep = (np.maximum(da, db) >= -far[:, None]).all(axis=1)
            # the edge's sphere against the cones through the apertures' spheres
            half = 0.5 * dih.length[e]
            mid = dih.origin[e] + half[:, None] * dih.direction[e]
            for j in range(k - 1, -1, -1):
                t = np.nonzero(keep)[0]
                it = i[t]
                keep[t] = beam_meets_spheres(apex[it], cen[it, j], rad[it, j], mid[t], half[t] * (1 + 1e-9) + eps)
            if keep.any():
                yield r[keep], e[keep]
