"""A float64 segment-occlusion reference in numpy (Möller-Trumbore)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from . import shortened

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene


class NumpyRayCaster:
    """Occlusion by testing every (segment, triangle) pair in float64.

    O(segments x triangles): meant for small scenes and as the reference the Embree
    caster is tested against.
    """

    def __init__(self, scene: "Scene", chunk: int = 4_000_000) -> None:
        self._corners = scene.vertices[scene.triangles]  # (f, 3, 3)
        self._offset = scene.length_tolerance(scene.tolerances.ray_offset)
        self._chunk = chunk
        self._rays = 0

    @property
    def rays_cast(self) -> int:
        return self._rays

    def occluded(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        a = np.asarray(a, dtype=np.float64).reshape(-1, 3)
        b = np.asarray(b, dtype=np.float64).reshape(-1, 3)
        origin, direction, length = shortened(a, b, self._offset)
        k = len(a)
        out = np.zeros(k, dtype=bool)
        live = np.nonzero(length > 0)[0]
        self._rays += len(live)
        if len(live) == 0:
            return out
        v0 = self._corners[:, 0]
        e1 = self._corners[:, 1] - v0
        e2 = self._corners[:, 2] - v0
        f = len(v0)
        step = max(1, self._chunk // max(f, 1))
        for s in range(0, len(live), step):
            sel = live[s : s + step]
            o = origin[sel][:, None, :]
            d = direction[sel][:, None, :]
            p = np.cross(d, e2[None])
            det = np.einsum("kfj,fj->kf", p, e1)
            ok = np.abs(det) > 1e-300
            inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
            tv = o - v0[None]
            u = np.einsum("kfj,kfj->kf", tv, p) * inv
            q = np.cross(tv, e1[None])
            v = np.einsum("kj,kfj->kf", direction[sel], q) * inv
            t = np.einsum("kfj,fj->kf", q, e2) * inv
            hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & (t < length[sel][:, None])
            out[sel] = hit.any(axis=1)
        return out
