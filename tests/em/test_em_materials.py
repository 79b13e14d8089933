"""ITU-R P.2040 materials, PEC/absorber flags and Sionna XML material properties."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.constants import epsilon_0

from wavepaths.em.materials import (
    ABSORBER,
    ITU_MATERIALS,
    PEC,
    Material,
    itu_material,
    material_from_sionna,
    relative_permittivity,
)
from wavepaths.errors import WavepathsError

# η = ε' − j σ/(ω ε0) from the reference's table (diffraction-physics.md §8), 4 decimals.
ETA_TABLE = [
    ("concrete", 1e9, 5.2400 - 0.8304j),
    ("concrete", 3.5e9, 5.2400 - 0.6321j),
    ("concrete", 28e9, 5.2400 - 0.4019j),
    ("brick", 1e9, 3.9100 - 0.4278j),
    ("brick", 3.5e9, 3.9100 - 0.1494j),
    ("brick", 28e9, 3.9100 - 0.0260j),
    ("wood", 1e9, 1.9900 - 0.0845j),
    ("wood", 3.5e9, 1.9900 - 0.0924j),
    ("wood", 28e9, 1.9900 - 0.1073j),
    ("glass", 1e9, 6.3100 - 0.0647j),
    ("glass", 3.5e9, 6.3100 - 0.0990j),
    ("glass", 28e9, 6.3100 - 0.2005j),
    ("metal", 1e9, 1 - 1.7975e8j),
    ("metal", 3.5e9, 1 - 5.1357e7j),
    ("metal", 28e9, 1 - 6.4197e6j),
    ("medium_dry_ground", 1e9, 15.0000 - 0.6291j),
    ("medium_dry_ground", 3.5e9, 13.2338 - 1.3852j),
]

# Names required by the brief (Sionna RT 2.x), plus the others Sionna 2.2's itu.py defines.
BRIEF_NAMES = {
    "concrete", "brick", "plasterboard", "wood", "glass", "ceiling_board", "chipboard",
    "plywood", "marble", "floorboard", "metal", "very_dry_ground", "medium_dry_ground",
    "wet_ground",
}
SIONNA_22_NAMES = BRIEF_NAMES | {"vacuum", "clear_acrylic", "vinyl_tile", "carpet_tile", "asphalt_concrete"}


@pytest.mark.parametrize(("name", "f", "expected"), ETA_TABLE)
def test_eta_table_to_1e4_relative(name: str, f: float, expected: complex) -> None:
    eta = relative_permittivity(itu_material(name), f)
    assert isinstance(eta, complex)
    assert abs(eta - expected) <= 1e-4 * abs(expected)


def test_eta_formula_against_p2040_definition() -> None:
    # ε' = a f^b, σ = c f^d (f in GHz), η = ε' − j σ/(2π f ε0): medium-dry ground has b ≠ 0.
    m = itu_material("medium_dry_ground")
    f = 3.5e9
    eps, sigma = 15.0 * 3.5**-0.1, 0.035 * 3.5**1.63
    assert relative_permittivity(m, f) == pytest.approx(eps - 1j * sigma / (2 * math.pi * f * epsilon_0), rel=1e-14)


def test_eta_vectorised_over_frequency() -> None:
    f = np.array([[1e9, 3.5e9], [28e9, 60e9]])
    eta = relative_permittivity(itu_material("concrete"), f)
    assert eta.shape == (2, 2)
    assert eta[0, 1] == pytest.approx(relative_permittivity(itu_material("concrete"), 3.5e9), rel=1e-15)


def test_names_are_sionna_names() -> None:
    assert BRIEF_NAMES <= set(ITU_MATERIALS)
    assert set(ITU_MATERIALS) == SIONNA_22_NAMES
    for name, m in ITU_MATERIALS.items():
        assert m.name == name and m.kind == "itu" and m.thickness_m == 0.1


def test_out_of_range_frequency_names_material_and_range() -> None:
    with pytest.raises(WavepathsError, match=r"brick.*\[1e\+09, 4e\+10\]"):
        relative_permittivity(itu_material("brick"), 50e9)
    with pytest.raises(WavepathsError, match="floorboard"):
        relative_permittivity(itu_material("floorboard"), 3.5e9)
    with pytest.raises(WavepathsError):
        relative_permittivity(itu_material("concrete"), -1.0)


def test_pec_and_absorber_have_no_permittivity() -> None:
    assert PEC.is_pec and not PEC.is_absorber
    assert ABSORBER.is_absorber and not ABSORBER.is_pec
    for m in (PEC, ABSORBER):
        with pytest.raises(WavepathsError, match="special-cased"):
            relative_permittivity(m, 3.5e9)


def test_custom_material() -> None:
    m = Material("wall", "custom", a=4.0, c=0.01)
    f = 2e9
    assert relative_permittivity(m, f) == pytest.approx(4.0 - 1j * 0.01 / (2 * math.pi * f * epsilon_0))
    with pytest.raises(WavepathsError):
        Material("bad", "custom", a=0.5)
    with pytest.raises(WavepathsError):
        Material("bad", "custom", a=2.0, b=1.0)
    with pytest.raises(WavepathsError):
        Material("bad", "plasma")  # type: ignore[arg-type]


def test_itu_material_thickness_and_unknown_name() -> None:
    m = itu_material("glass", 0.02)
    assert m.thickness_m == 0.02 and m.c == ITU_MATERIALS["glass"].c
    with pytest.raises(WavepathsError, match="concrete.*wood|valid names"):
        itu_material("unobtainium")


def test_material_from_sionna_itu() -> None:
    # <bsdf type="itu-radio-material"><string name="type" value="concrete"/><float name="thickness" value="0.2"/>
    m = material_from_sionna("itu-radio-material", {"type": "concrete", "thickness": "0.2"})
    assert m == itu_material("concrete", 0.2)
    assert material_from_sionna("itu-radio-material", {"type": "metal"}).thickness_m == 0.1
    with pytest.raises(WavepathsError, match="valid names"):
        material_from_sionna("itu-radio-material", {"type": "kryptonite"})
    with pytest.raises(WavepathsError, match="type"):
        material_from_sionna("itu-radio-material", {})


def test_material_from_sionna_radio_material() -> None:
    m = material_from_sionna(
        "radio-material", {"relative_permittivity": 3.0, "conductivity": 0.5, "thickness": 0.3}, bsdf_id="wall"
    )
    assert (m.kind, m.name, m.a, m.c, m.thickness_m) == ("custom", "wall", 3.0, 0.5, 0.3)
    d = material_from_sionna("radio-material", {})
    assert (d.a, d.c, d.thickness_m) == (1.0, 0.0, 0.1)  # Sionna's defaults
    with pytest.raises(WavepathsError):
        material_from_sionna("radio-material", {"relative_permittivity": "abc"})


def test_material_from_sionna_absorber_legacy_and_unknown() -> None:
    assert material_from_sionna("absorber-radio-material", {}).is_absorber
    # Sionna 0.x ids such as "mat-itu_wet_ground" are ITU materials whatever the type.
    assert material_from_sionna("diffuse", {}, bsdf_id="mat-itu_wet_ground") == itu_material("wet_ground")
    assert material_from_sionna("twosided", {"type": "brick"}, bsdf_id="itu_x").name == "brick"
    with pytest.raises(WavepathsError, match="radio-material"):
        material_from_sionna("diffuse", {}, bsdf_id="wall")
