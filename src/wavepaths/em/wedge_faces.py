"""The wedge faces' reflections for Luebbers' lossy-wedge diffraction coefficient.

The job of this module is the reflection of each face of the wedge as the diffraction
coefficients of :mod:`wavepaths.em.utd` need it:

* :func:`luebbers_face_coefficients`: the scalar Fresnel pairs ``R0``, ``Rn`` at Luebbers'
  angles (Luebbers, IEEE TAP 32(1):70-76, 1984; ITU-R P.526 wedge section), as
  :class:`FaceCoefficients`;
* :func:`edge_fixed_reflection`: a face's reflection ``G = -B_out^T R B_in`` as a 2x2 Jones
  matrix between KP's edge-fixed bases (``docs/conventions.md``);
* :func:`wedge_reflection_matrices`: the pair ``(G0, Gn)`` that replaces Luebbers' scalar
  ``R0``, ``Rn`` in :func:`~wavepaths.em.utd.diffraction_jones_matrices`.

Bases and sign conventions are those of :mod:`wavepaths.em.utd`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from wavepaths._vec import dot3, unit_cross
from wavepaths.em.fresnel import ReflectionModel, reflection_coefficients
from wavepaths.em.materials import Material
from wavepaths.em.utd_terms import CArray

__all__ = [
    "FaceCoefficients",
    "edge_fixed_reflection",
    "luebbers_face_coefficients",
    "wedge_reflection_matrices",
]


class FaceCoefficients(NamedTuple):
    """Face reflection coefficients for the diffraction coefficient, complex arrays.

    For Luebbers: ``r0_s, r0_h`` (0-face) and ``rn_s, rn_h`` (n-face), the soft ones being
    ``r_te`` and the hard ones ``r_tm`` of :mod:`wavepaths.em.fresnel`. For the Sionna
    compat mode the same fields hold ``r_te``/``r_tm`` at Sionna's angles.
    """

    r0_s: CArray
    r0_h: CArray
    rn_s: CArray
    rn_h: CArray


def luebbers_face_coefficients(
    material_0: Material, material_n: Material, frequency_hz: float, phi: ArrayLike,
    phi_prime: ArrayLike, n: ArrayLike, model: ReflectionModel = "half_space",
    *, beta_0: ArrayLike = np.pi / 2,
) -> FaceCoefficients:
    """Face reflection coefficients at Luebbers' angles (ITU-R P.526 wedge section).

    ``R0`` at grazing angle ``phi'`` on the 0-face (``cos theta = sin b0 |sin phi'|``) and
    ``Rn`` at grazing angle ``n pi - phi`` on the n-face (``cos theta = sin b0 |sin(n pi -
    phi)|``, the observer side). ``r_te`` goes with ``D_s`` and ``r_tm`` with ``D_h``, no sign
    change (PEC -> ``(-1, +1)``, exactly KP). With the default ``beta_0 = pi/2`` this is the
    2-D form of Luebbers / P.526; a ``beta_0`` uses the true 3-D angle of incidence on the
    face. Note: unlike KP, the result is not symmetric in ``phi <-> phi'``.

    Returns
    -------
    FaceCoefficients
        ``(r0_s, r0_h, rn_s, rn_h)``, complex128 of the broadcast shape.
    """
    p, pp, nn, b0 = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (phi, phi_prime, n, beta_0)))
    sb = np.abs(np.sin(b0))
    c0 = sb * np.abs(np.sin(pp))
    cn = sb * np.abs(np.sin(nn * np.pi - p))
    r0 = reflection_coefficients(material_0, frequency_hz, c0, model)
    rn = reflection_coefficients(material_n, frequency_hz, cn, model)
    return FaceCoefficients(r0.r_te, r0.r_tm, rn.r_te, rn.r_tm)


def edge_fixed_reflection(
    r_te: ArrayLike, r_tm: ArrayLike, k_in: ArrayLike, k_out: ArrayLike, normal: ArrayLike, e: ArrayLike,
    fallback: ArrayLike,
) -> CArray:
    """A face's reflection as a Jones matrix between KP's edge-fixed bases, in the sign
    convention of the ``R``'s of :func:`~wavepaths.em.utd.luebbers_coefficients`.

    The face (unit ``normal``, containing the edge ``e``) reflects the ray ``k_in`` into its
    mirror ``k_out`` with the Fresnel coefficients ``r_te``, ``r_tm``: ``E_r = R E_i``, ``R =
    r_te s s^T + r_tm p_r p_i^T`` (``s = unit(k_in x normal)``, ``p = s x k``; the chain's
    :func:`~wavepaths.fields.chain._apply_reflection`). Returned is ``G = -B_out^T R B_in``
    with ``B_in = (b0', phi')`` the edge-fixed basis of ``k_in`` as an incident ray and
    ``B_out = (b0, phi)`` that of ``k_out`` as a diffracted one (:mod:`wavepaths.em.utd`). With
    incidence normal to the edge (``beta_0 = pi/2``) ``G = diag(r_te, r_tm)``, Luebbers' scalar
    pairs; a PEC face gives ``diag(-1, +1)`` at every ``beta_0`` (KP). At oblique incidence on a
    dielectric face the face's TE/TM basis is turned against the edge-fixed one and ``G`` is
    full: it is the geometrical-optics reflection the term of that face's reflection boundary
    must cancel, which the diagonal pairs cannot (the total field then jumps there: 1.3 dB at
    ``beta_0 = 42`` deg on a lossy wedge). Sionna RT also writes its faces' reflections as
    2x2 matrices, in its own "shadow-boundary" bases (docs/sionna-diffraction.md).
    ``||G||_2 = max(|r_te|, |r_tm|)``: the two bases are orthonormal in the same planes.
    ``fallback``: the direction used where ``k`` runs along the edge (``beta_0 = 0``).

    Returns
    -------
    (..., 2, 2) complex128
    """
    ki, ko, nrm, ee, fb = (np.asarray(v, dtype=float) for v in (k_in, k_out, normal, e, fallback))
    z = np.zeros_like(nrm)
    z[..., 2] = 1.0
    x = np.zeros_like(nrm)
    x[..., 0] = 1.0
    s = unit_cross(ki, nrm, unit_cross(nrm, z, x))  # the TE direction (as the reflection kernel's)
    p_i = np.cross(s, ki)
    p_r = np.cross(s, ko)
    phi_i = unit_cross(ki, ee, fb)
    b_i = np.cross(ki, phi_i)
    phi_o = unit_cross(ee, ko, fb)
    b_o = np.cross(ko, phi_o)

    rte, rtm = np.asarray(r_te, dtype=complex), np.asarray(r_tm, dtype=complex)
    out = np.empty(np.broadcast_shapes(rte.shape, ki.shape[:-1]) + (2, 2), dtype=np.complex128)
    for a, u in enumerate((b_o, phi_o)):
        us, up = dot3(u, s), dot3(u, p_r)
        for b, v in enumerate((b_i, phi_i)):
            out[..., a, b] = -(rte * (us * dot3(s, v)) + rtm * (up * dot3(p_i, v)))
    return out


def wedge_reflection_matrices(
    r0_s: ArrayLike, r0_h: ArrayLike, rn_s: ArrayLike, rn_h: ArrayLike, e: ArrayLike, s_in: ArrayLike,
    s_out: ArrayLike, normal_0: ArrayLike, normal_n: ArrayLike, fallback: ArrayLike,
) -> tuple[CArray, CArray]:
    """``(G0, Gn)`` (..., 2, 2): the faces' reflections of :func:`edge_fixed_reflection` that
    replace Luebbers' scalar ``R0``, ``Rn``
    (:func:`~wavepaths.em.utd.diffraction_jones_matrices`), each where its reflection
    boundary needs it.

    ``G0``: the 0-face reflecting the incident ray ``s_in`` into its mirror (the input basis
    is the incident ray's own; at the 0-face's reflection boundary the output basis is the
    diffracted ray's). ``Gn``: the n-face reflecting into the diffracted ray ``s_out`` the
    ray that is its mirror (the output basis is the diffracted ray's own; at the n-face's
    reflection boundary the input basis is the incident ray's). The Fresnel coefficients are
    Luebbers' (:func:`luebbers_face_coefficients`: the 0-face at the incident ray's angle,
    the n-face at the diffracted ray's, which are the angles of these two reflections).
    """
    si, so, n0, nn = (np.asarray(v, dtype=float) for v in (s_in, s_out, normal_0, normal_n))

    def mirror(k, nrm):
        return k - 2.0 * dot3(k, nrm)[..., None] * nrm

    g0 = edge_fixed_reflection(r0_s, r0_h, si, mirror(si, n0), n0, e, fallback)
    gn = edge_fixed_reflection(rn_s, rn_h, mirror(so, nn), so, nn, e, fallback)
    return g0, gn
