"""The coverage map: per-cell sums of path coefficients, and what is read from them.

A :class:`CoverageMap` keeps, per mechanism, transmitter and cell, the sums that every
quantity derives from (so that a map can be re-read as coherent or incoherent, per
transmitter or best server, without tracing again):

* ``a_total`` — ``sum a e^{-j 2 pi f tau}`` over all paths of the cell, in path order
  (the same sum as :meth:`wavepaths.fields.FieldResult.path_gain`);
* ``a_sum`` — the same sum restricted to one mechanism;
* ``power_sum`` — ``sum |a|^2`` per mechanism (the incoherent split, which adds up
  exactly to the incoherent total);
* ``num_paths`` — how many paths of each mechanism reach the cell;
* ``field_total`` — ``sum e e^{-j 2 pi f tau}``, the paths' field vectors at the cell before
  the receive antenna (normalised like ``a``), and ``field_power_sum`` — ``sum |e|^2``: the
  field strength, which does not depend on the receive antenna.

Mechanisms (:data:`MECHANISMS`): line of sight (no interaction), reflection (one or more
specular reflections only), diffraction (a path with an edge diffraction, with or
without reflections).

Cells whose centre lies inside a solid object are NaN in every quantity (``inside``);
cells that no path reaches have zero gain, ``-inf`` dB. ``.npz`` files written by
:meth:`CoverageMap.save` hold the derived maps in dB and the raw sums, with the settings
as JSON under ``metadata``; :meth:`CoverageMap.load` restores the map.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import numpy as np

from ..em.constants import SPEED_OF_LIGHT  # noqa: F401 (re-exported)
from ..errors import WavepathsError
from ..fields.result import ETA_0, power_db
from .grid import Grid, MeshGrid, PlanarGrid

if TYPE_CHECKING:  # pragma: no cover
    import matplotlib.artist

MECHANISMS = ("los", "reflection", "diffraction")
Mechanism = Literal["los", "reflection", "diffraction"]
FORMAT_VERSION = 1
NPZ_UNITS = {
    "path_gain_db": "dB", "received_power_dbm": "dBm", "field_strength_dbuv_m": "dBuV/m",
    "best_server": "index into tx_positions (-1: inside an object or no path)", "cell_centers": "m", "inside": "bool",
    "path_gain_db_per_tx": "dB", "mechanism_gain_db": "dB (power sum)", "tx_positions": "m",
    "a_total": "1 (complex amplitude, unit transmit power, carrier phase exp(-j 2 pi f tau) included)",
    "a_sum": "1 (complex amplitude, unit transmit power, carrier phase included)",
    "power_sum": "1 (sum of |a|^2, unit transmit power)", "num_paths": "count",
    "field_total": "1 (field 3-vector normalised like a, carrier phase included; "
                   "|e| = lambda / 4 pi d in free space)",
    "field_power_sum": "1 (sum of |e|^2)", "mesh_vertices": "m", "mesh_faces": "index into mesh_vertices",
    "frequency_hz": "Hz", "tx_power_dbm": "dBm", "elapsed_s": "s", "timings": "s",
}
"""The unit of each array of a map file (:meth:`CoverageMap.save`) and of its settings, kept
under ``metadata["units"]``: SI units, dB only in names ending ``_db``, ``_dbm``,
``_dbuv_m``; ``1`` a dimensionless amplitude normalised like Sionna RT's ``Paths.a``."""


def field_strength_dbuv_m(received_power_dbm: np.ndarray, frequency_hz: float) -> np.ndarray:
    """Field strength [dBuV/m] seen by an isotropic receiver that gets ``received_power_dbm``.

    ``received_power_dbm`` must be that of an isotropic receive antenna (any other's gain
    would go into the result). As :func:`wavepaths.fields.result.field_strength_v_m`: the effective area
    ``lambda^2 / 4 pi`` gives ``E = sqrt(eta_0 P_r 4 pi) / lambda`` [V/m]; in decibels
    ``E_dBuV/m = P_dBm - 30 + 10 log10(4 pi eta_0) - 20 log10(lambda) + 120``.
    ``-inf`` and NaN pass through.
    """
    lam = SPEED_OF_LIGHT / frequency_hz
    return np.asarray(received_power_dbm) + (90.0 + 10 * np.log10(4 * np.pi * ETA_0) - 20 * np.log10(lam))


