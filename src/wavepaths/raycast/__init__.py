"""Batched segment-occlusion queries.

Two implementations answer the same question, "is the open segment from ``a`` to
``b`` blocked by any triangle?":

* :class:`~wavepaths.raycast.embree.EmbreeRayCaster` (default): Intel Embree through
  ``embreex``. **This is where float32 enters wavepaths.** Embree stores vertices and
  rays in float32, so the caster subtracts the scene centre before converting (city
  scenes come in projected coordinates near 1e6 m, where float32 resolution would be
  0.06 m), and shortens every segment by the scene-scaled ``ray_offset`` at both ends.
* :class:`~wavepaths.raycast.numpy_caster.NumpyRayCaster`: a float64 Möller-Trumbore
  in numpy, exact enough to serve as a reference on small scenes; the tests hold the
  two together.
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

        The segment is shortened by the scene's ``ray_offset`` at both ends, so end
        points lying on surfaces (reflection and diffraction points) do not block it.
        """
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


def shortened(a: np.ndarray, b: np.ndarray, offset: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Origins, unit directions and lengths of segments shortened by ``offset`` at each end.

    Returns
    -------
    origin : (k, 3) float64
    direction : (k, 3) float64
    length : (k,) float64
        May be <= 0 for segments shorter than ``2 * offset``: such segments are never
        occluded (both ends sit on the same surface point within tolerance).
    """
    d = b - a
    full = np.linalg.norm(d, axis=1)
    unit = d / np.where(full > 0, full, 1.0)[:, None]
    start = a + offset * unit
    end = b - offset * unit  # from b itself, not a + (|b - a| - 2 offset) u: no rounding at far ends
    length = np.einsum("ij,ij->i", end - start, unit)
    return start, unit, length
