"""Bounding-sphere beams and trees: which spheres a cone of rays can meet.

A *beam* is the set of rays from an apex ``A`` (an image source) through a sphere
``(P, r_P)`` (the bounding sphere of the polygon the wave last reflected on, or of an
edge). Seen from ``A``, a sphere ``(C, R)`` at distance ``|C - A| > R`` covers the cap of
directions within ``asin(R / |C - A|)`` of ``C - A``; two caps overlap iff the angle
between their axes is at most the sum of their angular radii. :func:`beam_meets_spheres`
tests that, and treats an apex inside either sphere as a hit: it never rejects a sphere
that some ray of the beam meets, which is what keeps the searches that use it complete.

:class:`SphereTree` is a bounding-volume hierarchy over spheres (polygons, edges, beams),
in Morton order (:func:`morton_order`), queried by many beams at once
(:func:`query_tree`): (query, node) pairs are tested level by level with numpy and
compacted, in blocks of bounded size, and the pairs that reach a leaf are expanded to its
items. A node's sphere contains the spheres of all items below it, and both tests used on
nodes (beam, half-space) can only pass for a larger sphere when they pass for a smaller
one inside it, so the query returns a superset of the items that pass the same test,
never fewer. ``NODE_ANGLE_SLACK`` on nodes keeps the margin above rounding.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np

NODE_ANGLE_SLACK = 1e-7  # [rad] added to the beam test on tree nodes (the exact test on items adds 1e-9)


def vector_angle(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(k,) float64: the angle [rad] between the rows of ``u`` and ``v`` (k, 3), as
    ``atan2(|u x v|, u . v)``: accurate to rounding at every angle. ``arccos`` of the
    normalised dot product loses half the digits near 0 and pi (about 1.5e-8 rad): more
    than the caps of a small scene seen from a transmitter 1e8 m away, which the beam
    tests then rejected (found by a review)."""
    c = np.cross(u, v)
    return np.arctan2(np.sqrt(np.einsum("ij,ij->i", c, c)), np.einsum("ij,ij->i", u, v))


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
    angle = vector_angle(to_p, to_q)
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
