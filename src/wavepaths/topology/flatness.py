"""Flat edges by distance (step 3 of :func:`wavepaths.topology.dihedra.build_dihedra`).

Float32 mesh files turn a thin triangle's face direction far beyond ``coplanar_angle`` but
move none of its corners off its plane by more than the rounding. These tests call faces
coplanar when a corner lies within ``plane_distance`` of the reference face's plane and the
fold stays under ``flat_angle`` (docs/scenes.md, "Cleaning").
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene


def coplanar_entries(scene: "Scene", w: np.ndarray, entry_edge: np.ndarray, pf: np.ndarray, height: np.ndarray,
                     ptr: np.ndarray, cos_tol: float) -> np.ndarray:
    """Face entries coplanar with their edge's reference face: within ``coplanar_angle`` of its
    direction (or of the opposite one), or with their corner within the plane tolerance of its plane.

    An edge is flat when its faces are coplanar. Measured by the angle between face directions
    alone, a thin triangle fails: the directions come from vertices rounded to float32 in the
    mesh file (about 6e-8 of the coordinates, 5e-5 m at 800 m), so a face whose corner is 0.1 m
    from the edge points up to 5e-4 rad off, and a wall's triangulation diagonal became a
    dihedron with n - 1 ~ 1e-5 (4,769 of munich's 36,565 diffracting dihedra had n - 1 < 1e-4,
    170 of etoile's 9,094). The measure that this rounding cannot fool is a distance: the
    corner's height above the plane through the edge and the reference face's direction,
    compared with ``plane_distance`` (1e-6 of the scene's size, the tolerance at which a point
    lies in a plane): moving the corner by less than that makes the faces coplanar, unless
    they fold by more than ``flat_angle`` (a narrow facet of a faceted curved surface: a real
    crease, whose corner is near its neighbour's plane only because the facet is narrow). The
    reference is the edge's tallest face (the one whose direction the rounding disturbs least);
    on an edge without corners (every entry a half-face of a polygon the edge runs inside,
    ``height`` inf), its first entry, with the angle test alone.

    Parameters
    ----------
    w : (e, 3) float64
        Unit direction of each edge.
    entry_edge : (m,) int64
        Edge of each face entry, sorted (CSR order, ``ptr``).
    pf : (m, 3) float64
        Unit face direction of each entry (in the face plane, perpendicular to the edge).
    height : (m,) float64
        Distance of each entry's corner from the edge [m] (inf where it has none).
    ptr : (e + 1,) int64
        CSR pointer of the entries per edge.
    cos_tol : float
        ``cos(coplanar_angle)``.

    Returns
    -------
    (m,) bool
    """
    num_e = len(ptr) - 1
    finite = np.where(np.isfinite(height), height, -1.0)
    tallest = np.full(num_e, -1.0)
    np.maximum.at(tallest, entry_edge, finite)
    idx = np.flatnonzero((finite == tallest[entry_edge]) & (finite >= 0.0))
    ref = np.full(num_e, len(pf), dtype=np.int64)
    np.minimum.at(ref, entry_edge[idx], idx)  # the first of equally tall entries
    ref = np.where(ref < len(pf), ref, ptr[:-1])  # the first entry where no entry has a corner
    p_ref = pf[ref[entry_edge]]
    angle_ok = np.abs(np.einsum("ij,ij->i", pf, p_ref)) >= cos_tol
    sin_fold = np.abs(np.einsum("ij,ij->i", pf, np.cross(w[entry_edge], p_ref)))
    tol = scene.length_tolerance(scene.tolerances.plane_distance)
    near = sin_fold * np.where(np.isfinite(height), height, 0.0) <= tol  # the corner off the plane [m]
    return angle_ok | (np.isfinite(height) & near & (sin_fold <= np.sin(scene.tolerances.flat_angle)))


def flat_widest_sector(scene: "Scene", w: np.ndarray, entry_edge: np.ndarray, pf: np.ndarray, height: np.ndarray,
                       srt: np.ndarray, nxt: np.ndarray, gaps: np.ndarray, max_sector: np.ndarray,
                       counts: np.ndarray) -> np.ndarray:
    """(e,) bool: edges whose widest sector is flat by distance, so that they never diffract.

    The faces bounding an edge's widest sector (the air side of two facades continuing each
    other, with party walls behind) can be a few 1e-5 rad from coplanar after float32
    rounding, which made that sector wider than pi + ``coplanar_angle`` and the edge a
    diffracting dihedron with n - 1 ~ 1e-5 (78 of munich's, 14 of etoile's). The test is
    :func:`coplanar_entries`' distance, on the two bounding faces: opposite directions, and
    the corner of the shorter within the plane tolerance of the taller's plane, folding by at
    most ``flat_angle``. Bounding faces without corners (half-faces of a polygon the edge runs
    inside) keep the angle test alone.

    ``srt`` orders the entries by (edge, angle); ``gaps[i]`` is the sector from entry
    ``srt[i]`` to entry ``srt[nxt[i]]``; ``max_sector`` the widest per edge.
    """
    num_e = len(counts)
    e_of = entry_edge[srt]
    widest = np.flatnonzero(gaps == max_sector[e_of])
    first = np.full(num_e, len(gaps), dtype=np.int64)
    np.minimum.at(first, e_of[widest], widest)  # the first widest sector of each edge
    has = (first < len(gaps)) & (counts >= 2)
    e = np.flatnonzero(has)
    p, q = srt[first[e]], srt[nxt[first[e]]]
    hp, hq = height[p], height[q]
    ok = np.isfinite(hp) & np.isfinite(hq) & (np.einsum("ij,ij->i", pf[p], pf[q]) < 0)
    tall = hp >= hq
    ref, other = np.where(tall, p, q), np.where(tall, q, p)
    sin_fold = np.abs(np.einsum("ij,ij->i", pf[other], np.cross(w[e], pf[ref])))
    off = sin_fold * np.where(ok, height[other], 0.0)  # the shorter's corner off the taller's plane [m]
    out = np.zeros(num_e, dtype=bool)
    out[e] = (ok & (off <= scene.length_tolerance(scene.tolerances.plane_distance))
              & (sin_fold <= np.sin(scene.tolerances.flat_angle)))
    return out
