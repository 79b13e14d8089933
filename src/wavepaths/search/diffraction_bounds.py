"""Conservative bounds of the diffraction search, which drop candidates without losing a path.

* The Keller cone (the diffracted rays leave the edge on the cone whose opening
  equals the incident angle): :class:`KellerFrame` holds the incident cones' cosines at the
  edges' ends per diffraction source, and :func:`keller_cone_keep` keeps the sources whose
  cones can reach a sphere around a chunk of receivers (images).
* The UTD amplitude bound (:func:`_diffraction_amplitude_bound`): an upper bound on a
  diffracted candidate's coefficient with passive reflections and unit antenna patterns,
  for the pruning of weak candidates (``TraceOptions.prune_db``) and the tolerance of
  coverage maps (``TraceOptions.tolerance_db``).

:mod:`wavepaths.search.diffraction` uses both in its candidate search (and re-exports them).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from . import kernels
from .spheres import vector_angle

if TYPE_CHECKING:  # pragma: no cover
    from .context import TxContext


@dataclass(frozen=True)
class KellerFrame:
    """Per diffraction source (image S, dihedron from A to B, unit direction ``w``): the
    cosines of the incident cone at the edge's ends, ``cos beta_X = w.(X - S)/|X - S|``
    (:func:`keller_cone_keep`); the edges themselves once per distinct dihedron (munich's
    25 M order-2 sources lie on at most its 36 k dihedra). Receiver-independent: built once
    per context and order."""

    dihedra: np.ndarray  # (u,) int64, the distinct dihedra of the sources
    inv: np.ndarray  # (c,) int64, each source's row in ``dihedra``
    A: np.ndarray  # (u, 3) [m]
    B: np.ndarray  # (u, 3) [m]
    w: np.ndarray  # (u, 3)
    cos_a: np.ndarray  # (c,)
    cos_b: np.ndarray  # (c,)


FRAME_BLOCK = 1 << 20
"""Sources per block when a :class:`KellerFrame` is built (bounds its temporaries)."""


def keller_frame(dihedra, src, sources: np.ndarray) -> KellerFrame:
    """The :class:`KellerFrame` of the sources ``src`` at image points ``sources`` (c, 3)."""
    ud, inv = np.unique(src.dihedron, return_inverse=True)
    w = np.ascontiguousarray(dihedra.direction[ud])
    A = np.ascontiguousarray(dihedra.origin[ud])
    B = A + dihedra.length[ud][:, None] * w
    k = len(inv)
    cos_a, cos_b = np.empty(k), np.empty(k)
    for s in range(0, k, FRAME_BLOCK):
        i, S = inv[s : s + FRAME_BLOCK], sources[s : s + FRAME_BLOCK]
        for X, out in ((A, cos_a), (B, cos_b)):
            v = X[i] - S
            out[s : s + len(i)] = np.einsum("ij,ij->i", v, w[i]) / np.maximum(np.linalg.norm(v, axis=1), 1e-300)
    return KellerFrame(ud, inv.astype(np.int64).ravel(), A, B, w, cos_a, cos_b)


def keller_cone_keep(frame: KellerFrame, targets: np.ndarray, compiled: bool = False) -> np.ndarray | None:
    """(c,) bool: the (source, dihedron) pairs whose Keller cones can reach a sphere around
    ``targets``; ``None`` when all can.

    Along an edge from A (t = 0) to B (t = L), a receiver R is reached at some point iff
    ``w.(R - A)/|R - A| >= cos beta_A`` and ``w.(R - B)/|R - B| <= cos beta_B`` with
    ``cos beta_X = w.(X - S)/|X - S|`` (the diffracted cone's opening equals the incident
    angle, and both sides are monotonic in t). For a sphere (C, r) each side is tested
    with the angular margin ``asin(r / |C - X|)``: conservative, so no path is lost.
    The sphere's side depends on the dihedron only: ``cos(max(theta_A - delta_A, 0))`` and
    ``cos(min(theta_B + delta_B, pi))`` are found once per distinct dihedron, and each
    source compares its two cosines with them. ``compiled``: both steps as compiled loops
    (:func:`wavepaths.search._numba_diffraction.keller_cone_keep`; the same expressions).
    """
    if len(frame.inv) == 0 or len(targets) == 0:
        return None
    c = targets.mean(axis=0)
    r = float(np.linalg.norm(targets - c, axis=1).max()) * (1 + 1e-9) + 1e-9
    slack = 1e-9
    if compiled and kernels.available():
        from . import _numba

        keep = np.empty(len(frame.inv), dtype=np.bool_)
        n = _numba.keller_cone_keep(frame.A, frame.B, frame.w, frame.inv, frame.cos_a, frame.cos_b, c, r, slack, keep)
        return None if n == len(keep) else keep
    w = frame.w

    def angle_range(X):
        v = c - X
        dist = np.linalg.norm(v, axis=1)
        theta = vector_angle(v, np.broadcast_to(w, v.shape))
        delta = np.where(dist > r, np.arcsin(np.clip(r / np.maximum(dist, 1e-300), 0, 1)), np.pi)
        return theta, delta

    th_a, de_a = angle_range(frame.A)
    th_b, de_b = angle_range(frame.B)
    reach_a = np.cos(np.maximum(th_a - de_a, 0.0)) + slack  # per dihedron: reached iff cos_a <= reach_a
    reach_b = np.cos(np.minimum(th_b + de_b, np.pi)) - slack  # ... and cos_b >= reach_b
    keep = (frame.cos_a <= reach_a[frame.inv]) & (frame.cos_b >= reach_b[frame.inv])
    return None if keep.all() else keep


UTD_BOUND_FLOOR = 1e-6
"""``sin_beta_0_floor`` of :func:`~wavepaths.em.utd.utd_magnitude_bound` in the amplitude bounds
(its default)."""


def _diffraction_amplitude_bound(ctx: TxContext, phi: np.ndarray, phi_prime: np.ndarray, n: np.ndarray,
                                 te: np.ndarray, de: np.ndarray, tr: np.ndarray, dr: np.ndarray,
                                 t: np.ndarray) -> np.ndarray:
    """(k,) float64 [1/m]: an upper bound on ``|a| / (lambda / 4 pi)`` of diffracted candidates.

    With passive reflections (``|Gamma| <= 1``) before and after the edge and unit antenna
    patterns, a diffracted path's coefficient is at most
    ``(lambda / 4 pi) |D| / sqrt(s s' (s + s'))`` (UTD, spherical incidence; ``s'``, ``s`` the
    unfolded lengths before and after the edge, from the images' reduced coordinates:
    ``s' = sqrt((t_e - t)^2 + d_e^2)``, ``s = sqrt((t_r - t)^2 + d_r^2)``), with ``|D|`` at most
    :func:`~wavepaths.em.utd.utd_magnitude_bound` at the lowest frequency the fields will
    use (``prune_frequency_hz``; the bound does not grow with frequency). The result carries
    a 1 % margin for the rounding between the search's angles and the fields'.
    """
    from ..em.utd import utd_magnitude_bound
    from ..em.utd_terms import SIN_BETA_0_FLOOR
    from .paths import SPEED_OF_LIGHT

    k = 2.0 * np.pi * ctx.options.prune_frequency_hz / SPEED_OF_LIGHT
    s_in = np.sqrt((te - t) ** 2 + de * de)
    s_out = np.sqrt((tr - t) ** 2 + dr * dr)
    with np.errstate(divide="ignore", invalid="ignore"):
        sin_b = np.maximum(de / s_in, SIN_BETA_0_FLOOR)
        L = s_in * s_out / (s_in + s_out) * sin_b**2
        amp = 1.01 * utd_magnitude_bound(phi, phi_prime, sin_b, n, k, L, sin_beta_0_floor=UTD_BOUND_FLOOR) / np.sqrt(
            s_in * s_out * (s_in + s_out))
    return np.where(np.isfinite(amp), amp, np.inf)
