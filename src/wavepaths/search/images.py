"""Image trees: the mirror images of a point across sequences of polygons.

The tree depends only on the source (a transmitter, or a receiver for reflections
after a diffraction), so it is built once and reused for every receiver. Pruning keeps
it complete (no valid path is lost) while dropping sequences that cannot carry a path:

* a polygon whose material is an absorber or free space never reflects (``skip_absorbers``);
* no reflection on the polygon just reflected on, nor on one coplanar with it;
* the parent image must not lie in the new mirror's plane;
* after reflecting on ``p``, the wave travels on the side of ``p`` where the previous
  image lies, so the next mirror ``q`` must reach into that half-space (tested with
  ``q``'s bounding sphere: conservative, hence complete);
* a polygon of a closed object reflects only waves arriving from outside the object
  (unless a source is inside it), and contact faces (a building's floor on the ground)
  never reflect (:mod:`wavepaths.scene.closed`);
* the reflected wave seems to come from the image ``I`` through ``p``, so ``q`` must meet
  the cone from ``I`` that contains ``p``'s bounding sphere (a beam test on bounding
  spheres: conservative, hence complete).

:func:`build_image_levels` finds the candidate mirrors of each parent chain in a tree of
the mirrors' bounding spheres (:mod:`wavepaths.search.beams`), queried with the parent's
half-space and beam, instead of testing every (chain, mirror) pair; it keeps exactly the
chains of :func:`build_image_levels_all_pairs` (the reference, for tests), in the same order.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Iterator

import numpy as np

from ..errors import ImageTreeTooLarge, WavepathsError
from ..scene.closed import points_inside_closed
from .on_faces import points_on_surfaces
from .spheres import NODE_ANGLE_SLACK, SphereTree, beam_meets_spheres, build_sphere_tree, query_tree, vector_angle
from .geometry import mirror_points, segment_plane_intersection

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene

MAX_IMAGES = 20_000_000


@dataclass(frozen=True)
class ImageLevel:
    """All image chains of one order ``k`` for a batch of sources.

    Attributes
    ----------
    source : (c,) int64
        Which source (row of the ``sources`` array the tree was built from).
    polygons : (c, k) int64
        Mirror polygons in path order, from the source outward.
    images : (c, k + 1, 3) float64
        ``images[:, 0]`` is the source, ``images[:, j]`` its image after reflections on
        ``polygons[:, :j]`` [m].
    """

    source: np.ndarray
    polygons: np.ndarray
    images: np.ndarray

    def __len__(self) -> int:
        return len(self.source)

    @property
    def order(self) -> int:
        return self.polygons.shape[1]

    @property
    def last(self) -> np.ndarray:
        """(c, 3): the deepest image of each chain (the source itself at order 0)."""
        return self.images[:, -1]


def reflecting_polygons(scene: "Scene", skip_absorbers: bool) -> np.ndarray:
    """(p,) bool: polygons that may reflect: not hidden contact faces, and with ``skip_absorbers``
    not absorbers nor faces of a free-space material (:func:`~wavepaths.scene.loaders.is_transparent`:
    permittivity 1 and conductivity 0, whose reflection coefficient is 0 at every angle, and
    which still block rays since no transmission is modelled)."""
    from ..scene.loaders import is_transparent

    keep = ~scene.hidden_polygons
    if skip_absorbers:
        silent = np.array([m.kind == "absorber" or is_transparent(m) for m in scene.materials], dtype=bool)
        keep &= ~silent[scene.polygon_material]
    return keep


def source_inside_objects(scene: "Scene", sources: np.ndarray) -> np.ndarray:
    """(s, objects) bool: which closed objects each source lies in (one-sided culling is off there).

    A source exactly on a face of an object is on its surface, not inside it
    (:func:`wavepaths.search.on_faces.points_on_surfaces`), whatever the ray-parity test says there.
    """
    if not (scene.outward_sign != 0).any() or len(sources) == 0:
        return np.zeros((len(sources), len(scene.object_names)), dtype=bool)
    inside = points_inside_closed(scene, sources)
    if inside.any():
        inside &= ~points_on_surfaces(scene, sources)
    return inside


PARENT_CHUNK = 1 << 15  # parent chains whose beams are queried together
CANDIDATE_BLOCK = 1 << 20  # (chain, mirror) candidates tested at once


def _admissible(
    scene: "Scene", k: int, lv: ImageLevel, chain: np.ndarray, q: np.ndarray, centre: np.ndarray,
    radius: np.ndarray, inside: np.ndarray, tol: float, compiled: bool = False,
) -> np.ndarray:
    """(m,) bool: which candidates (parent chain, mirror ``q``) of order ``k`` are kept.

    The tests of :func:`build_image_levels_all_pairs`, expression for expression (so both
    builders keep exactly the same chains): the parent image off ``q``'s plane; closed
    objects reflect from outside only; for ``k >= 2``, ``q`` reaches the half-space the wave
    travels in after the parent's last mirror ``p``, is not ``p`` nor coplanar with it, and
    its bounding sphere meets the beam from the parent image through ``p``'s sphere.

    ``compiled``: run the same tests as one compiled loop per candidate
    (:func:`wavepaths.search._numba.admissible`, numba; no temporaries per test), with the
    same expressions in the same order.
    """
    if compiled:
        from . import _numba

        out = np.empty(len(chain), dtype=np.bool_)
        c = np.ascontiguousarray
        _numba.admissible(k, c(lv.images), c(lv.polygons, dtype=np.int64), c(lv.source, dtype=np.int64),
                          c(chain, dtype=np.int64), c(q, dtype=np.int64), c(scene.polygon_normal),
                          c(scene.polygon_offset), c(scene.outward_sign), c(scene.polygon_object, dtype=np.int64),
                          c(inside), c(centre), c(radius), float(tol), float(1e-12 * scene.diagonal), out)
        return out
    n = scene.polygon_normal
    d = scene.polygon_offset
    outward = scene.outward_sign
    parent = lv.last[chain]
    side = np.einsum("ij,ij->i", parent, n[q]) - d[q]
    keep = np.abs(side) > (tol if k >= 2 else 1e-12 * scene.diagonal)
    two_sided = (outward[q] == 0) | inside[lv.source[chain], scene.polygon_object[q]]
    keep &= two_sided | (outward[q] * side > 0)
    if k >= 2:
        p = lv.polygons[chain, -1]
        before = lv.images[chain, -2]
        side = np.sign(np.einsum("ij,ij->i", before, n[p]) - d[p])
        reach = side * (np.einsum("ij,ij->i", centre[q], n[p]) - d[p]) > -radius[q]
        same_plane = (np.abs(np.einsum("ij,ij->i", n[p], n[q])) > 1 - 1e-12) & (
            np.abs(np.einsum("ij,ij->i", centre[q], n[p]) - d[p]) <= tol
        )
        keep &= reach & ~same_plane & (q != p)
        keep &= beam_meets_spheres(parent, centre[p], radius[p], centre[q], radius[q])
    return keep


def _candidates(
    scene: "Scene", k: int, lv: ImageLevel, rows: np.ndarray, mirrors: np.ndarray, tree: SphereTree,
    centre: np.ndarray, radius: np.ndarray,
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Blocks of (parent chain, mirror) candidates of order ``k`` for the parents ``rows``.

    Order 1: every mirror. Order ``k >= 2``: the mirrors whose path of nodes in ``tree``
    passes the parent's half-space and beam tests on the nodes' bounding spheres (see
    :func:`~wavepaths.search.spheres.query_tree`). Both tests are monotone in the sphere and
    the nodes' spheres contain their items' spheres (with margins far above rounding), so
    every mirror that :func:`_admissible` would keep is a candidate.
    """
    if k == 1:
        per = max(1, CANDIDATE_BLOCK // max(len(mirrors), 1))
        for s in range(0, len(rows), per):
            r = rows[s : s + per]
            yield np.repeat(r, len(mirrors)), np.tile(mirrors, len(r))
        return
    n = scene.polygon_normal
    d = scene.polygon_offset
    p = lv.polygons[rows, -1]
    apex = lv.last[rows]
    before = lv.images[rows, -2]
    side = np.sign(np.einsum("ij,ij->i", before, n[p]) - d[p])
    pc, pr, pn, pd = centre[p], radius[p], n[p], d[p]
    margin = 1e-9 * scene.diagonal
    start = int(rows[0])

    def node_test(r: np.ndarray, level: int, nodes: np.ndarray) -> np.ndarray:
        c, rad = tree.centre[level][nodes], tree.radius[level][nodes]
        i = r - start
        ok = side[i] * (np.einsum("ij,ij->i", c, pn[i]) - pd[i]) > -rad - margin
        j = np.nonzero(ok)[0]
        ok[j] = beam_meets_spheres(apex[i[j]], pc[i[j]], pr[i[j]], c[j], rad[j], NODE_ANGLE_SLACK)
        return ok

    yield from query_tree(tree, rows, node_test, max(1, CANDIDATE_BLOCK // max(tree.leaf_size, tree.branch)))


def build_image_levels(
    scene: "Scene", sources: np.ndarray, max_order: int, skip_absorbers: bool = True, stats: dict | None = None,
    compiled: bool | None = None, visibility_group: int = 0,
) -> list[ImageLevel]:
    """Image chains of orders ``0..max_order`` for each source point.

    The chains are those of :func:`build_image_levels_all_pairs` (the same set, in the same
    order), found without testing every (chain, mirror) pair: the mirrors are held in a
    :class:`~wavepaths.search.spheres.SphereTree` of their bounding spheres, and each parent
    chain of order ``k - 1`` queries it with its half-space and its beam (the cone from its
    image through its last mirror's bounding sphere); only the mirrors found go through the
    exact tests (:func:`_admissible`). Parents are processed in chunks of ``PARENT_CHUNK``
    and candidates in blocks of about ``CANDIDATE_BLOCK``, so the working memory is bounded
    by the tree being built.

    Parameters
    ----------
    scene : Scene
    sources : (s, 3) float64
        Source points [m] (transmitters, or receivers for the receiver side).
    max_order : int
    skip_absorbers : bool
    stats : dict, optional
        Receives ``images_order_{k}_candidates`` (candidates given the exact tests).
    compiled : bool, optional
        Run the exact tests as a compiled loop (numba): by default when numba is installed;
        ``False`` runs the numpy reference; ``True`` without numba raises ``ImportError``.
    visibility_group : int
        When positive, drop the order-1 chains whose mirror is proven hidden from every source
        of its group (``visibility_group`` sources per group, consecutive along a Morton
        curve; :func:`~wavepaths.search.mirror_visibility.hidden_mirrors`): no path reflects
        first on a mirror its source cannot see, so no chain of any order starting there is
        built. Counted in ``stats["images_order_1_culled_hidden"]``. ``0`` keeps them (the
        chains of :func:`build_image_levels_all_pairs`).

    Returns
    -------
    list of ImageLevel
        ``levels[k]`` holds the chains of order ``k``; level 0 is the sources themselves
        (``images`` of shape (s, 1, 3), ``polygons`` of shape (s, 0)).

    Raises
    ------
    ImageTreeTooLarge
        When an order holds more than ``MAX_IMAGES`` chains.
    """
    sources = np.asarray(sources, dtype=np.float64).reshape(-1, 3)
    s = len(sources)
    tol = scene.length_tolerance(scene.tolerances.plane_distance)
    levels = [ImageLevel(np.arange(s), np.zeros((s, 0), np.int64), sources[:, None, :].copy())]
    if max_order == 0:
        return levels
    centre, radius = scene.polygon_spheres
    mirrors = np.nonzero(reflecting_polygons(scene, skip_absorbers))[0]
    tree = build_sphere_tree(centre[mirrors], radius[mirrors], mirrors)
    inside = source_inside_objects(scene, sources)  # decided per source, never for the whole batch
    from . import kernels

    if compiled and not kernels.available():
        raise ImportError("build_image_levels(compiled=True) needs numba (pip install 'wavepaths[fast]')")
    compiled = compiled is not False and kernels.available()
    num_p = max(scene.num_polygons, 1)
    for k in range(1, max_order + 1):
        lv = levels[-1]
        kept_chain, kept_q = [], []
        total = tested = 0
        for s0 in range(0, len(lv), PARENT_CHUNK):
            rows = np.arange(s0, min(len(lv), s0 + PARENT_CHUNK), dtype=np.int64)
            got_c, got_q = [], []
            for chain, q in _candidates(scene, k, lv, rows, mirrors, tree, centre, radius):
                tested += len(chain)
                keep = _admissible(scene, k, lv, chain, q, centre, radius, inside, tol, compiled)
                got_c.append(chain[keep])
                got_q.append(q[keep])
                total += int(keep.sum())
                if total > MAX_IMAGES:
                    raise ImageTreeTooLarge(
                        f"the image tree of order {k} holds more than {MAX_IMAGES:,} chains: lower "
                        f"`max_reflections` (or `diffraction_reflections`) or simplify the scene"
                    )
            if got_c:
                c = np.concatenate(got_c)
                q = np.concatenate(got_q)
                o = np.argsort(c * num_p + q, kind="stable")
                kept_chain.append(c[o])
                kept_q.append(q[o])
        if stats is not None:
            stats[f"images_order_{k}_candidates"] = stats.get(f"images_order_{k}_candidates", 0) + tested
        chain = np.concatenate(kept_chain) if kept_chain else np.zeros(0, np.int64)
        q = np.concatenate(kept_q) if kept_q else np.zeros(0, np.int64)
        if k == 1 and visibility_group > 0 and len(chain):
            seen = _seen_mirrors(scene, sources, visibility_group, chain, q, mirrors, stats, compiled)
            chain, q = chain[seen], q[seen]
        elif k >= 2 and visibility_group > 0 and len(chain):
            seen = _seen_after_mirror(scene, k, lv, chain, q, stats, compiled)
            chain, q = chain[seen], q[seen]
        levels.append(_extend(scene, lv, chain, q))
    return levels


def _seen_mirrors(scene: "Scene", sources: np.ndarray, size: int, chain: np.ndarray, q: np.ndarray,
                  mirrors: np.ndarray, stats: dict | None, compiled: bool) -> np.ndarray:
    """(c,) bool: the order-1 chains (source ``chain``, mirror ``q``) whose mirror is not
    proven hidden from the source's group (see ``visibility_group``)."""
    from .mirror_visibility import hidden_mirrors, source_groups

    group = source_groups(sources, size)
    col = np.searchsorted(mirrors, q)
    wanted = np.zeros((int(group.max()) + 1, len(mirrors)), bool)
    wanted[group[chain], col] = True
    hidden, rays = hidden_mirrors(scene, sources, group, mirrors, wanted, compiled)
    seen = ~hidden[group[chain], col]
    if stats is not None:
        stats["images_order_1_culled_hidden"] = stats.get("images_order_1_culled_hidden", 0) + int((~seen).sum())
        stats["mirror_visibility_rays"] = stats.get("mirror_visibility_rays", 0) + rays
    return seen


def _seen_after_mirror(scene: "Scene", k: int, lv: ImageLevel, chain: np.ndarray, q: np.ndarray,
                       stats: dict | None, compiled: bool) -> np.ndarray:
    """(c,) bool: the order-``k`` chains (parent ``chain`` of ``lv``, mirror ``q``) whose leg
    from the parent's last mirror to ``q`` is not proven blocked
    (:func:`~wavepaths.search.mirror_visibility.hidden_after_mirror`)."""
    from .mirror_visibility import hidden_after_mirror

    hidden, rays = hidden_after_mirror(scene, lv.last[chain], lv.polygons[chain, -1], q, compiled)
    if stats is not None:
        stats[f"images_order_{k}_culled_hidden"] = stats.get(f"images_order_{k}_culled_hidden", 0) + int(hidden.sum())
        stats["mirror_visibility_rays"] = stats.get("mirror_visibility_rays", 0) + rays
    return ~hidden


def _extend(scene: "Scene", lv: ImageLevel, chain: np.ndarray, q: np.ndarray) -> ImageLevel:
    """The level of order ``k + 1``: chains ``chain`` of ``lv`` extended by mirrors ``q`` (in blocks)."""
    m, k = len(chain), lv.order
    polygons = np.empty((m, k + 1), np.int64)
    images = np.empty((m, k + 2, 3), np.float64)
    for s in range(0, m, CANDIDATE_BLOCK):
        c, qq = chain[s : s + CANDIDATE_BLOCK], q[s : s + CANDIDATE_BLOCK]
        polygons[s : s + len(c), :k] = lv.polygons[c]
        polygons[s : s + len(c), k] = qq
        images[s : s + len(c), : k + 1] = lv.images[c]
        images[s : s + len(c), k + 1] = mirror_points(lv.last[c], scene.polygon_normal[qq], scene.polygon_offset[qq])
    return ImageLevel(source=lv.source[chain], polygons=polygons, images=images)


def build_image_levels_all_pairs(
    scene: "Scene", sources: np.ndarray, max_order: int, skip_absorbers: bool = True
) -> list[ImageLevel]:
    """Reference builder: every (chain, mirror) pair of each order tested, then pruned.

    Kept unchanged as the reference that :func:`build_image_levels` must equal (same chains,
    same order); it holds ``chains x mirrors`` candidates at once, so it is for small scenes
    and tests only.

    Parameters
    ----------
    scene : Scene
    sources : (s, 3) float64
        Source points [m] (transmitters, or receivers for the receiver side).
    max_order : int
    skip_absorbers : bool

    Returns
    -------
    list of ImageLevel
        ``levels[k]`` holds the chains of order ``k``; level 0 is the sources themselves
        (``images`` of shape (s, 1, 3), ``polygons`` of shape (s, 0)).
    """
    sources = np.asarray(sources, dtype=np.float64).reshape(-1, 3)
    s = len(sources)
    tol = scene.length_tolerance(scene.tolerances.plane_distance)
    levels = [ImageLevel(np.arange(s), np.zeros((s, 0), np.int64), sources[:, None, :].copy())]
    if max_order == 0:
        return levels
    n = scene.polygon_normal
    d = scene.polygon_offset
    centre, radius = scene.polygon_spheres
    mirrors = np.nonzero(reflecting_polygons(scene, skip_absorbers))[0]
    outward = scene.outward_sign
    inside = source_inside_objects(scene, sources)  # decided per source, never for the whole batch
    for k in range(1, max_order + 1):
        lv = levels[-1]
        c = len(lv)
        count = c * len(mirrors)
        if count > MAX_IMAGES:
            raise WavepathsError(
                f"the image tree of order {k} would hold {count:,} candidates (limit {MAX_IMAGES:,}): "
                f"lower `max_reflections` or simplify the scene"
            )
        chain = np.repeat(np.arange(c), len(mirrors))
        q = np.tile(mirrors, c)
        parent = lv.last[chain]
        side = np.einsum("ij,ij->i", parent, n[q]) - d[q]
        # a source exactly in the plane has no image; one merely close to it (even closer than
        # the geometric tolerance) still reflects
        keep = np.abs(side) > (tol if k >= 2 else 1e-12 * scene.diagonal)
        two_sided = (outward[q] == 0) | inside[lv.source[chain], scene.polygon_object[q]]
        keep &= two_sided | (outward[q] * side > 0)  # closed objects: from outside only
        if k >= 2:
            p = lv.polygons[chain, -1]
            before = lv.images[chain, -2]  # the image the wave came from before reflecting on p
            side = np.sign(np.einsum("ij,ij->i", before, n[p]) - d[p])
            reach = side * (np.einsum("ij,ij->i", centre[q], n[p]) - d[p]) > -radius[q]
            same_plane = (np.abs(np.einsum("ij,ij->i", n[p], n[q])) > 1 - 1e-12) & (
                np.abs(np.einsum("ij,ij->i", centre[q], n[p]) - d[p]) <= tol
            )
            keep &= reach & ~same_plane & (q != p)
            # beam test: q's bounding sphere must meet the cone from the image through p
            apex = lv.last[chain]
            to_p = centre[p] - apex
            dist_p = np.linalg.norm(to_p, axis=1)
            to_q = centre[q] - apex
            dist_q = np.linalg.norm(to_q, axis=1)
            half_p = np.arcsin(np.clip(radius[p] / np.maximum(dist_p, 1e-300), 0, 1))
            half_q = np.arcsin(np.clip(radius[q] / np.maximum(dist_q, 1e-300), 0, 1))
            angle = vector_angle(to_p, to_q)
            inside_cone = (dist_p <= radius[p]) | (dist_q <= radius[q]) | (angle <= half_p + half_q + 1e-9)
            keep &= inside_cone
        chain, q = chain[keep], q[keep]
        new = mirror_points(lv.last[chain], n[q], d[q])
        levels.append(
            ImageLevel(
                source=lv.source[chain],
                polygons=np.concatenate([lv.polygons[chain], q[:, None]], axis=1),
                images=np.concatenate([lv.images[chain], new[:, None, :]], axis=1),
            )
        )
    return levels


SEGMENT_EPS = 1e-12
"""Margin of a back-traced reflection point on its segment's parameter (``eps < t < 1 - eps``):
a point at either end of its leg is no reflection."""


def backtrace(
    scene: "Scene", target: np.ndarray, level: ImageLevel, chain: np.ndarray, eps: float = SEGMENT_EPS,
    compiled: bool = True,
) -> tuple[np.ndarray, np.ndarray, dict]:
    """Reflection points of image chains that end at ``target`` (image method, backwards).

    For a chain source -> q_1 -> ... -> q_k -> target with images I_1..I_k, the last
    reflection point is where the segment target -> I_k crosses q_k's plane, the one
    before it where (that point) -> I_{k-1} crosses q_{k-1}'s plane, and so on. Each
    point must lie strictly inside its segment and inside its polygon; candidates are
    compacted after every step, so later steps only see the survivors, and the images
    are gathered per step (never materialised for all candidates at once).

    Parameters
    ----------
    scene : Scene
    target : (m, 3) float64
        Where each chain must arrive (a receiver or a diffraction point) [m].
    level : ImageLevel
        The image chains of order k.
    chain : (m,) int64
        Row of ``level`` for each target.
    eps : float
        Margin on the segment parameter (0 + eps < t < 1 - eps).
    compiled : bool
        Run :func:`wavepaths.search._numba.backtrace` (the same tests candidate by candidate,
        this code being its reference) when numba is installed.

    Returns
    -------
    keep : (s,) int64
        Rows of the input that carry a valid chain.
    points : (s, k, 3) float64
        Their reflection points, in path order.
    rejected : dict
        ``{"segment": count, "outside_polygon": count}``.
    """
    from ..scene.polygon_query import POLYGON_MARGIN, points_in_polygons

    k = level.order
    m = len(chain)
    from . import kernels

    if compiled and k >= 1 and kernels.available():
        from . import _numba

        keep = np.empty(m, np.int64)
        points = np.empty((m, k, 3))
        rej = np.zeros(2, np.int64)
        n = _numba.backtrace(np.ascontiguousarray(target, dtype=np.float64), level.images, level.polygons,
                             np.ascontiguousarray(chain, dtype=np.int64), scene.polygon_normal, scene.polygon_offset,
                             scene.polygon_tri_ptr, scene.polygon_tris, scene.triangles, scene.vertices,
                             scene.triangle_dual, float(eps), POLYGON_MARGIN, keep, points, rej)
        return keep[:n], points[:n], {"segment": int(rej[0]), "outside_polygon": int(rej[1])}
    keep = np.arange(m)
    found = []
    rejected = {"segment": 0, "outside_polygon": 0}
    y = target
    for j in range(k - 1, -1, -1):
        c = chain[keep]
        q = level.polygons[c, j]
        x, t = segment_plane_intersection(y, level.images[c, j + 1], scene.polygon_normal[q], scene.polygon_offset[q])
        ok = (t > eps) & (t < 1 - eps)
        rejected["segment"] += int((~ok).sum())
        idx = np.nonzero(ok)[0]
        inside = points_in_polygons(scene, x[idx], q[idx])
        rejected["outside_polygon"] += int((~inside).sum())
        idx = idx[inside]
        keep = keep[idx]
        found = [f[idx] for f in found]
        found.append(x[idx])
        y = x[idx]
    points = np.stack(found[::-1], axis=1) if found else np.zeros((m, 0, 3))
    return keep, points, rejected
