"""Radio materials: ITU-R P.2040 permittivity model, PEC, absorber, Sionna RT names.

The complex relative permittivity follows ITU-R P.2040-3, section 2.1.4 and Table 3, with the time factor ``exp(+jwt)`` of ``docs/conventions.md``::

    eps_r' = a * f_GHz**b
    sigma  = c * f_GHz**d                       [S/m]
    eta    = eps_r' - j * sigma / (omega * eps_0)

A perfect electric conductor and a perfect absorber have no finite permittivity: they
are separate ``kind`` values that :mod:`wavepaths.em.fresnel` special-cases exactly
(PEC: ``r_te = -1``, ``r_tm = +1``; absorber: no reflection, no transmission).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.constants import epsilon_0

from wavepaths.errors import WavepathsError

__all__ = [
    "ABSORBER",
    "ITU_MATERIALS",
    "PEC",
    "Material",
    "as_material",
    "itu_material",
    "material_by_name",
    "material_from_sionna",
    "relative_permittivity",
]

MaterialKind = Literal["itu", "custom", "pec", "absorber"]
_KINDS: tuple[str, ...] = ("itu", "custom", "pec", "absorber")

#: Default slab thickness of Sionna RT 2.x (``sionna.rt.constants.DEFAULT_THICKNESS``) [m].
DEFAULT_THICKNESS_M = 0.1


@dataclasses.dataclass(frozen=True)
class Material:
    """A radio material.

    Parameters
    ----------
    name : str
        Name, e.g. ``"concrete"``.
    kind : {"itu", "custom", "pec", "absorber"}
        ``"itu"``: ITU-R P.2040 Table 3 row, ``eps_r' = a f^b``, ``sigma = c f^d`` (f in GHz).
        ``"custom"``: frequency-independent; ``a`` is the relative permittivity and ``c``
        the conductivity [S/m] (``b = d = 0``). ``"pec"``: perfect electric conductor.
        ``"absorber"``: reflects and transmits nothing.
    a, b, c, d : float
        P.2040 coefficients (see ``kind``).
    f_min_hz, f_max_hz : float
        Frequency range [Hz] where the model is valid (inclusive).
    thickness_m : float
        Slab thickness [m] used by the single-layer slab reflection model.
    """

    name: str
    kind: MaterialKind
    a: float = 1.0
    b: float = 0.0
    c: float = 0.0
    d: float = 0.0
    f_min_hz: float = 0.0
    f_max_hz: float = math.inf
    thickness_m: float = DEFAULT_THICKNESS_M

    def __post_init__(self) -> None:
        if self.kind not in _KINDS:
            raise WavepathsError(
                f"material {self.name!r}: `kind` must be one of {_KINDS}, got {self.kind!r}"
            )
        if not (self.thickness_m >= 0.0 and math.isfinite(self.thickness_m)):
            raise WavepathsError(
                f"material {self.name!r}: `thickness_m` must be finite and >= 0, "
                f"got {self.thickness_m!r}"
            )
        if not self.f_min_hz <= self.f_max_hz:
            raise WavepathsError(
                f"material {self.name!r}: need f_min_hz <= f_max_hz, "
                f"got {self.f_min_hz!r} > {self.f_max_hz!r}"
            )
        if self.kind == "custom":
            if not (self.a >= 1.0 and math.isfinite(self.a)):
                raise WavepathsError(
                    f"material {self.name!r}: relative permittivity `a` must be finite and "
                    f">= 1, got {self.a!r}"
                )
            if not (self.c >= 0.0 and math.isfinite(self.c)):
                raise WavepathsError(
                    f"material {self.name!r}: conductivity `c` must be finite and >= 0 S/m, "
                    f"got {self.c!r}"
                )
            if self.b != 0.0 or self.d != 0.0:
                raise WavepathsError(
                    f"material {self.name!r}: a custom material has b = d = 0, "
                    f"got b={self.b!r}, d={self.d!r}"
                )

    @property
    def is_pec(self) -> bool:
        """True for a perfect electric conductor."""
        return self.kind == "pec"

    @property
    def is_absorber(self) -> bool:
        """True for a perfect absorber."""
        return self.kind == "absorber"


PEC = Material("pec", "pec")
ABSORBER = Material("absorber", "absorber")


def _itu(name: str, a: float, b: float, c: float, d: float, f_lo_ghz: float, f_hi_ghz: float) -> Material:
    return Material(name, "itu", a, b, c, d, f_lo_ghz * 1e9, f_hi_ghz * 1e9, DEFAULT_THICKNESS_M)


# ITU-R P.2040-3 Table 3 (the rows valid up to 100 GHz), under the names Sionna RT 2.2 uses
# (sionna/rt/radio_materials/itu.py, first frequency range of each material). The last four
# (vinyl_tile, carpet_tile, asphalt_concrete: 1-40 GHz; clear_acrylic: 110-330 GHz) and
# "vacuum" exist in Sionna 2.2 too (P.2040-4 rows); Sionna's additional sub-THz ranges of
# concrete, brick, ... are not represented, since a Material has one range.
ITU_MATERIALS: dict[str, Material] = {
    m.name: m
    for m in (
        _itu("vacuum", 1.0, 0.0, 0.0, 0.0, 0.001, 100.0),
        _itu("concrete", 5.24, 0.0, 0.0462, 0.7822, 1.0, 100.0),
        _itu("brick", 3.91, 0.0, 0.0238, 0.16, 1.0, 40.0),
        _itu("plasterboard", 2.73, 0.0, 0.0085, 0.9395, 1.0, 100.0),
        _itu("wood", 1.99, 0.0, 0.0047, 1.0718, 0.001, 100.0),
        _itu("glass", 6.31, 0.0, 0.0036, 1.3394, 0.1, 100.0),
        _itu("ceiling_board", 1.48, 0.0, 0.0011, 1.0750, 1.0, 100.0),
        _itu("chipboard", 2.58, 0.0, 0.0217, 0.7800, 1.0, 100.0),
        _itu("plywood", 2.71, 0.0, 0.33, 0.0, 1.0, 40.0),
        _itu("marble", 7.074, 0.0, 0.0055, 0.9262, 1.0, 60.0),
        _itu("floorboard", 3.66, 0.0, 0.0044, 1.3515, 50.0, 100.0),
        _itu("metal", 1.0, 0.0, 1e7, 0.0, 1.0, 100.0),
        _itu("very_dry_ground", 3.0, 0.0, 0.00015, 2.52, 1.0, 10.0),
        _itu("medium_dry_ground", 15.0, -0.1, 0.035, 1.63, 1.0, 10.0),
        _itu("wet_ground", 30.0, -0.4, 0.15, 1.30, 1.0, 10.0),
        _itu("vinyl_tile", 3.62, 0.0, 0.0051, 0.8422, 1.0, 40.0),
        _itu("carpet_tile", 2.08, 0.0, 0.0009, 0.8200, 1.0, 40.0),
        _itu("asphalt_concrete", 4.83, 0.0, 0.0108, 1.3969, 1.0, 40.0),
        _itu("clear_acrylic", 2.58, 0.0, 0.0001, 1.6524, 110.0, 330.0),
    )
}


def itu_material(name: str, thickness_m: float = DEFAULT_THICKNESS_M) -> Material:
    """The ITU-R P.2040 material ``name`` with slab thickness ``thickness_m`` [m].

    Raises
    ------
    WavepathsError
        If ``name`` is not a key of :data:`ITU_MATERIALS` (the message lists them).
    """
    try:
        base = ITU_MATERIALS[name]
    except KeyError:
        raise WavepathsError(
            f"unknown ITU material {name!r}; valid names: {', '.join(sorted(ITU_MATERIALS))}"
        ) from None
    return dataclasses.replace(base, thickness_m=float(thickness_m))


def material_by_name(name: str) -> Material | None:
    """The material a mesh file's material name stands for, or None.

    ``"pec"`` and ``"absorber"``, and the ITU-R P.2040 names of :data:`ITU_MATERIALS`, bare
    or with Sionna's prefixes (``concrete``, ``itu_concrete``, ``itu-concrete``,
    ``mat-itu_concrete``), in any case; names with spaces or dashes between words match
    their underscored form (``Medium Dry Ground``).
    """
    key = "_".join(name.strip().lower().replace("-", " ").replace("_", " ").split())  # "ITU Concrete": itu_concrete
    key = key[4:] if key.startswith("mat_") else key
    key = key[4:] if key.startswith("itu_") else key
    if key == "pec":
        return PEC
    if key == "absorber":
        return ABSORBER
    return itu_material(key) if key in ITU_MATERIALS else None


def as_material(value: "Material | str", what: str = "material") -> Material:
    """``value`` as a :class:`Material`: a Material itself, or a name :func:`material_by_name` knows.

    Raises
    ------
    WavepathsError
        Any other value (the message lists the names).
    """
    if isinstance(value, Material):
        return value
    if isinstance(value, str):
        found = material_by_name(value)
        if found is not None:
            return found
        raise WavepathsError(f"{what}: unknown material name {value!r}; use 'pec', 'absorber' or an ITU-R P.2040 "
                             f"name: {', '.join(sorted(ITU_MATERIALS))}")
    raise WavepathsError(f"{what} must be a Material or a material name, got {type(value).__name__}")


def relative_permittivity(
    material: Material, frequency_hz: ArrayLike
) -> complex | NDArray[np.complex128]:
    """Complex relative permittivity ``eta = eps_r' - j sigma/(omega eps_0)``.

    ITU-R P.2040-3 section 2.1.4 and Table 3, time factor ``exp(+jwt)``.

    Parameters
    ----------
    material : Material
        Of kind ``"itu"`` or ``"custom"``.
    frequency_hz : float or array_like
        Frequency [Hz], finite and > 0.

    Returns
    -------
    complex or (...) complex128
        ``eta`` (a Python complex for a scalar frequency).

    Raises
    ------
    WavepathsError
        For a PEC or absorber (no finite permittivity: use
        :func:`wavepaths.em.fresnel.reflection_coefficients`, which handles them), or a
        frequency outside ``[f_min_hz, f_max_hz]`` (the message names the material and range).
    """
    if material.kind in ("pec", "absorber"):
        raise WavepathsError(
            f"material {material.name!r} is of kind {material.kind!r} and has no finite "
            "relative permittivity; its reflection coefficients are special-cased"
        )
    f = np.asarray(frequency_hz, dtype=float)
    if not np.all(np.isfinite(f) & (f > 0.0)):
        raise WavepathsError(f"`frequency_hz` must be finite and > 0, got {frequency_hz!r}")
    if np.any(f < material.f_min_hz) or np.any(f > material.f_max_hz):
        raise WavepathsError(
            f"frequency {frequency_hz!r} Hz is outside the valid range of material "
            f"{material.name!r}: [{material.f_min_hz:g}, {material.f_max_hz:g}] Hz (ITU-R P.2040 Table 3 gives "
            f"its parameters there only); give the objects made of it a material valid at this frequency: "
            f"Material(name, 'custom', a=relative permittivity, c=conductivity [S/m]), in the scene file, "
            f"through load_scene(..., materials=...) for a mesh file, or wavepaths.scene.with_materials(scene, "
            f"{{{material.name!r}: material}}) (on the command line: --replace-material "
            f"{material.name}=EPS_R,SIGMA)"
        )
    if material.kind == "custom":
        eps_r = np.full_like(f, material.a)
        sigma = np.full_like(f, material.c)
    else:
        f_ghz = f / 1e9
        eps_r = material.a * f_ghz**material.b
        sigma = material.c * f_ghz**material.d
    eta = eps_r - 1j * sigma / (2.0 * np.pi * f * epsilon_0)
    if eta.ndim == 0:
        return complex(eta)
    return eta.astype(np.complex128)


# Mitsuba BSDF plugin names that Sionna RT 2.2 registers (radio_materials/*.py).
_SIONNA_BSDF_TYPES = ("itu-radio-material", "radio-material", "absorber-radio-material")


def _prop_float(props: Mapping[str, Any], key: str, default: float, what: str) -> float:
    value = props.get(key, default)
    try:
        return float(value)
    except (TypeError, ValueError):
        raise WavepathsError(f"{what}: property {key!r} must be a float, got {value!r}") from None


def _legacy_itu_name(bsdf_id: str | None) -> str | None:
    """The ITU type encoded in a Sionna 0.x style id (``mat-itu_concrete``), else None."""
    if bsdf_id is None:
        return None
    name = bsdf_id[4:] if bsdf_id.startswith("mat-") else bsdf_id
    if name.startswith(("itu_", "itu-")):
        return name[4:]
    return None


def material_from_sionna(
    bsdf_type: str, props: Mapping[str, Any], *, bsdf_id: str | None = None
) -> Material:
    """The material described by a ``<bsdf>`` element of a Sionna RT 2.x Mitsuba XML file.

    Understands the three radio BSDF plugins Sionna RT 2.2 registers:

    * ``<bsdf type="itu-radio-material">`` with ``<string name="type" value="concrete"/>``
      and optionally ``<float name="thickness" value="0.1"/>``;
    * ``<bsdf type="radio-material">`` with floats ``relative_permittivity`` (default 1),
      ``conductivity`` [S/m] (default 0) and ``thickness`` [m] (default 0.1);
    * ``<bsdf type="absorber-radio-material">``.

    As in Sionna's XML preprocessing (``scene_utils.py``), any BSDF whose id, after an
    optional ``mat-`` prefix, starts with ``itu_`` or ``itu-`` is an ITU material whose type
    is the rest of the id unless a ``type`` property overrides it.

    Parameters
    ----------
    bsdf_type : str
        The ``type`` attribute of the ``<bsdf>`` element.
    props : mapping
        Its child properties by ``name`` (values may still be strings from the XML).
    bsdf_id : str, optional
        The ``id`` attribute; used for the name and for Sionna 0.x ``itu_`` ids.

    Returns
    -------
    Material

    Notes
    -----
    Sionna's ``scattering_coefficient`` ``S`` (diffuse reflection; it also scales specular
    reflection by ``sqrt(1 - S^2)``) and ``xpd_coefficient`` are not part of a
    :class:`Material` and are ignored.

    Raises
    ------
    WavepathsError
        For an unknown BSDF type, an unknown ITU name (listing the valid names), or invalid
        property values.
    """
    what = f"<bsdf type={bsdf_type!r} id={bsdf_id!r}>"
    legacy = _legacy_itu_name(bsdf_id)
    if bsdf_type == "itu-radio-material" or legacy is not None:
        itu_type = props.get("type", legacy)
        if itu_type is None:
            raise WavepathsError(f"{what}: missing string property 'type' (the ITU material)")
        thickness = _prop_float(props, "thickness", DEFAULT_THICKNESS_M, what)
        if not (thickness >= 0.0 and math.isfinite(thickness)):
            raise WavepathsError(f"{what}: 'thickness' must be finite and >= 0, got {thickness!r}")
        return itu_material(str(itu_type), thickness)
    if bsdf_type == "radio-material":
        eps = _prop_float(props, "relative_permittivity", 1.0, what)
        sigma = _prop_float(props, "conductivity", 0.0, what)
        thickness = _prop_float(props, "thickness", DEFAULT_THICKNESS_M, what)
        return Material(bsdf_id or "custom", "custom", a=eps, c=sigma, thickness_m=thickness)
    if bsdf_type == "absorber-radio-material":
        return dataclasses.replace(ABSORBER, name=bsdf_id or ABSORBER.name)
    raise WavepathsError(
        f"{what}: unknown BSDF type {bsdf_type!r}; expected one of {_SIONNA_BSDF_TYPES} "
        "(or an id starting with 'itu_' / 'mat-itu_')"
    )
