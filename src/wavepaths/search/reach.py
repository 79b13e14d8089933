"""Per-mirror reach lists of the receiver side: for every polygon, the dihedra whose
Keller cones from some diffraction source of one order can reach it.

With ``b >= 1`` reflections after the edge, the first leg after the diffraction ends on the
receiver image's last mirror; a (receiver image, dihedron) pair can hold a path only if that
mirror is in reach. The lists depend on the sources only, so
:func:`wavepaths.search.diffraction.diffraction_tile` builds them once per context and
order, and every tile walks them (:mod:`wavepaths.search._numba_reach`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from . import kernels

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene
    from .diffraction import KellerFrame


MIRROR_REACH_BUDGET = 1 << 28
"""(polygon, source) pairs above which :func:`mirror_reach` is not built for an order (the
receiver side then runs without its lists). munich's order-0 sources: 23 k polygons x 5 k
sources, 2.9-4.6 s on two threads for 13.8 M entries; its order-2 sources (11 M) would
take hours."""

REACH_SLACK = 1e-7
"""Margin of :func:`mirror_reach` in the cosine domain: the cosines are formed without
inverse functions, and ``sin theta = sqrt(1 - cos^2 theta)`` carries an absolute error up to
``sqrt(2.2e-16) ~ 1.5e-8`` near theta = 0 or pi."""


@dataclass(frozen=True)
class MirrorReach:
    """Per polygon ``p``, the dihedra whose Keller cones, from some source of one order, can
    reach ``p``'s bounding sphere: ``dihedra[ptr[p]:ptr[p + 1]]``, ascending (CSR).

    A diffracted path leaves the edge along the Keller cone of its incident ray (the cone
    with the edge as axis, opening the angle of incidence, seed §2.1), and with ``b >= 1``
    reflections after the edge its first leg ends on the receiver image's last mirror. So a
    (receiver image, dihedron) pair can hold a path only if the dihedron is in the list of
    the image's last mirror. The lists depend on the sources only: built once per context
    and order (:func:`mirror_reach`), they serve every tile.
    """

    ptr: np.ndarray  # (num_polygons + 1,) int64
    dihedra: np.ndarray  # (k,) int64

    def sizes(self, polygons: np.ndarray) -> np.ndarray:
        """(n,) int64: the lengths of the lists of ``polygons``."""
        return self.ptr[polygons + 1] - self.ptr[polygons]

    def mask(self, q: np.ndarray, col: np.ndarray, D: int) -> np.ndarray:
        """(E, D) bool: the (image, column) pairs whose dihedron is in the list of the
        image's last mirror ``q`` (E,); ``col`` maps a dihedron to its column among the D,
        -1 for none (the numpy twin of the kernel that walks the lists)."""
        uq, inv = np.unique(q, return_inverse=True)
        size = self.sizes(uq)
        row = np.repeat(np.arange(len(uq)), size)
        pos = np.repeat(self.ptr[uq], size) + np.arange(len(row)) - np.repeat(np.cumsum(size) - size, size)
        j = col[self.dihedra[pos]]
        table = np.zeros((len(uq), D), dtype=bool)
        table[row[j >= 0], j[j >= 0]] = True
        return table[inv.ravel()]


def _reach_cosines(X: np.ndarray, w: np.ndarray, c: np.ndarray, r: float, slack: float):
    """Per edge end ``X`` (u, 3) with edge direction ``w``: ``cos(max(theta - delta, 0)) + slack``
    and ``cos(min(theta + delta, pi)) - slack``, with ``theta`` the angle between ``w`` and
    ``c - X`` and ``delta`` the angular radius of the sphere (``c``, ``r``) seen from X (pi
    from inside it), formed as cosines of sums (no inverse functions)."""
    v = c - X
    dist = np.linalg.norm(v, axis=1)
    inside = dist <= r
    d = np.where(inside, 1.0, dist)
    ct = np.clip(np.einsum("ij,ij->i", v, w) / d, -1.0, 1.0)
    st = np.sqrt(np.maximum(1.0 - ct * ct, 0.0))
    sd = np.where(inside, 0.0, r / d)
    cd = np.sqrt(np.maximum(1.0 - sd * sd, 0.0))
    lo = np.where(inside | (ct >= cd), 1.0, ct * cd + st * sd)
    hi = np.where(inside | (ct <= -cd), -1.0, ct * cd - st * sd)
    return lo + slack, hi - slack


def mirror_reach(scene: "Scene", frame: "KellerFrame", compiled: bool = False) -> MirrorReach:
    """The :class:`MirrorReach` lists of the sources of ``frame``, for every polygon.

    The Keller-cone test of :func:`~wavepaths.search.diffraction.keller_cone_keep` against each polygon's bounding sphere
    (:func:`~wavepaths.scene.polygon_shapes.polygon_spheres`), with the margin :data:`REACH_SLACK`:
    a source reaches the sphere at some point of its edge iff ``cos_a <= cos(max(theta_A -
    delta_A, 0))`` and ``cos_b >= cos(min(theta_B + delta_B, pi))``. ``compiled``: both passes
    (the lengths, then the lists) as parallel loops over polygons
    (:mod:`wavepaths.search._numba_reach`, the same expressions).
    """
    centre, radius = scene.polygon_spheres
    P = len(radius)
    if compiled and kernels.available():
        k = kernels._compiled()
        c = np.ascontiguousarray
        args = (c(frame.A), c(frame.B), c(frame.w), c(frame.inv, dtype=np.int64), c(frame.cos_a), c(frame.cos_b),
                c(centre), c(radius), REACH_SLACK)
        counts = np.empty(P, np.int64)
        k["mirror_reach_counts"](*args, counts)
        ptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        out = np.empty(int(ptr[-1]), np.int64)
        k["mirror_reach_fill"](*args, c(frame.dihedra, dtype=np.int64), ptr, out)
        return MirrorReach(ptr, out)
    lists = []
    for p in range(P):
        lo_a, _ = _reach_cosines(frame.A, frame.w, centre[p], radius[p], REACH_SLACK)
        _, hi_b = _reach_cosines(frame.B, frame.w, centre[p], radius[p], REACH_SLACK)
        keep = (frame.cos_a <= lo_a[frame.inv]) & (frame.cos_b >= hi_b[frame.inv])
        lists.append(frame.dihedra[np.unique(frame.inv[keep])])
    ptr = np.concatenate([[0], np.cumsum([len(x) for x in lists])]).astype(np.int64)
    return MirrorReach(ptr, np.concatenate(lists).astype(np.int64) if lists else np.zeros(0, np.int64))
