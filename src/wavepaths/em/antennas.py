"""Antenna patterns and polarisation, in Sionna RT 2.2's conventions.

An :class:`Antenna` is a vertically polarised amplitude pattern ``C~(theta', phi')``
("iso", "dipole", "hw_dipole" or "tr38901") in the antenna's local frame, one or two
slant angles ``zeta`` that turn it into linear polarisations (3GPP TR 38.901 §7.3,
polarisation models 1 and 2), and an orientation ``(yaw, pitch, roll)`` that rotates
the local frame into the global one (3GPP TR 38.901 §7.1.3, ``R = Rz Ry Rx``).
:func:`antenna_field` returns the field pattern along the GLOBAL ``theta_hat`` and
``phi_hat`` of each direction, normalised so that ``|C_theta|^2 + |C_phi|^2`` is the
gain (linear, relative to an isotropic radiator). See ``docs/antennas.md``.

Directions: for a transmitter, the departure directions (from the antenna toward the
first vertex of the path); for a receiver, the direction from the receiver toward the
last vertex, i.e. the propagation direction of the arriving wave reversed (Sionna RT
evaluates receive patterns at ``-k_incident`` in the same way).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from functools import lru_cache
from typing import Literal, get_args

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wavepaths.em.polarization import (
    _check_pole_tolerance,
    _flat_components,
    _spherical_basis,
    _theta_phi,
    as_unit_directions,
)
from wavepaths.errors import WavepathsError

PatternName = Literal["iso", "dipole", "hw_dipole", "tr38901"]
PolarizationName = Literal["V", "H", "VH", "cross"]
PolarizationModel = Literal["tr38901_1", "tr38901_2"]

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


def polarization_slant_angles(polarization: PolarizationName) -> tuple[float, ...]:
    """Slant angles ``zeta`` [rad] of the ports of a polarisation, in port order.

    ``zeta = 0`` is vertical (along ``theta_hat`` of the local frame) and
    ``zeta = pi/2`` horizontal (along ``phi_hat``), as registered in Sionna RT 2.2:
    "V" -> (0,), "H" -> (pi/2,), "VH" -> (0, pi/2), "cross" -> (-pi/4, +pi/4).

    Parameters
    ----------
    polarization : {"V", "H", "VH", "cross"}

    Returns
    -------
    tuple of float
        One angle per port.
    """
    table: dict[str, tuple[float, ...]] = {
        "V": (0.0,),
        "H": (math.pi / 2,),
        "VH": (0.0, math.pi / 2),
        "cross": (-math.pi / 4, math.pi / 4),
    }
    if not isinstance(polarization, str) or polarization not in table:
        raise WavepathsError(
            f"`polarization` must be one of {list(table)}, got {polarization!r}"
        )
    return table[polarization]


@dataclass(frozen=True)
class Antenna:
    """One antenna element with one or two polarisation ports.

    Parameters
    ----------
    pattern : {"iso", "dipole", "hw_dipole", "tr38901"}
        Vertically polarised amplitude pattern in the local frame:
        isotropic ``1``; short dipole ``sqrt(1.5) |sin t|`` (Balanis eq. 4-26a);
        half-wave dipole ``sqrt(1.643) |cos(pi/2 cos t) / sin t|`` (Balanis eq. 4-84);
        3GPP element (TR 38.901 Table 7.3-1: 65 deg beamwidths, 30 dB limits,
        8 dBi maximum, boresight along local ``+x``).
    polarization : {"V", "H", "VH", "cross"}
        Ports and their slant angles, see :func:`polarization_slant_angles`.
    orientation : (yaw, pitch, roll) of float
        Rotation angles [rad] about ``z``, ``y`` and ``x``: local-to-global rotation
        ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (TR 38.901 §7.1.3; Sionna RT's
        ``orientation``). Positive pitch tilts local ``+x`` downward.
    polarization_model : {"tr38901_1", "tr38901_2"}
        How a slant angle acts (TR 38.901 §7.3.2): model 2 (Sionna's default)
        rotates the field components, ``(C_t, C_p) = (cos zeta, sin zeta) C~``; model 1
        points the field along a short dipole on the axis ``Rx(zeta) z_hat`` while
        keeping the gain ``C~^2``.
    """

    pattern: PatternName = "iso"
    polarization: PolarizationName = "V"
    orientation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    polarization_model: PolarizationModel = "tr38901_2"

    def __post_init__(self) -> None:
        patterns = get_args(PatternName)
        if self.pattern not in patterns:
            raise WavepathsError(
                f"`pattern` must be one of {list(patterns)}, got {self.pattern!r}"
            )
        polarization_slant_angles(self.polarization)  # validates
        models = get_args(PolarizationModel)
        if self.polarization_model not in models:
            raise WavepathsError(
                f"`polarization_model` must be one of {list(models)}, "
                f"got {self.polarization_model!r}"
            )
        try:
            if isinstance(self.orientation, (str, bytes)) or any(
                isinstance(a, (str, bytes, bool, np.bool_)) for a in self.orientation
            ):
                raise TypeError("angles must be numbers")
            angles = tuple(float(a) for a in self.orientation)
        except (TypeError, ValueError) as exc:
            raise WavepathsError(
                f"`orientation` must be three angles (yaw, pitch, roll) in rad, "
                f"got {self.orientation!r}"
            ) from exc
        if len(angles) != 3 or not all(math.isfinite(a) for a in angles):
            raise WavepathsError(
                f"`orientation` must be three finite angles (yaw, pitch, roll) in rad, "
                f"got {self.orientation!r}"
            )
        if any(abs(a) > 2 * math.pi for a in angles):
            warnings.warn(
                f"antenna orientation {angles} has an angle beyond 2 pi: `Antenna.orientation` is in "
                "radians (the CLI's --tx-orientation and --rx-orientation are in degrees); if you meant "
                "degrees, pass np.deg2rad(...)",
                stacklevel=3,
            )
        object.__setattr__(self, "orientation", angles)

    @property
    def num_ports(self) -> int:
        """Number of polarisation ports: 1 for "V"/"H", 2 for "VH"/"cross"."""
        return len(polarization_slant_angles(self.polarization))

    @property
    def slant_angles(self) -> tuple[float, ...]:
        """Slant angle [rad] of each port, see :func:`polarization_slant_angles`."""
        return polarization_slant_angles(self.polarization)

    @property
    def rotation(self) -> FloatArray:
        """(3, 3) float64 local-to-global rotation matrix, see :func:`rotation_matrix`."""
        return rotation_matrix(self.orientation)


def rotation_matrix(orientation: ArrayLike) -> FloatArray:
    """Local-to-global rotation ``R = Rz(yaw) Ry(pitch) Rx(roll)``.

    3GPP TR 38.901 §7.1.3 (closed form eq. 7.1-4, as Sionna RT's ``rotation_matrix``
    cites it): the roll about ``x`` is applied first, then the pitch about ``y``, then
    the yaw about ``z``, all about the fixed global axes. A local vector ``v'`` is
    ``R v'`` in the global frame; a global direction ``d`` is ``R^T d`` in the local
    frame.

    Parameters
    ----------
    orientation : (..., 3) array_like of float
        ``(yaw, pitch, roll)`` [rad].

    Returns
    -------
    (..., 3, 3) float64
    """
    a = np.asarray(orientation, dtype=np.float64)
    if a.ndim < 1 or a.shape[-1] != 3 or not np.all(np.isfinite(a)):
        raise WavepathsError(
            f"`orientation` must be finite (yaw, pitch, roll) of shape (..., 3), got {a.shape}"
        )
    ca, sa = np.cos(a[..., 0]), np.sin(a[..., 0])
    cb, sb = np.cos(a[..., 1]), np.sin(a[..., 1])
    cc, sc = np.cos(a[..., 2]), np.sin(a[..., 2])
    one, zero = np.ones_like(ca), np.zeros_like(ca)
    rz = np.stack([ca, -sa, zero, sa, ca, zero, zero, zero, one], -1).reshape(ca.shape + (3, 3))
    ry = np.stack([cb, zero, sb, zero, one, zero, -sb, zero, cb], -1).reshape(ca.shape + (3, 3))
    rx = np.stack([one, zero, zero, zero, cc, -sc, zero, sc, cc], -1).reshape(ca.shape + (3, 3))
    return rz @ ry @ rx


# ----------------------------------------------------------------------------------
# Vertically polarised amplitude patterns C~ in the local frame (real, >= 0)
# ----------------------------------------------------------------------------------


def _vertical_amplitude(
    pattern: str, z: FloatArray, rho: FloatArray, theta: FloatArray, phi: FloatArray
) -> FloatArray:
    """``C~(theta, phi)`` (1-D, real, >= 0); ``z = cos theta``, ``rho = sin theta``."""
    if pattern == "iso":
        return np.ones_like(rho)
    if pattern == "dipole":
        # Short dipole, Balanis eq. 4-26a; directivity 1.5 so |C|^2 = 1.5 sin^2 t.
        return math.sqrt(1.5) * rho
    if pattern == "hw_dipole":
        # Half-wave dipole, Balanis eq. 4-84, |cos(pi/2 cos t)| / sin t, scaled by the
        # directivity 1.643 used by Sionna (the exact value is 4/Cin(2 pi) = 1.640922). Written
        # without a division by sin t: cos(pi/2 |z|) = sin(pi/2 (1 - |z|)) and
        # 1 - |z| = rho^2 / (1 + |z|), so the ratio is
        # sinc(rho^2 / (2 (1 + |z|))) * pi rho / (2 (1 + |z|)), which tends to 0 on axis.
        w = 2.0 * (1.0 + np.abs(z))
        return math.sqrt(1.643) * np.sinc(rho * rho / w) * (math.pi * rho / w)
    if pattern == "tr38901":
        # 3GPP TR 38.901 Table 7.3-1, angles in rad, phi in (-pi, pi].
        theta_3db = phi_3db = math.radians(65.0)
        sla_v = a_max = 30.0
        g_max_dbi = 8.0
        a_v = -np.minimum(12.0 * ((theta - math.pi / 2) / theta_3db) ** 2, sla_v)
        a_h = -np.minimum(12.0 * (phi / phi_3db) ** 2, a_max)
        a_db = -np.minimum(-(a_v + a_h), a_max) + g_max_dbi
        return 10.0 ** (a_db / 20.0)
    raise AssertionError(f"unchecked pattern {pattern!r}")  # pragma: no cover


def _slant_components(
    model: str,
    zeta: float,
    th: tuple[FloatArray, ...],
    ph: tuple[FloatArray, ...],
    axis_tolerance: float,
) -> tuple[FloatArray | float, FloatArray | float]:
    """Unit polarisation components ``(cos psi, sin psi)`` on the local spherical basis.

    Model 2 (TR 38.901 eqs. 7.3-4/5): ``(cos zeta, sin zeta)``.
    Model 1 (TR 38.901 eq. 7.3-3): the far field of a short dipole along
    ``u = Rx(zeta) z_hat = (0, -sin zeta, cos zeta)``, i.e. the transverse part of
    ``-u``, normalised; ``(theta_hat . (-u), phi_hat . (-u))`` are the numerators of
    ``cos psi`` and ``sin psi`` and ``sqrt(1 - (u . d)^2)`` their norm. On the dipole
    axis (norm <= ``axis_tolerance``) the numerators are returned unnormalised, so the
    field tends to 0 there, as in Sionna RT.
    """
    cz, sz = math.cos(zeta), math.sin(zeta)
    if model == "tr38901_2":
        return cz, sz
    a = th[1] * sz - th[2] * cz
    b = ph[1] * sz - ph[2] * cz
    norm = np.sqrt(a * a + b * b)
    safe = np.where(norm > axis_tolerance, norm, 1.0)
    return a / safe, b / safe


def _local_pattern(antenna: Antenna, d: FloatArray, tol: float):
    """The local side of :func:`antenna_field` for unit global directions ``d`` (..., 3):
    ``R``, the flat global components ``x, y, z``, the local spherical basis ``th_l, ph_l``
    of ``d' = R^T d`` and the vertical amplitude ``C~`` there.

    Works on separate 1-D component arrays: numpy is several times faster on them
    than on a trailing axis of length 3.
    """
    r = rotation_matrix(antenna.orientation)
    x, y, z = _flat_components(d)
    # Local direction d' = R^T d, re-normalised (R is orthogonal to round-off only).
    xl = r[0, 0] * x + r[1, 0] * y + r[2, 0] * z
    yl = r[0, 1] * x + r[1, 1] * y + r[2, 1] * z
    zl = r[0, 2] * x + r[1, 2] * y + r[2, 2] * z
    n = np.sqrt(xl * xl + yl * yl + zl * zl)
    xl, yl, zl = xl / n, yl / n, zl / n
    th_l, ph_l = _spherical_basis(xl, yl, zl, tol)
    if antenna.pattern == "tr38901":
        theta_l, phi_l = _theta_phi(xl, yl, zl, tol)
    else:
        theta_l = phi_l = xl  # the other patterns depend on z and rho only
    amp = _vertical_amplitude(antenna.pattern, zl, np.sqrt(xl * xl + yl * yl), theta_l, phi_l)
    return r, (x, y, z), th_l, ph_l, amp


def _antenna_field_kernel(antenna: Antenna, d: FloatArray, tol: float) -> ComplexArray:
    """Kernel of :func:`antenna_field` for unit global directions ``d`` (..., 3)."""
    r, (x, y, z), th_l, ph_l, amp = _local_pattern(antenna, d, tol)
    th_g, ph_g = _spherical_basis(x, y, z, tol)
    # The global spherical vectors expressed in the local frame, R^T th_g and R^T ph_g,
    # dotted with the local ones give the 2x2 local-to-global field matrix
    # [[th_g . R th_l, th_g . R ph_l], [ph_g . R th_l, ph_g . R ph_l]] (TR 38.901 §7.1.3).
    def to_local(v: tuple[FloatArray, ...]) -> list[FloatArray]:
        return [r[0, k] * v[0] + r[1, k] * v[1] + r[2, k] * v[2] for k in range(3)]

    def dot(u: list[FloatArray], v: tuple[FloatArray, ...]) -> FloatArray:
        return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]

    th_gl, ph_gl = to_local(th_g), to_local(ph_g)
    m00, m01 = dot(th_gl, th_l), dot(th_gl, ph_l)
    m10, m11 = dot(ph_gl, th_l), dot(ph_gl, ph_l)
    out = np.zeros((x.size, antenna.num_ports, 2), dtype=np.complex128)
    for port, zeta in enumerate(antenna.slant_angles):
        a, b = _slant_components(antenna.polarization_model, zeta, th_l, ph_l, tol)
        c_theta, c_phi = a * amp, b * amp
        out[:, port, 0] = m00 * c_theta + m01 * c_phi
        out[:, port, 1] = m10 * c_theta + m11 * c_phi
    return out.reshape(d.shape[:-1] + (antenna.num_ports, 2))


def antenna_field(
    antenna: Antenna, directions: ArrayLike, *, pole_tolerance: float = 1e-9
) -> ComplexArray:
    """Field pattern of each port along the global ``theta_hat`` and ``phi_hat``.

    Steps: ``d' = R^T d`` (local direction); ``C~(theta', phi')`` (the vertically
    polarised pattern); polarisation by the port's slant angle (TR 38.901 §7.3.2,
    model 1 or 2) giving ``(C'_theta, C'_phi)`` on the local spherical basis; the
    field vector ``R (C'_theta theta_hat' + C'_phi phi_hat')`` projected on the
    global ``theta_hat(d)`` and ``phi_hat(d)`` (TR 38.901 §7.1.3).

    Parameters
    ----------
    antenna : Antenna
    directions : (..., 3) array_like of float
        Global directions (normalised internally). Transmitter: departure
        directions. Receiver: from the receiver toward where the wave comes from
        (the reversed propagation direction of the arriving wave).
    pole_tolerance : float
        Horizontal extent within which a direction counts as a pole of the local or
        global frame and gets ``phi = 0`` (see
        :func:`wavepaths.em.polarization.theta_phi_from_direction`); also the
        threshold below which polarisation model 1 skips its normalisation on the
        dipole axis.

    Returns
    -------
    (..., num_ports, 2) complex128
        ``[..., p, 0] = C_theta`` and ``[..., p, 1] = C_phi`` of port ``p``, dimensionless
        field amplitudes with ``|C_theta|^2 + |C_phi|^2`` the linear gain. All built-in
        patterns are real (imaginary parts 0).
    """
    if not isinstance(antenna, Antenna):
        raise WavepathsError(f"`antenna` must be an Antenna, got {type(antenna).__name__}")
    d = as_unit_directions(directions)
    return _antenna_field_kernel(antenna, d, _check_pole_tolerance(pole_tolerance))


def antenna_field_vectors(
    antenna: Antenna, directions: ArrayLike, *, pole_tolerance: float = 1e-9, compiled: bool | None = None
) -> ComplexArray:
    """Field pattern of each port as a global 3-vector, ``C_theta theta_hat + C_phi phi_hat``.

    The vector :func:`antenna_field`'s components describe, found without the global
    spherical basis: ``R (C'_theta theta_hat' + C'_phi phi_hat')`` of the local direction
    ``d' = R^T d`` (TR 38.901 §7.1.3; the projection on the global ``theta_hat``,
    ``phi_hat`` and back is the identity on vectors transverse to ``d``). The field chain
    (:mod:`wavepaths.fields.chain`) starts and ends with it.

    Parameters
    ----------
    antenna : Antenna
    directions : (..., 3) array_like of float
        As :func:`antenna_field`.
    pole_tolerance : float
        As :func:`antenna_field`.
    compiled : bool, optional
        Run the compiled loop (``em/_numba_antennas.py``): by default when numba is
        installed; ``False`` runs the numpy reference (``FieldConfig(compiled=False)``
        passes it).

    Returns
    -------
    (..., num_ports, 3) complex128
        Transverse to the direction; ``|.|^2`` is the port's linear gain.
    """
    if not isinstance(antenna, Antenna):
        raise WavepathsError(f"`antenna` must be an Antenna, got {type(antenna).__name__}")
    tol = _check_pole_tolerance(pole_tolerance)
    kernel = _compiled_field_vectors() if compiled is not False else None
    if kernel is not None:
        a = np.asarray(directions, dtype=np.float64)
        if a.ndim >= 1 and a.shape[-1] == 3:
            flat = np.ascontiguousarray(a.reshape(-1, 3))
            out = np.empty((len(flat), antenna.num_ports, 3), dtype=np.complex128)
            from ._numba_antennas import MODEL_CODES, PATTERN_CODES

            bad = kernel(flat, np.ascontiguousarray(antenna.rotation), PATTERN_CODES[antenna.pattern],
                         np.array(antenna.slant_angles), MODEL_CODES[antenna.polarization_model], tol, out)
            if bad < 0:
                return out.reshape(a.shape[:-1] + (antenna.num_ports, 3))
        # a bad shape or direction: the reference raises its error
    return _antenna_field_vectors_numpy(antenna, directions, tol)


@lru_cache(maxsize=1)
def _compiled_field_vectors():
    """The compiled :func:`antenna_field_vectors`
    (:func:`wavepaths.em._numba_antennas.field_vectors`), or ``None`` without numba."""
    try:
        from ._numba_antennas import field_vectors
    except ImportError:
        return None
    return field_vectors


def _antenna_field_vectors_numpy(antenna: Antenna, directions: ArrayLike, tol: float) -> ComplexArray:
    """:func:`antenna_field_vectors` in numpy (the reference of the compiled kernel)."""
    d = as_unit_directions(directions)
    r, (x, _, _), th_l, ph_l, amp = _local_pattern(antenna, d, tol)
    out = np.zeros((x.size, antenna.num_ports, 3), dtype=np.complex128)
    for port, zeta in enumerate(antenna.slant_angles):
        a, b = _slant_components(antenna.polarization_model, zeta, th_l, ph_l, tol)
        ca, cb = a * amp, b * amp
        local = [ca * th_l[k] + cb * ph_l[k] for k in range(3)]  # the field in the local frame
        for k in range(3):
            out[:, port, k] = r[k, 0] * local[0] + r[k, 1] * local[1] + r[k, 2] * local[2]
    return out.reshape(d.shape[:-1] + (antenna.num_ports, 3))


def antenna_gain(
    antenna: Antenna, directions: ArrayLike, *, pole_tolerance: float = 1e-9
) -> FloatArray:
    """Linear gain ``|C_theta|^2 + |C_phi|^2`` of each port.

    Parameters
    ----------
    antenna : Antenna
    directions : (..., 3) array_like of float
        See :func:`antenna_field`.
    pole_tolerance : float
        See :func:`antenna_field`.

    Returns
    -------
    (..., num_ports) float64
        Gain relative to an isotropic radiator (power, linear).
    """
    c = antenna_field(antenna, directions, pole_tolerance=pole_tolerance)
    return np.sum(np.abs(c) ** 2, axis=-1)


def antenna_gain_dbi(
    antenna: Antenna, directions: ArrayLike, *, pole_tolerance: float = 1e-9
) -> FloatArray:
    """Gain of each port in dBi, ``10 log10(|C_theta|^2 + |C_phi|^2)``.

    Parameters
    ----------
    antenna : Antenna
    directions : (..., 3) array_like of float
        See :func:`antenna_field`.
    pole_tolerance : float
        See :func:`antenna_field`.

    Returns
    -------
    (..., num_ports) float64
        Gain [dBi]; ``-inf`` exactly in the nulls (e.g. on a dipole's axis), without
        a floating-point warning.
    """
    g = antenna_gain(antenna, directions, pole_tolerance=pole_tolerance)
    positive = g > 0.0
    return np.where(positive, 10.0 * np.log10(np.where(positive, g, 1.0)), -np.inf)