@dataclass(frozen=True, eq=False)
class CoverageMap:
    """A coverage map over a :class:`PlanarGrid` or :class:`MeshGrid`.

    ``shape`` is the grid's: ``(ny, nx)`` for a planar grid, ``(f,)`` for a mesh.

    Attributes
    ----------
    grid : PlanarGrid or MeshGrid
    cell_centers : shape + (3,) float64 [m]
        Receiver position of each cell.
    inside : shape bool
        Cells inside a solid object: NaN in every quantity, not traced.
    tx_positions : (m, 3) float64 [m]
    a_total : (m,) + shape complex128
        ``sum a e^{-j 2 pi f tau}`` over the cell's paths (first port pair), unit
        transmit power.
    a_sum : (3, m) + shape complex128
        The same per mechanism (:data:`MECHANISMS` order).
    power_sum : (3, m) + shape float64
        ``sum |a|^2`` per mechanism.
    num_paths : (3, m) + shape int32
    frequency_hz : float
    tx_power_dbm : float
    field_total : (m,) + shape + (3,) complex128 or None
        ``sum e e^{-j 2 pi f tau}`` over the cell's paths: their field 3-vectors at the cell
        centre, before the receive antenna (transmit port 0, unit transmit power, normalised
        like ``a``: :attr:`wavepaths.fields.FieldResult.incident_field`). ``None`` in a map
        file written before it was kept.
    field_power_sum : (m,) + shape float64 or None
        ``sum |e|^2``.
    coherent : bool
        Whether the map's default quantities add paths coherently (``|sum a e^{-j2pi f tau}|^2``)
        or by power (``sum |a|^2``).
    elapsed_s : float
        Wall-clock time of :func:`wavepaths.coverage.coverage` (context, inside test,
        tiles) [s].
    timings : dict
        Wall-clock time of each stage [s].
    stats : dict
        Search counters added over all tiles (candidates, rejections, rays cast).
    metadata : dict
        JSON-ready settings: scene, trace options, field settings, coverage options.
    """

    grid: Grid
    cell_centers: np.ndarray
    inside: np.ndarray
    tx_positions: np.ndarray
    a_total: np.ndarray
    a_sum: np.ndarray
    power_sum: np.ndarray
    num_paths: np.ndarray
    frequency_hz: float
    tx_power_dbm: float
    field_total: np.ndarray | None = None
    field_power_sum: np.ndarray | None = None
    coherent: bool = True
    elapsed_s: float = 0.0
    timings: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)

    # ---- sizes -----------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, ...]:
        return self.inside.shape

    @property
    def num_cells(self) -> int:
        return int(self.inside.size)

    @property
    def num_tx(self) -> int:
        return len(self.tx_positions)

    @property
    def cells_per_second(self) -> float:
        """Cells traced (outside objects) per second of ``elapsed_s``."""
        traced = self.num_cells - int(self.inside.sum())
        return traced / self.elapsed_s if self.elapsed_s > 0 else float("nan")

    # ---- linear quantities -----------------------------------------------------------
    def _coherent(self, coherent: bool | None) -> bool:
        return self.coherent if coherent is None else bool(coherent)

    def path_gain_per_tx(self, coherent: bool | None = None) -> np.ndarray:
        """(m,) + shape float64: linear path gain of each transmitter (NaN inside objects)."""
        if self._coherent(coherent):
            return np.abs(self.a_total) ** 2
        return self.power_sum.sum(axis=0)

    @property
    def best_server(self) -> np.ndarray:
        """shape int64: the transmitter with the highest path gain (the map's default
        reading, :attr:`coherent`); -1 inside objects or where no path arrives."""
        return self.best_server_by()

    def best_server_by(self, coherent: bool | None = None) -> np.ndarray:
        """shape int64: the transmitter with the highest coherent (``|sum a e^{-j2pi f tau}|^2``)
        or incoherent (``sum |a|^2``) path gain; default the map's :attr:`coherent`; -1 inside
        objects or where no path arrives."""
        g = self.path_gain_per_tx(coherent)
        filled = np.where(np.isnan(g), -1.0, g)
        best = np.argmax(filled, axis=0)
        reached = np.take_along_axis(filled, best[None], axis=0)[0] > 0
        return np.where(reached & ~self.inside, best, -1)

    def _select(self, per_tx: np.ndarray, tx: int | None, coherent: bool | None = None) -> np.ndarray:
        """``per_tx`` (m,) + shape or (3, m) + shape -> that transmitter, or the best server
        of the ``coherent`` reading."""
        axis = per_tx.ndim - len(self.shape) - 1
        if tx is not None:
            if not -self.num_tx <= tx < self.num_tx:
                raise WavepathsError(f"`tx` must be in 0..{self.num_tx - 1}, got {tx}")
            return np.take(per_tx, tx, axis=axis)
        best = np.maximum(self.best_server_by(coherent), 0)
        idx = best.reshape((1,) * (axis + 1) + best.shape)
        return np.squeeze(np.take_along_axis(per_tx, idx, axis=axis), axis=axis)

    def path_gain(self, tx: int | None = None, coherent: bool | None = None) -> np.ndarray:
        """shape float64: linear path gain of transmitter ``tx``, or of the best server.

        The best server is that of the same reading: with ``coherent=False``, the
        transmitter with the highest power sum (:meth:`best_server_by`), so the map is the
        highest incoherent gain of all transmitters."""
        return self._select(self.path_gain_per_tx(coherent), tx, coherent)

    def path_count(self, tx: int | None = None) -> np.ndarray:
        """shape int64: paths (all mechanisms) reaching each cell from transmitter ``tx``, or
        from any transmitter when ``tx`` is None; 0 inside objects."""
        per_tx = self.num_paths.sum(axis=0).astype(np.int64)  # (m,) + shape
        if tx is not None:
            if not -self.num_tx <= tx < self.num_tx:
                raise WavepathsError(f"`tx` must be in 0..{self.num_tx - 1}, got {tx}")
            count = per_tx[tx]
        else:
            count = per_tx.sum(axis=0)
        return np.where(self.inside, 0, count)

    def without_paths(self, tx: int | None = None) -> np.ndarray:
        """shape bool: cells outside objects that no path reaches (from ``tx``, or from any
        transmitter), whatever the quantity read: :meth:`path_count` is 0."""
        return (self.path_count(tx) == 0) & ~self.inside

    def mechanism_gain(self, mechanism: Mechanism, tx: int | None = None) -> np.ndarray:
        """shape float64: ``sum |a|^2`` over the paths of one mechanism (the incoherent split).

        Without ``tx``: of the map's best server (:attr:`best_server`, the map's default
        reading), so that the split belongs to the transmitter :meth:`path_gain` shows."""
        if mechanism not in MECHANISMS:
            raise WavepathsError(f"`mechanism` must be one of {MECHANISMS}, got {mechanism!r}")
        return self._select(self.power_sum, tx)[MECHANISMS.index(mechanism)]

    # ---- decibels ----------------------------------------------------------------------
    def path_gain_db(self, tx: int | None = None, coherent: bool | None = None) -> np.ndarray:
        """shape float64: path gain [dB]; ``-inf`` where no path arrives, NaN inside objects."""
        return power_db(self.path_gain(tx, coherent))

    def received_power_dbm(self, tx: int | None = None, coherent: bool | None = None) -> np.ndarray:
        """shape float64: received power [dBm] for ``tx_power_dbm``."""
        return self.tx_power_dbm + self.path_gain_db(tx, coherent)

    @property
    def receive_pattern(self) -> str | None:
        """The receive antenna's pattern from :attr:`metadata` (``None`` when not recorded)."""
        ant = self.metadata.get("field_config", {}).get("rx_antenna")
        return ant.get("pattern") if isinstance(ant, dict) else None

    @property
    def has_field_strength(self) -> bool:
        """Whether :meth:`field_strength_dbuv_m` can be read: the map holds the field sums
        (every map traced now), or, for a map file written before them, its receive antenna
        is isotropic (or not recorded)."""
        return self.field_total is not None or self.receive_pattern in (None, "iso")

    def field_gain_per_tx(self, coherent: bool | None = None) -> np.ndarray:
        """(m,) + shape float64: the squared magnitude of the field at the cell, unit transmit
        power, normalised like the path gain (free space, isotropic transmitter:
        ``(lambda / 4 pi d)^2``): ``|sum e e^{-j 2 pi f tau}|^2`` (all polarisations) or
        ``sum |e|^2``; as :meth:`wavepaths.fields.FieldResult.field_gain`."""
        if self.field_total is None:
            raise WavepathsError("this coverage map file holds no field sums (written by an older wavepaths)")
        if self._coherent(coherent):
            return np.sum(np.abs(self.field_total) ** 2, axis=-1)
        return self.field_power_sum

    def field_strength_dbuv_m(self, tx: int | None = None, coherent: bool | None = None) -> np.ndarray:
        """shape float64: field strength [dBuV/m] for ``tx_power_dbm``: the field at the cell
        whatever the receive antenna (the transmit antenna's gain included), of transmitter
        ``tx`` or of the best server of the same reading (:meth:`best_server_by` of
        ``coherent``, as :meth:`path_gain` and :meth:`received_power_dbm` pick it).

        ``E = sqrt(eta_0 P_t 4 pi g) / lambda`` with ``g`` the :meth:`field_gain_per_tx`
        (:func:`field_strength_dbuv_m` of ``P_t g``, the power an isotropic antenna matched
        to the field would receive): the magnitude of the total field vector (coherent), or
        the root of the paths' summed squared magnitudes. The same as
        :meth:`wavepaths.fields.FieldResult.field_strength` at the cell centre. A map file
        written before the field sums were kept falls back to the received power, right
        only for an isotropic receive antenna co-polarised with the field (another receive
        antenna raises :class:`WavepathsError`).
        """
        if self.field_total is not None:
            g = self._select(self.field_gain_per_tx(coherent), tx, coherent)
            return field_strength_dbuv_m(self.tx_power_dbm + power_db(g), self.frequency_hz)
        if not self.has_field_strength:
            raise WavepathsError(
                f"this coverage map file holds no field sums (written by an older wavepaths), and its received "
                f"power includes its receive antenna ({self.receive_pattern!r}): trace the map again")
        return field_strength_dbuv_m(self.received_power_dbm(tx, coherent), self.frequency_hz)

    def mechanism_gain_db(self, mechanism: Mechanism, tx: int | None = None) -> np.ndarray:
        """shape float64: :meth:`mechanism_gain` [dB]."""
        return power_db(self.mechanism_gain(mechanism, tx))

    def quantity(self, name: str, tx: int | None = None) -> np.ndarray:
        """One of ``path_gain_db``, ``received_power_dbm``, ``field_strength_dbuv_m``, or
        ``<mechanism>_gain_db`` (``los_gain_db``, ``reflection_gain_db``, ``diffraction_gain_db``)."""
        if name in ("path_gain_db", "received_power_dbm", "field_strength_dbuv_m"):
            return getattr(self, name)(tx)
        for mech in MECHANISMS:
            if name == f"{mech}_gain_db":
                return self.mechanism_gain_db(mech, tx)
        names = ["path_gain_db", "received_power_dbm", "field_strength_dbuv_m"] + [f"{m}_gain_db" for m in MECHANISMS]
        raise WavepathsError(f"`quantity` must be one of {names}, got {name!r}")

    # ---- files -------------------------------------------------------------------------
    def save(self, path: str) -> str:
        """Write the map to ``path`` (``.npz``, compressed). Returns the path written.

        Keys: ``path_gain_db``, ``received_power_dbm``, ``field_strength_dbuv_m``,
        ``best_server`` (shape; best server), ``cell_centers`` (shape + (3,)) [m],
        ``inside`` (shape), ``path_gain_db_per_tx`` ((m,) + shape),
        ``mechanism_gain_db`` ((3, m) + shape, :data:`MECHANISMS` order), ``tx_positions``
        (m, 3), the raw sums ``a_total``, ``a_sum``, ``power_sum``, ``num_paths``,
        ``field_total``, ``field_power_sum``,
        ``mesh_vertices`` and ``mesh_faces`` for a mesh grid, and ``metadata`` (a JSON
        string).
        """
        if not str(path).endswith(".npz"):
            path = f"{path}.npz"
        meta = dict(self.metadata)
        meta.update({
            "format_version": FORMAT_VERSION,
            "grid": self.grid.describe(),
            "frequency_hz": self.frequency_hz,
            "tx_power_dbm": self.tx_power_dbm,
            "coherent": self.coherent,
            "elapsed_s": self.elapsed_s,
            "timings": self.timings,
            "stats": {k: int(v) for k, v in self.stats.items()},
            "mechanisms": list(MECHANISMS),
            "units": NPZ_UNITS,
        })
        arrays = {
            "path_gain_db": self.path_gain_db(),
            "received_power_dbm": self.received_power_dbm(),
            "best_server": self.best_server,
            "cell_centers": self.cell_centers,
            "inside": self.inside,
            "path_gain_db_per_tx": power_db(self.path_gain_per_tx()),
            "mechanism_gain_db": power_db(self.power_sum),
            "tx_positions": self.tx_positions,
            "a_total": self.a_total,
            "a_sum": self.a_sum,
            "power_sum": self.power_sum,
            "num_paths": self.num_paths,
            "metadata": np.array(json.dumps(meta)),
        }
        if self.field_total is not None:
            arrays["field_total"] = self.field_total
            arrays["field_power_sum"] = self.field_power_sum
        if self.has_field_strength:
            arrays["field_strength_dbuv_m"] = self.field_strength_dbuv_m()
        if isinstance(self.grid, MeshGrid):
            arrays["mesh_vertices"] = self.grid.vertices
            arrays["mesh_faces"] = self.grid.faces
        np.savez_compressed(path, **arrays)
        return str(path)

    @classmethod
    def load(cls, path: str) -> "CoverageMap":
        """Read a map written by :meth:`save`."""
        try:
            fh = open(path, "rb")
        except OSError as exc:
            raise WavepathsError(f"{path}: cannot read a coverage map ({exc})") from None
        try:  # np.load leaves its own handle open when the zip is truncated: ours is closed here
            data = np.load(fh, allow_pickle=False)
        except (OSError, ValueError, zipfile.BadZipFile) as exc:  # foreign or truncated
            fh.close()
            raise WavepathsError(f"{path}: cannot read a coverage map ({exc})") from None
        with fh, data:
            need = ("metadata", "cell_centers", "inside", "tx_positions", "a_total", "a_sum", "power_sum", "num_paths")
            missing = [k for k in need if k not in data.files]
            if missing:
                raise WavepathsError(f"{path}: not a wavepaths coverage map (missing {missing})")
            meta = json.loads(str(data["metadata"]))
            g = meta["grid"]
            if g["kind"] == "planar":
                grid: Grid = PlanarGrid(g["center"], g["size"], g["cell_size"], orientation=g["orientation"])
            else:
                grid = MeshGrid(data["mesh_vertices"], data["mesh_faces"], g["offset"])
            own = {"grid", "frequency_hz", "tx_power_dbm", "coherent", "elapsed_s", "timings", "stats",
                   "format_version", "mechanisms", "units"}
            return cls(
                grid=grid,
                cell_centers=data["cell_centers"],
                inside=data["inside"],
                tx_positions=data["tx_positions"],
                a_total=data["a_total"],
                a_sum=data["a_sum"],
                power_sum=data["power_sum"],
                num_paths=data["num_paths"],
                field_total=data["field_total"] if "field_total" in data.files else None,
                field_power_sum=data["field_power_sum"] if "field_power_sum" in data.files else None,
                frequency_hz=float(meta["frequency_hz"]),
                tx_power_dbm=float(meta["tx_power_dbm"]),
                coherent=bool(meta["coherent"]),
                elapsed_s=float(meta["elapsed_s"]),
                timings=dict(meta["timings"]),
                stats=dict(meta["stats"]),
                metadata={k: v for k, v in meta.items() if k not in own},
            )

    # ---- pictures ----------------------------------------------------------------------
    def plot(self, quantity: str = "path_gain_db", tx: int | None = None, **kwargs) -> "matplotlib.artist.Artist":
        """Draw the map with matplotlib (see :func:`wavepaths.coverage.plot.plot_coverage`)."""
        from .plot import plot_coverage

        return plot_coverage(self, quantity=quantity, tx=tx, **kwargs)


