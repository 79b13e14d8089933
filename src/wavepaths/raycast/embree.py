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
    float32 enters here and only here, and three guards keep it harmless:

    1. vertices and rays are expressed relative to ``scene.center`` before the cast, so
       positions resolve to ~6e-8 of the scene's half-size whatever their absolute
       coordinates (city scenes sit near 1e6 m);
    2. each segment is clipped, in float64, to the scene's bounding box (a transmitter
       20 km away gives a ray no longer than the scene), because a float32 direction
       misplaces the far end of a ray by ~6e-8 of its length;
    3. the ray starts from the end nearer the scene centre, and both original ends are
       pulled in by ``scene.tolerances.ray_offset * scene.diagonal`` (1e-6 of the
       diagonal: ~30x the float32 resolution), so an end lying on a surface (a
       reflection or diffraction point) is not reported as a hit.
    """

    def __init__(self, scene: "Scene", batch: int = 1 << 20) -> None:
        self._center = scene.center.copy()
        self._offset = scene.length_tolerance(scene.tolerances.ray_offset)
        self._batch = batch
        lo, hi = scene.bounds - self._center
        pad = 10 * self._offset + 1e-9
        self._lo, self._hi = lo - pad, hi + pad
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
        origin, direction, length = self._prepare(a - self._center, b - self._center)
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

    def _prepare(self, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Shorten, clip to the bounding box and orient segments (float64, recentred)."""
        origin, direction, length = shortened(a, b, self._offset)
        # slab clipping of [0, length] against the box
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / direction
            t1 = (self._lo - origin) * inv
            t2 = (self._hi - origin) * inv
        tmin = np.nanmax(np.where(np.isfinite(np.minimum(t1, t2)), np.minimum(t1, t2), -np.inf), axis=1)
        tmax = np.nanmin(np.where(np.isfinite(np.maximum(t1, t2)), np.maximum(t1, t2), np.inf), axis=1)
        inside_box = ((origin >= self._lo) & (origin <= self._hi)) | (direction != 0)
        t0 = np.maximum(tmin, 0.0)
        t_end = np.minimum(tmax, length)
        empty = (t_end <= t0) | ~inside_box.all(axis=1)
        start = origin + t0[:, None] * direction
        end = origin + t_end[:, None] * direction
        # cast from the end nearer the centre: float32 direction errors grow away from the origin
        swap = np.einsum("ij,ij->i", start, start) > np.einsum("ij,ij->i", end, end)
        new_origin = np.where(swap[:, None], end, start)
        new_dir = np.where(swap[:, None], -direction, direction)
        return new_origin, new_dir, np.where(empty, 0.0, t_end - t0)

    def __getstate__(self) -> dict:  # Embree handles do not pickle: rebuild on the worker
        raise TypeError("EmbreeRayCaster is rebuilt per process from its Scene; pickle the Scene instead")
