"""Beams and bounding-sphere trees: which spheres a cone of rays can meet.

A *beam* is the set of rays from an apex ``A`` (an image source) through a sphere
``(P, r_P)`` (the bounding sphere of the polygon the wave last reflected on, or of an
edge). Seen from ``A``, a sphere ``(C, R)`` at distance ``|C - A| > R`` covers the cap of
directions within ``asin(R / |C - A|)`` of ``C - A``; two caps overlap iff the angle
between their axes is at most the sum of their angular radii. :func:`beam_meets_spheres`
tests that, and treats an apex inside either sphere as a hit: it never rejects a sphere
that some ray of the beam meets, which is what keeps the searches that use it complete.

:class:`SphereTree` is a bounding-volume hierarchy over spheres (polygons, edges),
queried by many beams at once (:func:`query_tree`): (query, node) pairs are tested level
by level with numpy and compacted, in blocks of bounded size, and the pairs that reach a
leaf are expanded to its items. A node's sphere contains the spheres of all items below
it, and both tests used on nodes (beam, half-space) can only pass for a larger sphere
when they pass for a smaller one inside it, so the query returns a superset of the
items that pass the same test, never fewer.

Uses:

* the image tree (:func:`~wavepaths.search.images.build_image_levels`): the mirrors a
  parent chain's beam can reach;
* per receiver tile (:func:`reflection_candidates`): the chains whose last leg can reach
  a cluster of receivers, from a tree over the chains' beams (:class:`ChainBeams`), then
  per receiver; the last leg must pass through the rectangles of all the chain's mirrors,
  unfolded (:func:`chain_apertures`, :func:`chain_beams_meet`);
* diffraction after reflections (:func:`chains_meeting_edges`): the edges a chain's last
  leg can end on, from a tree over the edges (:func:`edge_tree`).

Every test keeps a margin above rounding (``NODE_ANGLE_SLACK`` on nodes, ``1e-9`` of the
scene diagonal and of the distance on planes), so none drops a valid path.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Callable, Iterator

import numpy as np

from . import kernels

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene
    from .context import TxContext
    from .images import ImageLevel

NODE_ANGLE_SLACK = 1e-7  # [rad] added to the beam test on tree nodes (the exact test on items adds 1e-9)


def beam_meets_spheres(
    apex: np.ndarray, p_centre: np.ndarray, p_radius: np.ndarray, centre: np.ndarray, radius: np.ndarray,
    slack: float = 1e-9,
) -> np.ndarray:
    """Whether the beam from ``apex`` through sphere ``(p_centre, p_radius)`` can meet sphere ``(centre, radius)``.

    Parameters
    ----------
    apex : (k, 3) float64
        Beam apices [m].
    p_centre : (k, 3) float64, p_radius : (k,) float64
        The sphere every ray of the beam passes through [m].
    centre : (k, 3) float64, radius : (k,) float64
        The spheres tested [m].
    slack : float
        Angular margin [rad].

    Returns
    -------
    (k,) bool
        ``False`` only when no ray from the apex through the first sphere meets the second:
        the caps of directions subtended by the two spheres from the apex are disjoint
        (angle between their axes > sum of their angular radii + ``slack``). An apex inside
        either sphere always passes. The test is on whole lines' directions from the apex,
        not only beyond the first sphere, so it is conservative.
    """
    to_p = p_centre - apex
    dist_p = np.linalg.norm(to_p, axis=1)
    to_q = centre - apex
    dist_q = np.linalg.norm(to_q, axis=1)
    half_p = np.arcsin(np.clip(p_radius / np.maximum(dist_p, 1e-300), 0, 1))
    half_q = np.arcsin(np.clip(radius / np.maximum(dist_q, 1e-300), 0, 1))
    cos_axis = np.einsum("ij,ij->i", to_p, to_q) / np.maximum(dist_p * dist_q, 1e-300)
    angle = np.arccos(np.clip(cos_axis, -1, 1))
    return (dist_p <= p_radius) | (dist_q <= radius) | (angle <= half_p + half_q + slack)


def _spread_bits(x: np.ndarray) -> np.ndarray:
    """Insert two zero bits between the low 21 bits of ``x`` (for 3-D Morton codes)."""
    x = x.astype(np.uint64) & np.uint64(0x1FFFFF)
    x = (x | (x << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
    x = (x | (x << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
    x = (x | (x << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
    x = (x | (x << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
    x = (x | (x << np.uint64(2))) & np.uint64(0x1249249249249249)
    return x


def morton_order(points: np.ndarray) -> np.ndarray:
    """(n,) int64: the permutation that sorts ``points`` (n, d) along a d-D Morton curve.

    Each coordinate is scaled to its own range and quantised to ``63 // d`` bits.
    """
    points = np.asarray(points, np.float64)
    if len(points) == 0:
        return np.zeros(0, np.int64)
    n, dim = points.shape
    lo = points.min(axis=0)
    span = np.maximum(points.max(axis=0) - lo, 1e-300)
    if dim == 3:
        q = np.clip(((points - lo) / span * (2**21 - 1)).astype(np.int64), 0, 2**21 - 1)
        code = _spread_bits(q[:, 0]) | (_spread_bits(q[:, 1]) << np.uint64(1)) | (_spread_bits(q[:, 2]) << np.uint64(2))
    else:
        bits = min(max(1, 63 // dim), 16)
        q = np.clip(((points - lo) / span * (2**bits - 1)).astype(np.int64), 0, 2**bits - 1)
        # table[v]: the bits of v spread ``dim`` apart
        v = np.arange(2**bits, dtype=np.uint64)
        table = np.zeros(2**bits, np.uint64)
        for b in range(bits):
            table |= ((v >> np.uint64(b)) & np.uint64(1)) << np.uint64(b * dim)
        code = np.zeros(n, np.uint64)
        for i in range(dim):
            code |= table[q[:, i]] << np.uint64(i)
    return np.argsort(code, kind="stable").astype(np.int64)


@dataclass(frozen=True)
class SphereTree:
    """A bounding-volume hierarchy of spheres, implicit over items in Morton order.

    Level ``L`` (0 = root, ``depth - 1`` = leaves) has nodes ``0 .. n_L - 1``; node ``j``
    of level ``L < depth - 1`` has children ``j * branch .. j * branch + branch - 1`` (those
    below ``n_{L+1}``), and leaf ``j`` holds ``items[j * leaf_size : (j + 1) * leaf_size]``.

    Attributes
    ----------
    items : (n,) int64
        Item ids (as given to :func:`build_sphere_tree`) in tree order.
    centre : list of (n_L, 3) float64
        Node sphere centres per level [m].
    radius : list of (n_L,) float64
        Node sphere radii per level [m]; each contains the spheres of all items below.
    leaf_size, branch : int
    """

    items: np.ndarray
    centre: list[np.ndarray]
    radius: list[np.ndarray]
    leaf_size: int
    branch: int

    @property
    def depth(self) -> int:
        return len(self.centre)

    def __len__(self) -> int:
        return len(self.items)


def build_sphere_tree(
    centres: np.ndarray, radii: np.ndarray, ids: np.ndarray | None = None, leaf_size: int = 8, branch: int = 4,
    order: np.ndarray | None = None,
) -> SphereTree:
    """A :class:`SphereTree` over spheres ``(centres, radii)``, labelled ``ids`` (default ``arange``).

    The items are laid out in ``order`` (default: Morton order of the centres); trees built
    with the same ``order`` share their node structure, so several spheres per item (e.g. a
    beam's apex and the spheres it passes through) can be tested node by node together.

    A leaf's sphere is computed from its items' spheres, a node's from its children's
    (centre: middle of their bounding box; radius: the largest ``|c_i - C| + r_i``), then
    inflated by a relative ``1e-9`` and an absolute ``1e-9`` of the extent, so that it
    contains them in floating point.
    """
    centres = np.asarray(centres, np.float64).reshape(-1, 3)
    radii = np.asarray(radii, np.float64).reshape(-1)
    ids = np.arange(len(centres), dtype=np.int64) if ids is None else np.asarray(ids, np.int64)
    o = morton_order(centres) if order is None else np.asarray(order, np.int64)
    c, r, items = centres[o], radii[o], ids[o]
    n = len(items)
    if n == 0:
        return SphereTree(items, [np.zeros((0, 3))], [np.zeros(0)], leaf_size, branch)
    extent = float(np.abs(c).max() + r.max())
    sizes = [-(-n // leaf_size)]
    while sizes[-1] > 1:
        sizes.append(-(-sizes[-1] // branch))
    # leaves from their items, then each level from its children's spheres (bottom-up)
    cen, rad, group = c, r, leaf_size
    centre_levels, radius_levels = [], []
    for count in sizes:
        starts = np.arange(count, dtype=np.int64) * group
        lo = np.minimum.reduceat(cen - rad[:, None], starts, axis=0)
        hi = np.maximum.reduceat(cen + rad[:, None], starts, axis=0)
        mid = 0.5 * (lo + hi)
        owner = np.arange(len(cen)) // group
        reach = np.linalg.norm(cen - mid[owner], axis=1) + rad
        new_rad = np.maximum.reduceat(reach, starts) * (1 + 1e-9) + 1e-9 * extent
        centre_levels.append(mid)
        radius_levels.append(new_rad)
        cen, rad, group = mid, new_rad, branch
    return SphereTree(items, centre_levels[::-1], radius_levels[::-1], leaf_size, branch)


NodeTest = Callable[[np.ndarray, int, np.ndarray], np.ndarray]


def query_tree(
    tree: SphereTree, rows: np.ndarray, node_test: NodeTest, budget: int = 1 << 17
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """The (query row, item) pairs whose path of nodes from the root passes ``node_test``.

    Parameters
    ----------
    tree : SphereTree
    rows : (r,) int64
        Query ids; ``node_test`` receives them back.
    node_test : callable
        ``node_test(rows (k,), level, nodes (k,)) -> (k,) bool``: whether the query may
        meet something below the node (whose sphere is ``tree.centre[level][nodes]``,
        ``tree.radius[level][nodes]``). It must never be false for a node when some item
        below it would pass the caller's exact test: e.g. a test that is *monotone* (true
        for a sphere whenever it is true for a sphere it contains: a beam test, a
        half-space test) and passes for the item's own sphere.
    budget : int
        (query, node) pairs tested at once; blocks above it are split, so the working
        memory stays about ``budget x branch x depth`` pairs, and each yielded block has at
        most ``budget x max(branch, leaf_size)`` pairs.

    Yields
    ------
    rows : (k,) int64, items : (k,) int64
        Candidate pairs, in blocks (each query may appear in several blocks; the pairs are
        distinct).
    """
    if len(tree) == 0 or len(rows) == 0:
        return
    last = tree.depth - 1
    stack: list[tuple[int, np.ndarray, np.ndarray]] = [(0, np.asarray(rows, np.int64), np.zeros(len(rows), np.int64))]
    while stack:
        level, r, nd = stack.pop()
        if len(r) > budget:
            h = len(r) // 2
            stack.append((level, r[h:], nd[h:]))
            stack.append((level, r[:h], nd[:h]))
            continue
        ok = node_test(r, level, nd)
        r, nd = r[ok], nd[ok]
        if len(r) == 0:
            continue
        if level == last:
            slot = (nd[:, None] * tree.leaf_size + np.arange(tree.leaf_size)).ravel()
            rr = np.repeat(r, tree.leaf_size)
            valid = slot < len(tree.items)
            yield rr[valid], tree.items[slot[valid]]
        else:
            child = (nd[:, None] * tree.branch + np.arange(tree.branch)).ravel()
            rr = np.repeat(r, tree.branch)
            valid = child < len(tree.radius[level + 1])
            stack.append((level + 1, rr[valid], child[valid]))


# ---- polygons as beam apertures ------------------------------------------------------


def polygon_quads(scene: "Scene") -> np.ndarray:
    """(p, 4, 3) float64: a rectangle in each polygon's plane that contains the polygon [m].

    The rectangle is aligned with the principal axes of the polygon's corners in its plane
    and padded by ``1e-6`` of its size plus the scene's plane tolerance, so that every point
    the point-in-polygon test accepts (barycentric margin ``1e-9``) lies inside it. Its
    corners go around it in order. A beam through the polygon lies in the beam through its
    rectangle, which is a convex cone with four side planes (:func:`quad_side_planes`).
    """
    tri = scene.triangles
    poly = scene.triangle_polygon
    p = scene.num_polygons
    corners = scene.vertices[tri]  # (f, 3, 3)
    owner = np.repeat(poly, 3)
    pts = corners.reshape(-1, 3)
    count = np.bincount(owner, minlength=p).astype(np.float64)
    mean = np.zeros((p, 3))
    np.add.at(mean, owner, pts)
    mean /= np.maximum(count, 1)[:, None]
    n = scene.polygon_normal
    mean -= (np.einsum("ij,ij->i", mean, n) - scene.polygon_offset)[:, None] * n  # onto the plane
    rel = pts - mean[owner]
    cov = np.zeros((p, 3, 3))
    np.add.at(cov, owner, rel[:, :, None] * rel[:, None, :])
    proj = np.eye(3)[None] - n[:, :, None] * n[:, None, :]
    cov = proj @ cov @ proj
    _, vec = np.linalg.eigh(cov)
    u = vec[:, :, 2]  # largest in-plane axis
    u -= np.einsum("ij,ij->i", u, n)[:, None] * n
    norm = np.linalg.norm(u, axis=1)
    # polygons without a dominant axis: any in-plane direction
    axis = np.eye(3)[np.argmin(np.abs(n), axis=1)]
    fallback = np.cross(n, axis)
    bad = norm < 1e-6
    u[bad] = fallback[bad]
    u /= np.linalg.norm(u, axis=1)[:, None]
    v = np.cross(n, u)
    cu, cv = np.einsum("ij,ij->i", rel, u[owner]), np.einsum("ij,ij->i", rel, v[owner])
    lo_u = np.full(p, np.inf)
    hi_u = np.full(p, -np.inf)
    lo_v = np.full(p, np.inf)
    hi_v = np.full(p, -np.inf)
    np.minimum.at(lo_u, owner, cu)
    np.maximum.at(hi_u, owner, cu)
    np.minimum.at(lo_v, owner, cv)
    np.maximum.at(hi_v, owner, cv)
    pad = 1e-6 * np.hypot(hi_u - lo_u, hi_v - lo_v) + 2 * scene.length_tolerance(scene.tolerances.plane_distance)
    lo_u, hi_u, lo_v, hi_v = lo_u - pad, hi_u + pad, lo_v - pad, hi_v + pad
    us = np.stack([lo_u, hi_u, hi_u, lo_u], axis=1)
    vs = np.stack([lo_v, lo_v, hi_v, hi_v], axis=1)
    return mean[:, None, :] + us[:, :, None] * u[:, None, :] + vs[:, :, None] * v[:, None, :]


@dataclass(frozen=True)
class Apertures:
    """Bounding shapes of a scene's polygons, as beam apertures.

    Attributes
    ----------
    centre : (p, 3) float64, radius : (p,) float64
        Bounding spheres (:func:`~wavepaths.search.images.polygon_spheres`) [m].
    quads : (p, 4, 3) float64
        Bounding rectangles in their planes (:func:`polygon_quads`) [m].
    """

    centre: np.ndarray
    radius: np.ndarray
    quads: np.ndarray


def scene_apertures(scene: "Scene") -> Apertures:
    """The :class:`Apertures` of ``scene``'s polygons."""
    centre, radius = scene.polygon_spheres
    return Apertures(centre, radius, polygon_quads(scene))


