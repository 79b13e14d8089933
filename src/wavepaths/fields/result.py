"""Field results: per-path coefficients and per-receiver totals."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..search.paths import Paths

ETA_0 = 376.730313668  # free-space impedance [ohm]


def power_db(x: np.ndarray) -> np.ndarray:
    """10 log10(x), with -inf for zeros and no warning."""
    x = np.asarray(x, dtype=float)
    out = np.full(x.shape, -np.inf)
    pos = x > 0
    out[pos] = 10 * np.log10(x[pos])
    return out


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
    """

    paths: Paths
    a_ports: np.ndarray
    frequency_hz: float
    tx_power_dbm: float

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

    def field_strength(self, coherent: bool = True) -> np.ndarray:
        """(m, n) RMS field strength [V/m] at the receiver for ``tx_power_dbm``.

        From the received power of an isotropic receiver, whose effective area is
        ``lambda^2 / 4 pi``: ``E = sqrt(eta_0 P_r 4 pi) / lambda``.
        """
        pr = 1e-3 * 10 ** (self.received_power_dbm(coherent) / 10)
        lam = 299_792_458.0 / self.frequency_hz
        return np.sqrt(ETA_0 * pr * 4 * np.pi) / lam

    def field_strength_dbuv_m(self, coherent: bool = True) -> np.ndarray:
        """(m, n) field strength [dBuV/m]."""
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
        """Channel impulse response of one pair: taps ``a`` (k,) and delays ``tau`` (k,) [s]."""
        sel = (self.paths.tx_index == tx) & (self.paths.rx_index == rx)
        return self.a[sel], self.delays[sel]

    def cfr(self, frequencies_hz: np.ndarray, tx: int = 0, rx: int = 0) -> np.ndarray:
        """Channel frequency response ``H(f) = sum_i a_i exp(-j 2 pi f tau_i)`` at absolute
        frequencies ``f`` (k,) [Hz], coefficients held at their carrier values."""
        a, tau = self.cir(tx, rx)
        f = np.asarray(frequencies_hz, dtype=float)
        return np.exp(-2j * np.pi * np.multiply.outer(f, tau)) @ a
