"""Field settings: frequency, diffraction model, antennas, transmit power."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import numpy as np
from scipy.constants import speed_of_light

from ..em.antennas import Antenna
from ..errors import WavepathsError

if TYPE_CHECKING:  # pragma: no cover
    from ..scene.model import Scene

DiffractionModel = Literal["utd", "gtd"]
Compat = Literal["none", "sionna"]
ReflectionModel = Literal["slab", "half_space"]


def _check_antenna(name: str, value: object) -> None:
    """Raise a :class:`WavepathsError` unless ``value`` is an :class:`Antenna`.

    Parameters
    ----------
    name : str
        The argument's name, for the message.
    value : object
        What was given.
    """
    if isinstance(value, Antenna):
        return
    hint = f"; write Antenna({value!r})" if isinstance(value, str) else ""
    raise WavepathsError(f"`{name}` must be an Antenna (wavepaths.em.antennas.Antenna), got "
                         f"{type(value).__name__} {value!r}{hint}")


@dataclass(frozen=True)
class FieldConfig:
    """How to turn path geometry into complex path coefficients.

    Attributes
    ----------
    frequency_hz : float
        Carrier frequency [Hz].
    model : {"utd", "gtd"}
        Diffraction coefficients: Kouyoumjian-Pathak UTD with Luebbers' face
        reflection coefficients for finitely conducting faces ("utd"), or Keller's
        non-uniform GTD ("gtd", diverges at shadow and reflection boundaries).
    compat : {"none", "sionna"}
        "sionna" replaces the diffraction matrix by Sionna RT 2.2's combination
        (``R0 (d1 - d4) + Rn (d2 - d3)``, see docs/sionna-diffraction.md) so that the rest
        of the chain can be compared with Sionna RT like for like. Not physics: the
        textbook model is the default.
    reflection_model : {"slab", "half_space"}
        Reflection off a material: ITU-R P.2040 single-layer slab of the material's
        thickness (as Sionna RT), or a half-space.
    tx_antenna, rx_antenna : Antenna
        Transmit and receive antennas (:class:`~wavepaths.em.antennas.Antenna`; a pattern
        name such as ``"dipole"`` is refused: write ``Antenna("dipole")``).
    tx_power_dbm : float
        Transmit power for received power and field strength [dBm]; finite (NaN or
        infinity raise :class:`~wavepaths.errors.WavepathsError`).
    compiled : bool
        Run the reflections and the ``"utd"`` diffraction (without the Sionna compat mode)
        in the compiled kernels of :mod:`wavepaths.fields.compiled` when numba is installed
        (the same formulas; ``False`` runs the numpy reference).
    """

    frequency_hz: float = 3.5e9
    model: DiffractionModel = "utd"
    compat: Compat = "none"
    reflection_model: ReflectionModel = "slab"
    tx_antenna: Antenna = field(default_factory=Antenna)
    rx_antenna: Antenna = field(default_factory=Antenna)
    tx_power_dbm: float = 0.0
    compiled: bool = True

    def __post_init__(self) -> None:
        if isinstance(self.frequency_hz, bool) or not isinstance(self.frequency_hz, numbers.Real):
            raise WavepathsError(f"`frequency_hz` must be a number [Hz], got {self.frequency_hz!r}")
        if not (self.frequency_hz > 0 and self.frequency_hz < 1e13):
            raise WavepathsError(f"`frequency_hz` must be in (0, 1e13) Hz, got {self.frequency_hz}")
        if self.model not in ("utd", "gtd"):
            raise WavepathsError(f"`model` must be one of ('utd', 'gtd'), got {self.model!r}")
        if self.compat not in ("none", "sionna"):
            raise WavepathsError(f"`compat` must be one of ('none', 'sionna'), got {self.compat!r}")
        if self.reflection_model not in ("slab", "half_space"):
            raise WavepathsError(f"`reflection_model` must be one of ('slab', 'half_space'), got {self.reflection_model!r}")
        for name in ("tx_antenna", "rx_antenna"):
            _check_antenna(name, getattr(self, name))
        if not isinstance(self.compiled, (bool, np.bool_)):
            raise WavepathsError(f"`compiled` must be True or False, got {self.compiled!r}")
        if isinstance(self.tx_power_dbm, bool) or not isinstance(self.tx_power_dbm, numbers.Real) \
                or not math.isfinite(self.tx_power_dbm):
            raise WavepathsError(f"`tx_power_dbm` must be a finite number [dBm], got {self.tx_power_dbm!r}")

    def check_materials(self, scene: "Scene") -> None:
        """Raise :class:`~wavepaths.errors.WavepathsError` now, before a search, when a material of
        ``scene``'s faces has no value at this frequency (an ITU-R P.2040 material outside its
        range): the fields would fail only after the whole search."""
        from ..em.materials import relative_permittivity

        for i in np.unique(scene.triangle_material):
            material = scene.materials[i]
            if material.kind not in ("pec", "absorber"):
                relative_permittivity(material, self.frequency_hz)  # raises out of range

    @property
    def wavelength(self) -> float:
        """Free-space wavelength [m]."""
        return speed_of_light / self.frequency_hz

    @property
    def wavenumber(self) -> float:
        """Free-space wavenumber k = 2 pi / lambda [rad/m]."""
        return 2.0 * 3.141592653589793 / self.wavelength

    @classmethod
    def from_cli(cls, args) -> "FieldConfig":
        """From the ``paths`` / ``coverage`` command-line flags."""
        import math

        def antenna(side: str) -> Antenna:
            pattern = getattr(args, f"{side}_antenna", None) or getattr(args, "antenna", "iso")
            degrees = [float(a) for a in (getattr(args, f"{side}_orientation", None) or (0, 0, 0))]
            if not all(math.isfinite(a) for a in degrees):
                raise WavepathsError(f"--{side}-orientation must be three finite angles [deg], got {degrees}")
            yaw, pitch, roll = (math.radians(a) for a in degrees)
            return Antenna(pattern=pattern, polarization=getattr(args, "polarization", "V"),
                           orientation=(yaw, pitch, roll))

        return cls(
            frequency_hz=args.frequency,
            model=args.model,
            compat=getattr(args, "compat", "none"),
            tx_antenna=antenna("tx"),
            rx_antenna=antenna("rx"),
            tx_power_dbm=0.0 if getattr(args, "tx_power_dbm", None) is None else args.tx_power_dbm,
        )