def quad_side_planes(apex: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """(m, 4, 3) float64: inward unit normals of the side planes of the beams from ``apex`` through ``quads``.

    Parameters
    ----------
    apex : (m, 3) float64
    quads : (m, 4, 3) float64
        Convex quadrilaterals, corners in order (either way round).

    Returns
    -------
    (m, 4, 3) float64
        Side plane ``i`` passes through the apex and corners ``i``, ``i + 1``; a point ``X`` is
        inside the (pointed, convex) beam iff ``normal_i . (X - apex) >= 0`` for all four.
        Degenerate planes (apex in the quad's plane, zero-width quad) get a zero normal, which
        every point passes.
    """
    rel = quads - apex[:, None, :]
    m = np.cross(rel, np.roll(rel, -1, axis=1))
    nq = np.cross(quads[:, 2] - quads[:, 0], quads[:, 3] - quads[:, 1])
    s = -np.sign(np.einsum("ij,ij->i", nq, apex - quads[:, 0]))
    norm = np.linalg.norm(m, axis=2)
    return m * (s[:, None] / np.where(norm > 0, norm, np.inf))[:, :, None]


def _mirror_across(points: np.ndarray, polygons: np.ndarray, scene: "Scene") -> np.ndarray:
    """``points`` (m, ..., 3) mirrored across the planes of ``polygons`` (m,)."""
    n = scene.polygon_normal[polygons]
    d = scene.polygon_offset[polygons]
    shape = (len(polygons),) + (1,) * (points.ndim - 2) + (3,)
    dist = np.einsum("i...j,i...j->i...", points, n.reshape(shape)) - d.reshape(shape[:-1])
    return points - 2.0 * dist[..., None] * n.reshape(shape)


def chain_apertures(
    scene: "Scene", level: "ImageLevel", rows: np.ndarray, centre: np.ndarray | None = None,
    radius: np.ndarray | None = None, quads: np.ndarray | None = None,
) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """What the last leg of each chain passes through, seen from its last image.

    Unfolding a chain ``q_1 .. q_k`` across its mirrors, the last leg (from the last
    reflection point to the receiver, or to a diffraction point) lies on a ray from the last
    image ``I_k`` that crosses ``q_k`` and the images of ``q_j`` (j < k) mirrored across
    ``q_{j+1}``, then ``q_{j+2}``, .., ``q_k`` (where the earlier reflection points unfold to).

    Parameters
    ----------
    scene : Scene
    level : ImageLevel
    rows : (m,) int64
    centre, radius : (p, 3), (p,) float64, optional
        Polygon bounding spheres (:func:`~wavepaths.search.images.polygon_spheres`).
    quads : (p, 4, 3) float64, optional
        Polygon rectangles (:func:`polygon_quads`).

    Returns
    -------
    centres : (m, k, 3), radii : (m, k)
        The mirrors' bounding spheres, mirrored so [m] (None without ``centre``).
    quads : (m, k, 4, 3)
        Their rectangles, mirrored so (None without ``quads``).
    """
    k = level.order
    polys = level.polygons[rows]
    cen = None if centre is None else centre[polys]
    rad = None if radius is None else radius[polys]
    qd = None if quads is None else quads[polys]
    for j in range(k - 1):
        for i in range(j + 1, k):
            if cen is not None:
                cen[:, j] = _mirror_across(cen[:, j], polys[:, i], scene)
            if qd is not None:
                qd[:, j] = _mirror_across(qd[:, j], polys[:, i], scene)
    return cen, rad, qd


def chain_beams_meet(
    scene: "Scene", level: "ImageLevel", rows: np.ndarray, quads: np.ndarray, centre: np.ndarray,
    radius: np.ndarray | None = None, end: np.ndarray | None = None, slack: float | None = None,
    owner: np.ndarray | None = None,
) -> np.ndarray:
    """(m,) bool: whether the last leg of chain ``rows[owner[i]]`` can reach target ``i`` (a sphere or a segment).

    The target is the sphere ``(centre[i], radius[i])``, or the segment ``centre[i] -> end[i]``
    when ``end`` is given. Without ``owner`` target ``i`` is tested against chain
    ``rows[i]``; with it (several targets per chain), the per-chain work (the mirrored
    apertures and the beams' side planes) is done once per chain. Two necessary conditions
    for a point of the target to end the last leg (see :func:`chain_apertures`):

    * it lies beyond the last mirror ``q_k``, on the side opposite the last image (the
      back-tracing needs the segment from it to ``I_k`` to cross ``q_k``'s plane);
    * the ray from ``I_k`` to it passes through the rectangle of ``q_k`` and those of the
      earlier mirrors mirrored forward, so it is inside each of these convex beams.

    Each is tested as "not entirely outside one bounding plane" (a sphere: centre farther
    than its radius outside; a segment: both ends outside), with a margin ``slack`` [m]
    (default ``1e-9`` of the scene diagonal plus ``1e-9`` of the distance to the apex): a
    target that some valid leg reaches always passes.
    """
    k = level.order
    owner = np.arange(len(rows)) if owner is None else np.asarray(owner, np.int64)
    m = len(owner)
    if m == 0:
        return np.zeros(0, bool)
    eps = scene.length_tolerance(1e-9) if slack is None else slack
    apex_c = level.images[rows, -1]  # per chain
    qk = level.polygons[rows, -1]
    n_c = scene.polygon_normal[qk]
    d_c = scene.polygon_offset[qk]
    side_c = np.sign(np.einsum("ij,ij->i", apex_c, n_c) - d_c)  # the last image's side of q_k
    apex, n, d, side = apex_c[owner], n_c[owner], d_c[owner], side_c[owner]
    rad = np.zeros(m) if radius is None else radius
    far = 1e-9 * np.linalg.norm(centre - apex, axis=1) + eps
    if end is None:
        keep = side * (np.einsum("ij,ij->i", centre, n) - d) < rad + far
    else:
        far = np.maximum(far, 1e-9 * np.linalg.norm(end - apex, axis=1) + eps)
        keep = (side * (np.einsum("ij,ij->i", centre, n) - d) < far) | (
            side * (np.einsum("ij,ij->i", end, n) - d) < far
        )
    idx = np.nonzero(keep)[0]
    used, inv = np.unique(owner[idx], return_inverse=True)  # chains still needed, once each
    _, _, qd = chain_apertures(scene, level, rows[used], quads=quads)
    for j in range(k):
        if len(idx) == 0:
            break
        planes = quad_side_planes(apex_c[used], qd[:, j])[inv]
        a = np.einsum("ikj,ij->ik", planes, centre[idx] - apex[idx])
        if end is None:
            ok = (a >= -(rad[idx] + far[idx])[:, None]).all(axis=1)
        else:
            b = np.einsum("ikj,ij->ik", planes, end[idx] - apex[idx])
            ok = (np.maximum(a, b) >= -far[idx][:, None]).all(axis=1)
        idx, inv = idx[ok], inv[ok]
    out = np.zeros(m, bool)
    out[idx] = True
    return out


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
    about ``budget`` pairs; the same pairs and the same ``culled_beam`` count."""
    lv = ctx.levels[order]
    beams = ctx.beams[order]
    kernels.flat_beams(lv, beams)  # built once, before any thread reads it
    g = len(clusters[2])
    nt = kernels.threads() if g * len(lv) >= kernels.PARALLEL_MIN_PAIRS else 1
    step = max(1, min(COMPILED_CLUSTERS, -(-g // (4 * nt))))

    def block(s: int):
        return kernels.reflection_pairs(scene, lv, beams, ctx.apertures, clusters, rx, s, min(g, s + step), POINT_TEST)

    kept = 0
    held_r: list[np.ndarray] = []
    held_c: list[np.ndarray] = []
    held = 0
    for r_, c_ in kernels.in_threads(block, list(range(0, g, step)), nt):
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
