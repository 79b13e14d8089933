"""Image trees: the mirror images of a point across sequences of polygons.

The tree depends only on the source (a transmitter, or a receiver for reflections
after a diffraction), so it is built once and reused for every receiver. Pruning keeps
it complete (no valid path is lost) while dropping sequences that cannot carry a path:

* a polygon whose material is an absorber never reflects (``skip_absorbers``);
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
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..errors import WavepathsError
from ..scene.closed import points_inside_closed
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


def polygon_spheres(scene: "Scene") -> tuple[np.ndarray, np.ndarray]:
    """Bounding spheres of the polygons: centres (p, 3) and radii (p,) [m]."""
    corners = scene.vertices[scene.triangles]
    p = scene.num_polygons
    lo = np.full((p, 3), np.inf)
    hi = np.full((p, 3), -np.inf)
    np.minimum.at(lo, scene.triangle_polygon, corners.min(axis=1))
    np.maximum.at(hi, scene.triangle_polygon, corners.max(axis=1))
    centre = 0.5 * (lo + hi)
    dist = np.linalg.norm(corners - centre[scene.triangle_polygon][:, None, :], axis=2).max(axis=1)
    radius = np.zeros(p)
    np.maximum.at(radius, scene.triangle_polygon, dist)
    return centre, radius


def reflecting_polygons(scene: "Scene", skip_absorbers: bool) -> np.ndarray:
    """(p,) bool: polygons that may reflect (not absorbers when skipped, not hidden contact faces)."""
    keep = ~scene.hidden_polygons
    if skip_absorbers:
        absorber = np.array([m.kind == "absorber" for m in scene.materials], dtype=bool)
        keep &= ~absorber[scene.polygon_material]
    return keep


def source_inside_objects(scene: "Scene", sources: np.ndarray) -> np.ndarray:
    """(s, objects) bool: which closed objects each source lies in (one-sided culling is off there)."""
    if not (scene.outward_sign != 0).any() or len(sources) == 0:
        return np.zeros((len(sources), len(scene.object_names)), dtype=bool)
    return points_inside_closed(scene, sources)


def build_image_levels(
    scene: "Scene", sources: np.ndarray, max_order: int, skip_absorbers: bool = True
) -> list[ImageLevel]:
    """Image chains of orders ``0..max_order`` for each source point.

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
    centre, radius = polygon_spheres(scene)
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
            cos_axis = np.einsum("ij,ij->i", to_p, to_q) / np.maximum(dist_p * dist_q, 1e-300)
            angle = np.arccos(np.clip(cos_axis, -1, 1))
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


def backtrace(
    scene: "Scene", target: np.ndarray, level: ImageLevel, chain: np.ndarray, eps: float = 1e-12
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

    Returns
    -------
    keep : (s,) int64
        Rows of the input that carry a valid chain.
    points : (s, k, 3) float64
        Their reflection points, in path order.
    rejected : dict
        ``{"segment": count, "outside_polygon": count}``.
    """
    from ..scene.polygon_query import points_in_polygons

    k = level.order
    m = len(chain)
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
