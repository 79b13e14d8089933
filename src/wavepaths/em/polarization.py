"""Spherical bases, Jones vectors and coherence matrices of transverse fields.

Conventions (see ``docs/antennas.md``):

* Global frame: right-handed Cartesian ``(x, y, z)``; a direction ``d`` has zenith
  ``theta`` measured from ``+z`` (``0 <= theta <= pi``) and azimuth ``phi`` measured
  from ``+x`` toward ``+y`` (``-pi < phi <= pi``), as in 3GPP TR 38.901 §7.1 and the
  Sionna RT EM primer, eqs. (1)-(2).
* Spherical unit vectors ``r_hat = d``,
  ``theta_hat = (cos t cos p, cos t sin p, -sin t)``, ``phi_hat = (-sin p, cos p, 0)``;
  ``(r_hat, theta_hat, phi_hat)`` is right-handed: ``r_hat x theta_hat = phi_hat``.
* A Jones vector ``e`` of shape ``(..., 2)`` holds the complex components of a
  transverse field along two orthonormal basis vectors ``(u, v)`` transverse to the
  propagation direction; the field vector is ``e[0] u + e[1] v``.
* A coherence matrix ``J = <e e^H>`` (seed §2.1, [Wolff90]) has shape ``(..., 2, 2)``;
  its trace is the radiance (power), up to the receptor constant ``K`` of the seed.

Everything is pure numpy and broadcasts over leading axes.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wavepaths.errors import WavepathsError

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


class SphericalBasis(NamedTuple):
    """Transverse spherical unit vectors ``theta_hat``, ``phi_hat``: (..., 3) float64."""

    theta_hat: FloatArray
    phi_hat: FloatArray


class ZenithAzimuth(NamedTuple):
    """Zenith ``theta`` in [0, pi] and azimuth ``phi`` in (-pi, pi]: (...,) float64 [rad]."""

    theta: FloatArray
    phi: FloatArray


# Input checks: public functions check, private kernels trust.


def _check_pole_tolerance(pole_tolerance: float) -> float:
    tol = float(pole_tolerance)
    if not (np.isfinite(tol) and 0.0 <= tol < 1.0):
        raise WavepathsError(
            f"`pole_tolerance` must be a finite number in [0, 1), got {pole_tolerance!r}"
        )
    return tol


def as_unit_directions(directions: ArrayLike, name: str = "directions") -> FloatArray:
    """Check an array of directions and return it normalised to unit length.

    ``directions`` : (..., 3) array_like of any non-zero finite length; ``name`` is
    used in error messages. Returns (..., 3) float64 unit vectors; raises
    :class:`WavepathsError` on a bad shape, a non-finite value or a zero vector.
    """
    d = _check_array(directions, name, (3,), np.float64)
    a = np.abs(d)
    # the largest component, as three column maxima (np.max over an axis of length 3 is ~10x slower)
    scale = np.maximum(np.maximum(a[..., 0], a[..., 1]), a[..., 2])[..., None]
    if np.any(scale == 0.0):
        raise WavepathsError(f"`{name}` must be non-zero vectors, got a zero vector")
    d = d / scale  # largest component +-1 first, so tiny vectors do not underflow
    return d / np.sqrt(np.einsum("...i,...i->...", d, d))[..., None]


def _check_array(value: ArrayLike, name: str, tail: tuple[int, ...], dtype: type) -> NDArray:
    """``value`` as an array of ``dtype`` with trailing shape ``tail``, all finite."""
    a = np.asarray(value, dtype=dtype)
    if a.ndim < len(tail) or a.shape[a.ndim - len(tail):] != tail:
        dims = ", ".join(str(n) for n in tail)
        raise WavepathsError(f"`{name}` must have shape (..., {dims}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise WavepathsError(f"`{name}` must be finite, got NaN or infinite entries")
    return a


def _check_square2(m: ArrayLike, name: str) -> ComplexArray:
    return _check_array(m, name, (2, 2), np.complex128)


def _check_jones(e: ArrayLike, name: str = "e") -> ComplexArray:
    return _check_array(e, name, (2,), np.complex128)


Xyz = tuple[FloatArray, FloatArray, FloatArray]


def _theta_phi(x: FloatArray, y: FloatArray, z: FloatArray, pole_tolerance: float) -> ZenithAzimuth:
    """Kernel of :func:`theta_phi_from_direction`: 1-D components of unit directions."""
    rho = np.sqrt(x * x + y * y)
    # atan2(rho, z) keeps full precision near the poles, where arccos(z) does not.
    theta = np.arctan2(rho, z)
    phi = np.where(rho <= pole_tolerance, 0.0, np.arctan2(y, x))
    return ZenithAzimuth(theta, phi)


def _spherical_basis(
    x: FloatArray, y: FloatArray, z: FloatArray, pole_tolerance: float
) -> tuple[Xyz, Xyz]:
    """Kernel of :func:`spherical_unit_vectors` on 1-D components of unit directions.

    Works on separate component arrays (numpy is several times faster on them than
    on small trailing axes). Returns ``((tx, ty, tz), (px, py, pz))``.
    """
    rho = np.sqrt(x * x + y * y)
    pole = rho <= pole_tolerance
    any_pole = bool(np.any(pole))
    safe_rho = np.where(pole, 1.0, rho) if any_pole else rho
    cos_phi, sin_phi = x / safe_rho, y / safe_rho
    if any_pole:
        cos_phi[pole], sin_phi[pole] = 1.0, 0.0
    # phi_hat = z_hat x d / rho; theta_hat = phi_hat x d (right-handed triad).
    ph = (-sin_phi, cos_phi, np.zeros_like(x))
    th = (z * cos_phi, z * sin_phi, -rho)
    if any_pole:
        # On (or within `pole_tolerance` of) a pole, phi = 0: phi_hat is y_hat made
        # exactly orthogonal to d by one Gram-Schmidt step (a no-op on the pole itself).
        xp, yp, zp = x[pole], y[pole], z[pole]
        fx, fy, fz = -yp * xp, 1.0 - yp * yp, -yp * zp
        n = np.sqrt(fx * fx + fy * fy + fz * fz)
        fx, fy, fz = fx / n, fy / n, fz / n
        for comp, value in zip(ph, (fx, fy, fz)):
            comp[pole] = value
        for comp, value in zip(th, (fy * zp - fz * yp, fz * xp - fx * zp, fx * yp - fy * xp)):
            comp[pole] = value
    return th, ph


def _flat_components(d: FloatArray) -> Xyz:
    """Contiguous 1-D ``x, y, z`` of directions of shape (..., 3)."""
    flat = d.reshape(-1, 3)
    return flat[:, 0].copy(), flat[:, 1].copy(), flat[:, 2].copy()


def theta_phi_from_direction(
    directions: ArrayLike, *, pole_tolerance: float = 1e-9
) -> ZenithAzimuth:
    """Zenith and azimuth angles of directions in the global frame.

    ``theta = atan2(sqrt(x^2 + y^2), z)`` (accurate at every zenith, unlike
    ``arccos(z)``) and ``phi = atan2(y, x)``; Sionna RT EM primer eq. (2),
    3GPP TR 38.901 §7.1.

    Parameters
    ----------
    directions : (..., 3) array_like of float
        Directions (normalised internally; need not be exactly unit).
    pole_tolerance : float
        Directions whose horizontal part ``sqrt(x^2 + y^2)`` (after normalisation) is
        at most this are on a pole, where the azimuth is undefined and is set to
        ``phi = 0``. This is Sionna RT's choice (``theta_phi_from_unit_vec``); Sionna
        uses 100 times Dr.Jit's float32 epsilon (2^-24: about 5.96e-6) because it computes in float32. The
        default 1e-9 is far above the round-off of float64 directions built from
        scene coordinates (about 1e-16 times coordinate/segment length) and far below
        any angle a scene resolves on purpose.

    Returns
    -------
    ZenithAzimuth
        ``theta`` (...,) in ``[0, pi]`` and ``phi`` (...,) in ``(-pi, pi]`` [rad].
    """
    d = as_unit_directions(directions)
    theta, phi = _theta_phi(*_flat_components(d), _check_pole_tolerance(pole_tolerance))
    return ZenithAzimuth(theta.reshape(d.shape[:-1]), phi.reshape(d.shape[:-1]))


def spherical_unit_vectors(
    directions: ArrayLike, *, pole_tolerance: float = 1e-9
) -> SphericalBasis:
    """Spherical unit vectors ``theta_hat`` and ``phi_hat`` of directions.

    ``theta_hat = (cos t cos p, cos t sin p, -sin t)``, ``phi_hat = (-sin p, cos p, 0)``
    (Sionna RT EM primer eq. (1); 3GPP TR 38.901 §7.1). The triad
    ``(d, theta_hat, phi_hat)`` is orthonormal and right-handed
    (``d x theta_hat = phi_hat``) for every direction, the poles included.

    Parameters
    ----------
    directions : (..., 3) array_like of float
        Directions (normalised internally).
    pole_tolerance : float
        See :func:`theta_phi_from_direction`. On a pole ``phi = 0``, so
        ``theta_hat = (+1, 0, 0)`` at ``+z`` and ``(-1, 0, 0)`` at ``-z`` and
        ``phi_hat = (0, 1, 0)`` at both, as in Sionna RT. Within the tolerance band
        the same vectors are re-orthogonalised to the direction.

    Returns
    -------
    SphericalBasis
        ``theta_hat`` and ``phi_hat``, each (..., 3) float64.
    """
    d = as_unit_directions(directions)
    th, ph = _spherical_basis(*_flat_components(d), _check_pole_tolerance(pole_tolerance))
    return SphericalBasis(np.stack(th, -1).reshape(d.shape), np.stack(ph, -1).reshape(d.shape))


def field_vector(
    components: ArrayLike, directions: ArrayLike, *, pole_tolerance: float = 1e-9
) -> ComplexArray:
    """Cartesian field vector ``E = e_theta theta_hat + e_phi phi_hat``.

    ``components`` (..., 2) complex along the global ``theta_hat``, ``phi_hat`` of
    ``directions`` (..., 3); returns (..., 3) complex128 in global Cartesian
    coordinates. ``pole_tolerance``: see :func:`theta_phi_from_direction`.
    """
    e = _check_jones(components, "components")
    basis = spherical_unit_vectors(directions, pole_tolerance=pole_tolerance)
    return e[..., 0:1] * basis.theta_hat + e[..., 1:2] * basis.phi_hat


def field_components(
    vectors: ArrayLike, directions: ArrayLike, *, pole_tolerance: float = 1e-9
) -> ComplexArray:
    """Components ``(E . theta_hat, E . phi_hat)`` of Cartesian field vectors.

    The inverse of :func:`field_vector` for fields transverse to ``directions``
    (a longitudinal part, if any, is discarded). ``vectors`` (..., 3) complex,
    ``directions`` (..., 3); returns (..., 2) complex128.
    """
    v = _check_array(vectors, "vectors", (3,), np.complex128)
    basis = spherical_unit_vectors(directions, pole_tolerance=pole_tolerance)
    return np.stack(
        [np.sum(v * basis.theta_hat, axis=-1), np.sum(v * basis.phi_hat, axis=-1)],
        axis=-1,
    )


def jones_basis_change(
    from_u: ArrayLike,
    from_v: ArrayLike,
    to_u: ArrayLike,
    to_v: ArrayLike,
    *,
    atol: float = 1e-9,
) -> FloatArray:
    """Real 2x2 matrix that re-expresses a Jones vector in another transverse basis.

    If a field is ``E = a from_u + b from_v``, then ``B @ (a, b)`` are its components
    along ``(to_u, to_v)``, with ``B[i, j] = to_i . from_j``. Both bases must be
    orthonormal and span the same plane (transverse to one propagation direction).
    ``B`` is orthogonal: a rotation when both bases have the same handedness about
    the propagation direction, a reflection (``det B = -1``) otherwise, e.g. when the
    receive side re-expresses a pattern given for ``-k`` in a basis built for ``k``.

    Parameters
    ----------
    from_u, from_v, to_u, to_v : (..., 3) array_like of float
        Unit basis vectors (broadcast together).
    atol : float
        Absolute tolerance on unit length, mutual orthogonality and coplanarity; the
        check guards against passing vectors of different directions by mistake.

    Returns
    -------
    (..., 2, 2) float64
        The change-of-basis matrix ``B``.
    """
    names = ("from_u", "from_v", "to_u", "to_v")
    values = (from_u, from_v, to_u, to_v)
    vecs = [_check_array(v, n, (3,), np.float64) for n, v in zip(names, values)]
    fu, fv, tu, tv = np.broadcast_arrays(*vecs)
    for name, a in zip(names, (fu, fv, tu, tv)):
        if np.any(np.abs(np.linalg.norm(a, axis=-1) - 1.0) > atol):
            raise WavepathsError(f"`{name}` must be unit vectors (within atol={atol})")
    if np.any(np.abs(np.sum(fu * fv, axis=-1)) > atol):
        raise WavepathsError("`from_u` and `from_v` must be orthogonal")
    if np.any(np.abs(np.sum(tu * tv, axis=-1)) > atol):
        raise WavepathsError("`to_u` and `to_v` must be orthogonal")
    n_from = np.cross(fu, fv)
    n_to = np.cross(tu, tv)
    if np.any(np.abs(np.abs(np.sum(n_from * n_to, axis=-1)) - 1.0) > atol):
        raise WavepathsError(
            "the two bases must span the same transverse plane (be transverse to the "
            "same propagation direction)"
        )
    out = np.empty(fu.shape[:-1] + (2, 2))
    out[..., 0, 0] = np.sum(tu * fu, axis=-1)
    out[..., 0, 1] = np.sum(tu * fv, axis=-1)
    out[..., 1, 0] = np.sum(tv * fu, axis=-1)
    out[..., 1, 1] = np.sum(tv * fv, axis=-1)
    return out


# Coherence matrices (seed §2.1, after Wolff 1990).


def coherence_from_jones(e: ArrayLike) -> ComplexArray:
    """Coherence matrix of a fully polarised field, ``J = e e^H``.

    ``e`` (..., 2) complex; returns (..., 2, 2) complex128 with
    ``J[..., i, j] = e_i conj(e_j)``: Hermitian, rank one, trace ``|e|^2``.
    """
    a = _check_jones(e)
    return a[..., :, None] * np.conj(a[..., None, :])


def unpolarized_coherence(power: ArrayLike = 1.0) -> ComplexArray:
    """Coherence matrix of an unpolarised field of given radiance.

    ``power`` (...,) non-negative radiance (trace of ``J``); returns (..., 2, 2)
    complex128 ``(power / 2) I``, the same in every transverse basis.
    """
    p = np.asarray(power, dtype=np.float64)
    if not np.all(np.isfinite(p)) or np.any(p < 0.0):
        raise WavepathsError(f"`power` must be finite and non-negative, got {power!r}")
    return (0.5 * p)[..., None, None] * np.eye(2, dtype=np.complex128)


def partially_polarized_coherence(e: ArrayLike, degree: ArrayLike) -> ComplexArray:
    """Coherence matrix of a partially polarised field.

    The polarised part ``degree * e e^H`` plus the unpolarised part
    ``(1 - degree) * |e|^2 / 2 * I``: the radiance is ``|e|^2`` and the degree of
    polarisation is ``degree`` (Born & Wolf §10.8, decomposition of ``J``).

    ``e`` (..., 2) complex, whose squared norm is the total radiance; ``degree``
    (...,) in [0, 1]. Returns (..., 2, 2) complex128.
    """
    a = _check_jones(e)
    g = np.asarray(degree, dtype=np.float64)
    if not np.all(np.isfinite(g)) or np.any((g < 0.0) | (g > 1.0)):
        raise WavepathsError(f"`degree` must be in [0, 1], got {degree!r}")
    power = np.sum(np.abs(a) ** 2, axis=-1)
    polarized = a[..., :, None] * np.conj(a[..., None, :])
    unpolarized = (0.5 * power)[..., None, None] * np.eye(2)
    return g[..., None, None] * polarized + (1.0 - g)[..., None, None] * unpolarized


def propagate_coherence(m: ArrayLike, j: ArrayLike) -> ComplexArray:
    """Transform a coherence matrix by a 2x2 Jones (transfer) matrix: ``M J M^H``.

    If a fully polarised field ``e`` becomes ``M e``, its coherence matrix becomes
    ``(M e)(M e)^H = M (e e^H) M^H``; by linearity of the time average the same
    holds for any ``J``.

    Parameters
    ----------
    m : (..., 2, 2) array_like of complex
        Jones matrix (reflection, diffraction, basis change, ...).
    j : (..., 2, 2) array_like of complex
        Coherence matrix in the input basis of ``m``.

    Returns
    -------
    (..., 2, 2) complex128
        Coherence matrix in the output basis of ``m``.
    """
    mm = _check_square2(m, "m")
    jj = _check_square2(j, "j")
    return mm @ jj @ np.conj(np.swapaxes(mm, -1, -2))


def seed_diffracted_coherence(
    j: ArrayLike, d_par: ArrayLike, d_perp: ArrayLike
) -> ComplexArray:
    """The seed's diffracted coherence matrix (seed §2.1).

    ``J_dif = [[J_xx D_par^2, J_xy D_par D_perp], [J_yx D_par D_perp, J_yy D_perp^2]]``
    with ``x`` the parallel (edge-fixed ``beta``) and ``y`` the perpendicular
    (``phi``) component: ``d_par`` is the soft coefficient ``D_s`` and ``d_perp`` the hard
    ``D_h``. The seed's own labels are the other way round: its ``D_par`` (``C = +1``) is
    Keller's hard coefficient (:func:`wavepaths.em.gtd.seed_keller_coefficient`), so its
    ``D_perp`` goes in as ``d_par`` and its ``D_par`` as ``d_perp``. It equals ``propagate_coherence(diag(D_par, D_perp), J)``
    for REAL coefficients only; the UTD coefficients are complex in general, and then
    the correct form is ``M J M^H`` (diagonal ``|D|^2``, off-diagonal
    ``D_par conj(D_perp)``), so complex input is refused here.

    Parameters
    ----------
    j : (..., 2, 2) array_like of complex
        Incident coherence matrix in the edge-fixed (parallel, perpendicular) basis.
    d_par, d_perp : (...,) array_like of float
        Real parallel and perpendicular diffraction coefficients.

    Returns
    -------
    (..., 2, 2) complex128
    """
    jj = _check_square2(j, "j")
    coeffs = []
    for name, value in (("d_par", d_par), ("d_perp", d_perp)):
        a = np.asarray(value)
        if np.iscomplexobj(a) and np.any(a.imag != 0.0):
            raise WavepathsError(
                f"`{name}` must be real for the seed's formula; use "
                "propagate_coherence(diag(D_par, D_perp), J) for complex coefficients"
            )
        coeffs.append(_check_array(np.real(a), name, (), np.float64))
    dp, ds = coeffs
    scale = np.empty(np.broadcast_shapes(dp.shape, ds.shape) + (2, 2))
    scale[..., 0, 0] = dp * dp
    scale[..., 0, 1] = dp * ds
    scale[..., 1, 0] = dp * ds
    scale[..., 1, 1] = ds * ds
    return jj * scale


def radiance(j: ArrayLike) -> FloatArray:
    """Radiance (power) of a coherence matrix: ``trace(J).real``.

    ``j`` : (..., 2, 2) complex. Returns (...,) float64.
    """
    jj = _check_square2(j, "j")
    return np.real(jj[..., 0, 0] + jj[..., 1, 1])


def degree_of_polarization(j: ArrayLike) -> FloatArray:
    """Degree of polarisation ``sqrt(1 - 4 det J / trace(J)^2)`` (Born & Wolf §10.8).

    ``j`` (..., 2, 2) Hermitian positive semi-definite; returns (...,) float64 in
    [0, 1], and 0 where the radiance is 0 (no field, nothing to polarise).
    """
    jj = _check_square2(j, "j")
    tr = np.real(jj[..., 0, 0] + jj[..., 1, 1])
    det = np.real(jj[..., 0, 0] * jj[..., 1, 1] - jj[..., 0, 1] * jj[..., 1, 0])
    safe_tr = np.where(tr > 0.0, tr, 1.0)
    ratio = np.clip(1.0 - 4.0 * det / safe_tr**2, 0.0, 1.0)
    return np.where(tr > 0.0, np.sqrt(ratio), 0.0)
