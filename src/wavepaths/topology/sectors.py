"""The angular sectors around each dihedron's edge, for receiver-independent pruning.

Around an edge, its faces cut the plane perpendicular to it into sectors. A point
(a transmitter or one of its images) can start a diffracted path only from a sector
wider than pi (a convex wedge's outside): this depends on the point and the edge
line only, not on where along the edge the path lands, so the path search evaluates
it once per (source, dihedron) and drops the rest before any receiver is looked at.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .dihedra import Dihedra

FACE_ANGLE_TOL = 1e-7  # [rad] a point this close to a face's direction is "on the face": FindDihedron's
# cosine tests resolve angles to ~1.5e-8 rad only, so the pre-filter must not be finer than that


@dataclass(frozen=True)
class SectorTable:
    """Sorted face angles around each edge, padded to ``m`` faces.

    Attributes
    ----------
    x_hat, y_hat : (d, 3) float64
        In-plane frame of each edge (``x_hat`` = first face's ``P_f``, ``y_hat = w x x_hat``).
    angles : (d, m) float64
        Face angles in [0, 2 pi), ascending; padding is +inf.
    count : (d,) int64
    width : (d, m) float64
        Width [rad] of the sector starting at ``angles[:, j]`` (counter-clockwise).
    face : (d, m) int64
        Index (into the dihedra's face arrays) of the face at ``angles[:, j]``; -1 for padding.
        The sector starting at slot ``j`` is bounded by ``face[:, j]`` (its ``face_0``, from
        which the UTD angles are measured) and ``face[:, (j + 1) % count]`` (its ``face_n``).
    """

    x_hat: np.ndarray
    y_hat: np.ndarray
    angles: np.ndarray
    count: np.ndarray
    width: np.ndarray
    face: np.ndarray


def sector_table(dihedra: Dihedra) -> SectorTable:
    d = len(dihedra)
    count = np.diff(dihedra.face_ptr)
    m = max(int(count.max()) if d else 1, 1)
    owner = np.repeat(np.arange(d), count)
    w = dihedra.direction
    x_hat = dihedra.face_direction[dihedra.face_ptr[:-1]] if d else np.zeros((0, 3))
    y_hat = np.cross(w, x_hat)
    pf = dihedra.face_direction
    ang = np.mod(np.arctan2(np.einsum("ij,ij->i", pf, y_hat[owner]), np.einsum("ij,ij->i", pf, x_hat[owner])), 2 * np.pi)
    table = np.full((d, m), np.inf)
    slot = np.arange(len(owner)) - dihedra.face_ptr[:-1][owner]
    table[owner, slot] = ang
    face = np.full((d, m), -1, dtype=np.int64)
    face[owner, slot] = np.arange(len(owner))
    order = np.argsort(table, axis=1, kind="stable")
    table = np.take_along_axis(table, order, axis=1)
    face = np.take_along_axis(face, order, axis=1)
    nxt = np.roll(table, -1, axis=1)
    last = count - 1
    rows = np.arange(d)
    nxt[rows, last] = table[rows, 0] + 2 * np.pi
    finite = np.isfinite(table)
    width = np.zeros_like(table)
    width[finite] = nxt[finite] - table[finite]
    return SectorTable(x_hat, y_hat, table, count, width, face)


def sector_of(table: SectorTable, dihedron: np.ndarray, points: np.ndarray, origin: np.ndarray,
              tol: float = FACE_ANGLE_TOL):
    """Sector index and width for ``points`` around ``dihedron`` edges.

    See :func:`sector_angle`, which also returns the angle inside the sector.
    """
    sector, width, _ = sector_angle(table, dihedron, points, origin, tol)
    return sector, width


def sector_angle(table: SectorTable, dihedron: np.ndarray, points: np.ndarray, origin: np.ndarray,
                 tol: float = FACE_ANGLE_TOL):
    """Sector index, width and angle inside the sector for ``points`` around ``dihedron`` edges.

    A sector is a prism around the whole edge line, so the sector of a point does not
    depend on where along the edge it is seen from: the seed's FindDihedron (§3.3) at a
    diffraction point P accepts a path E-P-R exactly when E and R lie in the same
    sector, and the true dihedron's faces are that sector's two bounding faces
    (``table.face``). The angle ``phi`` returned here is measured counter-clockwise
    about the edge from the sector's first face: for E it is the UTD ``phi'``, for R
    the UTD ``phi`` (both in ``(0, width)``), as :func:`~.find_dihedron.find_dihedron`
    computes them at P.

    Parameters
    ----------
    table : SectorTable
    dihedron : (k,) int64
    points : (k, 3) float64
    origin : (k, 3) float64
        A point on each edge line.
    tol : float
        Angular margin [rad]: points within it of a face, or on the edge line, get
        sector -1 (never a diffraction source).

    Returns
    -------
    sector : (k,) int64
    width : (k,) float64
    phi : (k,) float64
        Angle from the sector's first face [rad]; 0 where ``sector`` is -1.
    """
    v = points - origin
    x = np.einsum("ij,ij->i", v, table.x_hat[dihedron])
    y = np.einsum("ij,ij->i", v, table.y_hat[dihedron])
    sector, width, phi = sector_lookup(table, dihedron, x, y, tol)
    return sector, width, np.where(sector < 0, 0.0, phi)


def sector_lookup(table: SectorTable, dihedron: np.ndarray, x: np.ndarray, y: np.ndarray,
                  tol: float = FACE_ANGLE_TOL):
    """Sector, width and angle-in-sector of edge-frame coordinates ``(x, y)`` around ``dihedron``.

    The kernel of :func:`sector_angle`, shared with the path search. ``dihedron`` has shape
    (k,) and ``x``, ``y`` (along ``x_hat`` and ``y_hat``) shape (k,) or (e, k): the edge
    tables broadcast over the leading axis (the search's dense receiver side), nothing is
    gathered per pair. Within ``tol`` of a bounding face, or on the edge line, the sector is
    -1 (and its width 0). Only the sector's two bounding faces can be the nearest ones, so
    that test needs no loop over the faces.
    """
    theta = np.arctan2(y, x)
    theta += np.where(theta < 0, 2 * np.pi, 0.0)
    ang = table.angles[dihedron]  # (k, m), broadcast against theta's leading axes
    below = np.zeros(theta.shape, dtype=np.int64)
    for j in range(ang.shape[1]):  # m: a few faces; a loop over face slots, not over points
        below += ang[:, j] <= theta
    sec = np.mod(below - 1, table.count[dihedron])
    cols = np.arange(len(dihedron)) if theta.ndim == 1 else np.arange(len(dihedron))[None, :]
    start = ang[cols, sec]
    width = table.width[dihedron][cols, sec]
    phi = theta - start
    phi += np.where(phi < 0, 2 * np.pi, 0.0)
    on_face = (phi < tol) | (width - phi < tol) | ((x == 0) & (y == 0))
    return np.where(on_face, -1, sec), np.where(on_face, 0.0, width), phi
