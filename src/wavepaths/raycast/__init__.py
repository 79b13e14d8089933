"""Batched segment-occlusion queries.

**What blocks a segment.** The segment from ``a`` to ``b`` is blocked when it passes
through a face: it crosses the face's plane from one side to the other (both ends farther
than the plane tolerance from the plane, on opposite sides) at a point of the closed
triangle. Hence, by definition:

* an end point on a face (a reflection or diffraction point, or a transmitter or receiver
  placed on a surface) *touches* that face and is not blocked by it;
* a segment lying in a face's plane (both ends within the plane tolerance of it) runs along
  the face and is not blocked by it, nor where it touches the boundary edges of that face
  (a segment over a flat roof, in the roof's plane, that meets the top edge of a wall
  below it); except where it runs with solid on both sides of that plane (the shared wall
  of two touching buildings, each with its own face there): entering there through a
  wall's edge, it passes through the buildings and is blocked (decided by the inside rule
  of :mod:`wavepaths.scene.solids`, ``ExactSegments._between_solids``);
* a segment grazing a face (passing near it without crossing its plane) is not blocked;
* a segment crossing a face exactly through one of its edges or vertices is blocked
  (closed triangles: no ray leaks between the two triangles of a wall).

The plane tolerance is :func:`plane_tolerance` (1e-12 of the scene diagonal plus 1e-14 of
the scene's distance from the origin: above float64 rounding, far below any geometry),
plus, for a triangle merged into a polygon within ``coplanar_angle`` or ``coplanar_distance``, its corners'
distance from the polygon's plane (see :class:`~wavepaths.raycast.numpy_caster.ExactSegments`).
"A point of the closed triangle" is within ``edge_tol`` (1e-12 of the diagonal) inside each
edge and within the triangle's box grown by ``edge_tol`` (which bounds the tolerance at sharp
corners); every implementation adds its sums in one order, so that all agree bit for bit
(docs/stress.md, "What blocks a segment").
The decision is symmetric in the end points: both casters put them in a canonical order
(:func:`canonical`) before any arithmetic, so ``a -> b`` and ``b -> a`` give bit-identical
answers. No end is pulled in by an offset: the rule itself makes end points on surfaces
harmless, so a face arbitrarily close to an end point (the hidden face of a thin wedge)
still blocks.

Two implementations answer the question:

* :class:`~wavepaths.raycast.embree.EmbreeRayCaster` (default): Intel Embree through
  ``embreex``. **This is where float32 enters wavepaths.** Embree finds, in float32 on
  recentred coordinates, the nearest face along two rays covering the segment; every hit
  is confirmed or overruled by the float64 rule on that face, and a segment whose float32
  answer float64 cannot confirm is decided in float64 against the whole scene.
* :class:`~wavepaths.raycast.numpy_caster.NumpyRayCaster`: the float64 rule on every
  (segment, triangle) pair whose boxes can meet (found through a uniform grid of the
  triangles; the brute-force product over all pairs stays as the tests' reference), the
  reference; the tests hold the two together. The only
  float32 limit left in the Embree caster is a face the segment crosses within float32
  resolution (~1e-7 of the scene's half-size) of one of its edges, which Embree may miss;
  the search casts the segments of such near-boundary pairs in float64.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene


class RayCaster(Protocol):
    """Answers batched segment-occlusion queries for one scene."""

    def occluded(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(k,) bool: whether the segment ``a[i] -> b[i]`` ((k, 3) float64, metres) is blocked.

        By the rule of :mod:`wavepaths.raycast`: end points may lie on surfaces; the
        answer does not depend on the order of the ends.
        """
        ...

    def occluded_legs(self, V: np.ndarray, alive: np.ndarray, i: int, j: int) -> np.ndarray:
        """:meth:`occluded` of the legs ``V[alive, i] -> V[alive, j]`` of chains ``V`` (k, s, 3)."""
        ...

    @property
    def rays_cast(self) -> int:
        """How many rays this caster has cast so far (a per-stage counter)."""
        ...


def default_raycaster(scene: "Scene") -> RayCaster:
    """Embree if ``embreex`` imports, else the numpy caster (with a clear reason kept)."""
    try:
        from .embree import EmbreeRayCaster

        return EmbreeRayCaster(scene)
    except ImportError:  # pragma: no cover - embreex is a declared dependency
        from .numpy_caster import NumpyRayCaster

        return NumpyRayCaster(scene)


def plane_tolerance(scene: "Scene") -> float:
    """Distance [m] within which a point lies on a face's plane, for occlusion."""
    return 1e-12 * scene.diagonal + 1e-14 * float(np.abs(scene.center).max())


def canonical(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The segments' ends in a canonical order: ``a`` lexicographically before ``b``.

    Returns ``(first, second, swapped)``; every computation on a segment starts from this
    order, so that ``a -> b`` and ``b -> a`` are the same float64 operations.
    """
    swap = np.zeros(len(a), dtype=bool)
    undecided = np.ones(len(a), dtype=bool)
    for c in range(3):
        swap |= undecided & (b[:, c] < a[:, c])
        undecided &= b[:, c] == a[:, c]
    return np.where(swap[:, None], b, a), np.where(swap[:, None], a, b), swap

