"""Field results: per-path coefficients and per-receiver totals."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from ..em.constants import SPEED_OF_LIGHT  # noqa: F401 (re-exported)
from ..errors import WavepathsError
from ..search.paths import Paths

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene
    from .config import FieldConfig

ETA_0 = 376.730313668  # free-space impedance [ohm]


def power_db(x: np.ndarray) -> np.ndarray:
    """10 log10(x) of powers ``x >= 0``, without a warning: -inf for zeros (no path), NaN kept
    (a cell not traced: inside a building, say). The one dB conversion of the package's powers
    (paths, maps, the validation report and the benchmarks)."""
    x = np.asarray(x, dtype=float)
    out = np.full(x.shape, -np.inf)
    pos = x > 0
    out[pos] = 10 * np.log10(x[pos])
    out[np.isnan(x)] = np.nan
    return out


def field_strength_v_m(field_gain: np.ndarray, tx_power_dbm: float, frequency_hz: float) -> np.ndarray:
    """RMS field strength [V/m] from a field gain.

    Parameters
    ----------
    field_gain : array_like of float
        Squared magnitude of the incident field for unit transmit power, normalised like
        the path coefficients ``a`` (see :meth:`FieldResult.field_gain`) [1].
    tx_power_dbm : float
        Transmit power [dBm].
    frequency_hz : float
        Carrier frequency [Hz].

    Returns
    -------
    ndarray of float
        ``E = sqrt(eta_0 P_t 4 pi g) / lambda`` [V/m]: the power ``P_t g`` an isotropic,
        matched receiver would collect over its effective area ``lambda^2 / 4 pi``, as a
        field. NaN passes through.
    """
    lam = SPEED_OF_LIGHT / frequency_hz
    pt = 1e-3 * 10 ** (tx_power_dbm / 10)
    return np.sqrt(ETA_0 * 4 * np.pi * pt * np.asarray(field_gain, dtype=float)) / lam


def incident_fields(scene: "Scene", paths: Paths, config: "FieldConfig") -> np.ndarray:
    """Field 3-vector of each path at the receiver, before the receive antenna.

    Parameters
    ----------
    scene : Scene
    paths : Paths
        From :func:`wavepaths.trace` on ``scene``.
    config : FieldConfig
        Its receive antenna plays no part.

    Returns
    -------
    (N, Pt, 3) complex128
        ``e = (lambda / 4 pi) * spreading * E`` per transmit port, in the normalisation of
        the path coefficients (``a = C_rx^H e``, :func:`wavepaths.fields.path_coefficients`;
        free space, isotropic transmitter: ``|e| = lambda / 4 pi d``), without the
        ``exp(-j 2 pi f tau)`` phase.
    """
    from .chain import coefficients_and_fields

    return coefficients_and_fields(scene, paths, config)[1]


@dataclass(frozen=True, eq=False)
class FieldResult:
    """Complex path coefficients and what a radio engineer reads from them.

    Attributes
    ----------
    paths : Paths
        The geometry the fields belong to.
    a_ports : (N, Pr, Pt) complex128
        Path coefficient per receive and transmit port, normalised like Sionna RT's
        ``Paths.a`` (unit transmit power, no ``exp(-j 2 pi f tau)`` phase).
    frequency_hz : float
    tx_power_dbm : float
    incident_field : (N, Pt, 3) complex128 or None
        Field 3-vector of each path at the receiver, before the receive antenna, per
        transmit port, in the normalisation of ``a_ports`` (``a = C_rx^H e``, with ``C_rx``
        the receive pattern; :func:`incident_fields`). :func:`wavepaths.fields.compute_fields`
        fills it from the same chain as ``a_ports``. It makes :meth:`field_strength`
        independent of the receive antenna; ``None`` for a result built without it.
    """

    paths: Paths
    a_ports: np.ndarray
    frequency_hz: float
    tx_power_dbm: float
    incident_field: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.incident_field is not None:
            e = np.asarray(self.incident_field)
            want = (self.a_ports.shape[0], self.a_ports.shape[2], 3)
            if e.shape != want:
                raise WavepathsError(f"`incident_field` must have shape {want} (N, Pt, 3), got {e.shape}")

    def with_incident_field(self, scene: "Scene", config: "FieldConfig") -> "FieldResult":
        """This result with :attr:`incident_field` computed for ``scene`` and ``config`` (those
        the coefficients came from), so that :meth:`field_strength` is the field itself."""
        return replace(self, incident_field=incident_fields(scene, self.paths, config))

    @property
    def a(self) -> np.ndarray:
        """(N,) complex128: coefficient of the first port pair."""
        return self.a_ports[:, 0, 0]

    @property
    def delays(self) -> np.ndarray:
        """(N,) float64 [s]."""
        return self.paths.delays

    @property
    def a_phased(self) -> np.ndarray:
        """(N,) complex128: ``a * exp(-j 2 pi f tau)``, the narrow-band contribution at the carrier."""
        return self.a * np.exp(-2j * np.pi * self.frequency_hz * self.delays)

    @property
    def gain_db(self) -> np.ndarray:
        """(N,) float64: path gain |a|^2 in dB."""
        return power_db(np.abs(self.a) ** 2)

    # ---- per (tx, rx) totals ----------------------------------------------------------
    def _pair_sum(self, values: np.ndarray) -> np.ndarray:
        p = self.paths
        m, n = len(p.tx_positions), len(p.rx_positions)
        out = np.zeros(m * n, dtype=values.dtype)
        np.add.at(out, p.tx_index * n + p.rx_index, values)
        return out.reshape(m, n)

    def path_gain(self, coherent: bool = True) -> np.ndarray:
        """(m, n) linear path gain: |sum a e^{-j2pi f tau}|^2 (coherent) or sum |a|^2."""
        if coherent:
            return np.abs(self._pair_sum(self.a_phased)) ** 2
        return self._pair_sum(np.abs(self.a) ** 2)

    def path_gain_db(self, coherent: bool = True) -> np.ndarray:
        """(m, n) path gain [dB]."""
        return power_db(self.path_gain(coherent))

    def received_power_dbm(self, coherent: bool = True) -> np.ndarray:
        """(m, n) received power [dBm] for ``tx_power_dbm``."""
        return self.tx_power_dbm + self.path_gain_db(coherent)

    def field_gain(self, coherent: bool = True) -> np.ndarray:
        """(m, n) linear "field gain" [1]: the incident field at the receiver, squared, for unit
        transmit power, in the normalisation of ``a`` (free space: ``G_t (lambda / 4 pi d)^2``).

        With :attr:`incident_field` (transmit port 0), independent of the receive antenna:
        ``|sum_i e_i exp(-j 2 pi f tau_i)|^2`` with ``e_i`` the paths' field 3-vectors, the
        magnitude of the total field vector at the receiver (all polarisations; ``coherent``),
        or ``sum_i |e_i|^2`` (the power sum). Without it, :meth:`path_gain`, which includes the
        receive antenna's gain and polarisation (equal to the above only for an isotropic,
        co-polarised receive antenna).
        """
        if self.incident_field is None:
            return self.path_gain(coherent)
        e = self.incident_field[:, 0, :]
        if coherent:
            phase = np.exp(-2j * np.pi * self.frequency_hz * self.delays)
            total = np.stack([self._pair_sum(e[:, c] * phase) for c in range(3)], axis=-1)
            return np.sum(np.abs(total) ** 2, axis=-1)
        return self._pair_sum(np.sum(np.abs(e) ** 2, axis=-1))

    def field_strength(self, coherent: bool = True) -> np.ndarray:
        """(m, n) RMS field strength [V/m] at the receiver for ``tx_power_dbm``.

        The field an isotropic receiver sees, independent of the receive antenna (the
        transmit antenna's gain is in): ``E = sqrt(eta_0 P_t 4 pi g) / lambda`` with ``g``
        the :meth:`field_gain` (for a power ``P_r = P_t g`` that an isotropic antenna
        matched to the field would receive, whose effective area is ``lambda^2 / 4 pi``;
        free space: ``E = sqrt(eta_0 P_t G_t / 4 pi) / d``). Coherent: the magnitude of the
        vector sum of the paths' fields (each with ``exp(-j 2 pi f tau)``); otherwise the
        root of the sum of their squared magnitudes.

        Exact when the result holds :attr:`incident_field` (see :func:`incident_fields`,
        :meth:`with_incident_field`); without it, from :meth:`path_gain`, which is right
        only for an isotropic receive antenna co-polarised with the field.
        """
        return field_strength_v_m(self.field_gain(coherent), self.tx_power_dbm, self.frequency_hz)

    def field_strength_dbuv_m(self, coherent: bool = True) -> np.ndarray:
        """(m, n) field strength [dBuV/m] (see :meth:`field_strength`); ``-inf`` where no path arrives."""
        e = self.field_strength(coherent)
        with np.errstate(divide="ignore"):
            return 20 * np.log10(e * 1e6)

    def receiver_summary(self, rx: int, tx: int = 0) -> dict:
        """JSON-ready totals for one (tx, rx) pair."""
        return {
            "path_gain_db": float(self.path_gain_db(True)[tx, rx]),
            "path_gain_incoherent_db": float(self.path_gain_db(False)[tx, rx]),
            "received_power_dbm": float(self.received_power_dbm(True)[tx, rx]),
            "field_strength_v_m": float(self.field_strength(True)[tx, rx]),
            "field_strength_dbuv_m": float(self.field_strength_dbuv_m(True)[tx, rx]),
        }

    # ---- channel responses ------------------------------------------------------------
    def cir(self, tx: int = 0, rx: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Channel impulse response of one pair: taps ``a`` (k,) and delays ``tau`` (k,) [s]
        (empty where no path joins them; a transmitter or receiver that does not exist is an
        error)."""
        for name, value, count in (("tx", tx, len(self.paths.tx_positions)), ("rx", rx, len(self.paths.rx_positions))):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 <= value < count:
                raise WavepathsError(f"`{name}` must be an index in 0..{count - 1}, got {value!r}")
        sel = (self.paths.tx_index == tx) & (self.paths.rx_index == rx)
        return self.a[sel], self.delays[sel]

    def cfr(self, frequencies_hz: np.ndarray, tx: int = 0, rx: int = 0) -> np.ndarray:
        """Channel frequency response ``H(f) = sum_i a_i exp(-j 2 pi f tau_i)`` at absolute
        frequencies ``f`` (k,) [Hz], coefficients held at their carrier values."""
        a, tau = self.cir(tx, rx)
        f = np.asarray(frequencies_hz, dtype=float)
        return np.exp(-2j * np.pi * np.multiply.outer(f, tau)) @ a
