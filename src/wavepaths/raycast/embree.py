"""Segment occlusion through Embree (embreex), float32 on recentred coordinates."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from . import shortened

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene


class EmbreeRayCaster:
    """Occlusion queries against a scene with Embree.

    Parameters
    ----------
    scene : Scene
    batch : int
        Rays per Embree call (bounds the float32 temporaries).

    Notes
    -----
    float32 enters here and only here. Vertices and ray origins are expressed relative
    to ``scene.center`` before the cast to float32, so the resolution is ~6e-8 of the
    scene's half-size whatever its absolute coordinates; segments are shortened by
    ``scene.tolerances.ray_offset * scene.diagonal`` at both ends (30x that resolution).
    """

    def __init__(self, scene: "Scene", batch: int = 1 << 20) -> None:
        self._center = scene.center.copy()
        self._offset = scene.length_tolerance(scene.tolerances.ray_offset)
        self._batch = batch
        self._scene = rtcore_scene.EmbreeScene()
        corners = (scene.vertices[scene.triangles] - self._center).astype(np.float32)
        self._mesh = TriangleMesh(self._scene, corners)
        self._rays = 0

    @property
    def rays_cast(self) -> int:
        return self._rays

    def occluded(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        a = np.asarray(a, dtype=np.float64).reshape(-1, 3)
        b = np.asarray(b, dtype=np.float64).reshape(-1, 3)
        k = len(a)
        out = np.zeros(k, dtype=bool)
        if k == 0:
            return out
        origin, direction, length = shortened(a - self._center, b - self._center, self._offset)
        live = np.nonzero(length > 0)[0]
        for s in range(0, len(live), self._batch):
            sel = live[s : s + self._batch]
            hit = self._scene.run(
                origin[sel].astype(np.float32),
                direction[sel].astype(np.float32),
                query="OCCLUDED",
                dists=length[sel].astype(np.float32),
            )
            out[sel] = np.asarray(hit) != -1
        self._rays += len(live)
        return out

    def __getstate__(self) -> dict:  # Embree handles do not pickle: rebuild on the worker
        raise TypeError("EmbreeRayCaster is rebuilt per process from its Scene; pickle the Scene instead")
