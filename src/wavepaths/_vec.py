"""Row-wise 3-vector helpers shared by the numpy references of the compiled kernels.

The kernels add a dot product as ``(x0 y0 + x1 y1) + x2 y2``; ``np.einsum`` may add in
another order, and a decision next to a polygon's border, a sector's face or a triangle's
edge must come out the same bit for bit in both forms (docs/stress.md, "What blocks a
segment"). Every numpy reference of a kernel takes its dot products from here.
"""

from __future__ import annotations

import numpy as np


def dot3(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(...,) dot products over the last axis (of length 3), summed ``(u0 v0 + u1 v1) + u2 v2``."""
    return (u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1]) + u[..., 2] * v[..., 2]


def unit_cross(a: np.ndarray, b: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """unit(a x b) over the last axis, or ``fallback`` where a and b are parallel
    (``|a x b| <= 1e-12``, the kernels' ``_perp_unit`` threshold)."""
    c = np.cross(a, b)
    n = np.linalg.norm(c, axis=-1, keepdims=True)
    return np.where(n > 1e-12, c / np.where(n > 0, n, 1.0), fallback)


def unit(v: np.ndarray) -> np.ndarray:
    """``v`` divided by its norm over the last axis (zero vectors left as they are)."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)

