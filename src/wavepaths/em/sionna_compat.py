"""Sionna RT 2.2's diffraction combination, re-implemented as a compat mode.

Not physics: ``R0 (d1 - d4) + Rn (d2 - d3)`` is what Sionna RT 2.2 computes
(docs/sionna-diffraction.md), reproduced so that the rest of the chain can be compared with
Sionna like for like. The textbook coefficients are in :mod:`wavepaths.em.utd`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from wavepaths.em.fresnel import reflection_coefficients
from wavepaths.em.materials import Material
from wavepaths.em.utd_terms import SIN_BETA_0_FLOOR, Array, CArray, _check_floor, _check_r, _four_terms, _prepare
from wavepaths.em.wedge_faces import FaceCoefficients
from wavepaths.errors import WavepathsError

__all__ = ["sionna_compat_coefficients", "sionna_face_coefficients"]


def sionna_face_coefficients(
    material: Material, frequency_hz: float, phi_prime: ArrayLike, beta_0: ArrayLike,
    n: ArrayLike, *, scattering_coefficient: float = 0.0,
) -> FaceCoefficients:
    """Face coefficients as Sionna RT 2.2 ``_diffraction_matrix`` computes them.

    Single-layer slab (P.2040 eqs. 43-44, ``material.thickness_m``) of the one material for
    both faces, both at the *incident* direction: ``cos theta0 = |k_i . n0| = sin b0 |sin
    phi'|`` and ``cos thetan = |k_i . nn| = sin b0 |sin(n pi - phi')|``, all scaled by
    ``sqrt(1 - S^2)`` (``S`` the scattering coefficient). Returned in the fields
    ``(r0_s, r0_h, rn_s, rn_h)`` = ``(r_te, r_tm)`` of each face.
    """
    if not 0.0 <= scattering_coefficient <= 1.0:
        raise WavepathsError("`scattering_coefficient` must lie in [0, 1]")
    pp, b0, nn = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (phi_prime, beta_0, n)))
    sb = np.abs(np.sin(b0))
    red = np.sqrt(1.0 - scattering_coefficient**2)
    r0 = reflection_coefficients(material, frequency_hz, sb * np.abs(np.sin(pp)), "slab")
    rn = reflection_coefficients(material, frequency_hz, sb * np.abs(np.sin(nn * np.pi - pp)), "slab")
    return FaceCoefficients(red * r0.r_te, red * r0.r_tm, red * rn.r_te, red * rn.r_tm)


def _face_reflection_matrix(
    k_i: Array, b_in: Array, p_in: Array, normal: Array, psi_r: Array, sb: Array, cb: Array,
    r_te: CArray, r_tm: CArray,
) -> CArray:
    """Reflection off a face in edge-fixed bases: (E_b0', E_phi') -> (E_b_sb, E_phi_sb).

    The reflected wave propagates along k_r = (sb cos psi_r, sb sin psi_r, cb); its basis is
    phi_sb = (-sin psi_r, cos psi_r, 0), b_sb = k_r x phi_sb. The operator is
    E -> r_te (E.e_s) e_s + r_tm (E.p_i) p_r with e_s = unit(k_i x normal), p = k x e_s.
    """
    e_s = np.cross(k_i, normal)
    norm = np.linalg.norm(e_s, axis=-1, keepdims=True)
    degenerate = norm < 1e-12  # normal incidence on the face: any e_s perpendicular to k_i
    z = np.zeros_like(e_s)
    z[..., 2] = 1.0
    e_s = np.where(degenerate, z, e_s / np.where(degenerate, 1.0, norm))
    k_r = np.stack([sb * np.cos(psi_r), sb * np.sin(psi_r), cb], axis=-1)
    phi_sb = np.stack([-np.sin(psi_r), np.cos(psi_r), np.zeros_like(psi_r)], axis=-1)
    b_sb = np.cross(k_r, phi_sb)
    p_i = np.cross(k_i, e_s)
    p_r = np.cross(k_r, e_s)

    def dot(a: Array, b: Array) -> Array:
        return np.sum(a * b, axis=-1)

    out = np.empty(psi_r.shape + (2, 2), dtype=np.complex128)
    for col, v in enumerate((b_in, p_in)):
        vs, vp = dot(v, e_s), dot(v, p_i)
        for row, w in enumerate((b_sb, phi_sb)):
            out[..., row, col] = r_te * vs * dot(e_s, w) + r_tm * vp * dot(p_r, w)
    return out


def sionna_compat_coefficients(
    phi: ArrayLike, phi_prime: ArrayLike, beta_0: ArrayLike, n: ArrayLike, k: ArrayLike,
    L: ArrayLike, r0_te: ArrayLike = -1.0, r0_tm: ArrayLike = 1.0, rn_te: ArrayLike = -1.0,
    rn_tm: ArrayLike = 1.0, *, sin_beta_0_floor: float = SIN_BETA_0_FLOOR,
) -> CArray:
    """Sionna RT 2.2's diffraction Jones matrix (``RadioMaterial._diffraction_matrix``).

    A compat mode, re-implemented from Sionna's formula (see ``docs/sionna-diffraction.md``)::

        J = R0 (d1 - d4) + Rn (d2 - d3)

    with ``d_i`` the KP terms times KP's prefactor and ``R0``, ``Rn`` the 2x2 reflection
    matrices of the 0- and n-face for the *incident* ray, mapping the incident edge-fixed
    components to those of the reflected wave in its own edge-fixed basis (the basis of the
    reflection shadow boundary), which Sionna uses unchanged as the diffracted basis.
    ``Rn = -I`` whenever ``n pi > pi + phi'`` (n-face not lit), whatever the material. For a
    PEC, ``R0 = Rn = diag(+1, -1)`` in ``(b, phi)`` order, so when both faces are lit
    ``J = diag(D_s, -D_s)``: KP's ``D_s`` with the opposite sign of KP's dyadic for the
    soft component and ``D_s`` in place of ``D_h`` for the hard one.

    Bases: input ``(E_b0', E_phi')``, output ``(E_b0, E_phi)`` with ``phi' = unit(s' x e)``,
    ``b0' = s' x phi'``, ``phi = unit(e x s)``, ``b0 = s x phi`` -- the same unit vectors as
    Sionna's ``phi_hat_prime``, ``k_i x phi_hat_prime``, ``phi_hat``, ``k_o x phi_hat``.
    Sionna orders them ``(phi, b0)``, so ``J_ours = P J_sionna P`` with ``P = [[0,1],[1,0]]``.
    Differences that remain: double precision and the exact ``F`` instead of Sionna's
    float32 Boersma Fresnel integrals (relative ~1e-5), and exactly on a boundary the mean
    of the one-sided limits instead of Sionna's ``sin psi >= 0`` side.

    Parameters
    ----------
    phi, phi_prime, beta_0, n, k, L : array_like
        As :func:`kp_coefficients`; ``beta_0`` in ``[0, pi]`` is the angle of the incident
        propagation direction to the edge.
    r0_te, r0_tm, rn_te, rn_tm : complex array_like
        Slab TE/TM coefficients of the faces at Sionna's angles
        (:func:`sionna_face_coefficients`); defaults are PEC.

    Returns
    -------
    (..., 2, 2) complex128
    """
    _check_floor(sin_beta_0_floor, "sin_beta_0_floor")
    p, pp, b0, nn, kk, ll = _prepare(phi, phi_prime, beta_0, n, k, L)
    d1, d2, d3, d4 = _four_terms(p, pp, b0, nn, kk, ll, sin_beta_0_floor, None)
    shape = p.shape
    rr = [np.broadcast_to(r, shape) for r in _check_r(r0_te, r0_tm, rn_te, rn_tm)]
    sb, cb = np.sin(b0), np.cos(b0)
    k_i = np.stack([-sb * np.cos(pp), -sb * np.sin(pp), cb], axis=-1)
    phi_in = np.stack([-np.sin(pp), np.cos(pp), np.zeros(shape)], axis=-1)
    b_in = np.cross(k_i, phi_in)
    n0 = np.broadcast_to(np.array([0.0, 1.0, 0.0]), shape + (3,))
    nnv = np.stack([np.sin(nn * np.pi), -np.cos(nn * np.pi), np.zeros(shape)], axis=-1)
    r0m = _face_reflection_matrix(k_i, b_in, phi_in, n0, np.pi - pp, sb, cb, rr[0], rr[1])
    rnm = _face_reflection_matrix(k_i, b_in, phi_in, nnv, (2 * nn - 1) * np.pi - pp, sb, cb, rr[2], rr[3])
    unlit_n = nn * np.pi > np.pi + pp
    minus_i = np.broadcast_to(-np.eye(2, dtype=np.complex128), rnm.shape)
    rnm = np.where(unlit_n[..., None, None], minus_i, rnm)
    return r0m * (d1 - d4)[..., None, None] + rnm * (d2 - d3)[..., None, None]


