"""What a FieldResult and ``wavepaths paths`` report: a field strength that does not depend on
the receive antenna, strict JSON, totals per (transmitter, receiver) pair, a checked
transmit power."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.constants import speed_of_light

from wavepaths import TraceOptions, WavepathsError, load_scene, trace
from wavepaths.em.antennas import Antenna
from wavepaths.fields import FieldConfig, compute_fields
from wavepaths.fields.result import ETA_0, FieldResult

from ..conftest import quads_scene, strict_json

WAVEPATHS = os.path.join(os.path.dirname(sys.executable), "wavepaths")
PATTERNS = ("iso", "dipole", "hw_dipole", "tr38901")


def run_paths(*args):
    return subprocess.run([WAVEPATHS, "paths", *map(str, args)], capture_output=True, text=True, timeout=300)


def far_los(d=200.0):
    """A single line-of-sight path of length ``d`` along +y, far from a small screen."""
    s = quads_scene([[[-1, -1, -100], [1, -1, -100], [1, 1, -100], [-1, 1, -100]]])
    p = trace(s, [[500.0, 500.0, 0.0]], [[500.0, 500.0 + d, 0.0]], TraceOptions(max_reflections=0, diffraction=False))
    assert len(p) == 1
    return s, p


def free_space_dbuv_m(tx_power_dbm, tx_gain, d):
    """Field of an EIRP ``P_t G_t`` at distance ``d``: ``E = sqrt(eta_0 P_t G_t / 4 pi) / d``."""
    pt = 1e-3 * 10 ** (tx_power_dbm / 10)
    return 20 * np.log10(np.sqrt(ETA_0 * pt * tx_gain / (4 * np.pi)) / d * 1e6)


# ---- field strength independent of the receive antenna ------------------------------------
@pytest.mark.parametrize("rx_pattern", PATTERNS)
@pytest.mark.parametrize("tx_pattern, tx_gain", [("iso", 1.0), ("dipole", 1.5)])
def test_field_strength_is_the_free_space_field_whatever_the_receive_antenna(rx_pattern, tx_pattern, tx_gain):
    s, p = far_los(200.0)  # broadside of a vertical dipole: its gain is 1.5
    cfg = FieldConfig(tx_power_dbm=30.0, tx_antenna=Antenna(tx_pattern), rx_antenna=Antenna(rx_pattern))
    r = compute_fields(s, p, cfg)
    want = free_space_dbuv_m(30.0, tx_gain, 200.0)
    for coherent in (True, False):
        assert r.field_strength_dbuv_m(coherent)[0, 0] == pytest.approx(want, abs=1e-9)


def test_field_strength_off_the_receivers_boresight_is_not_reduced():
    """The review's case: a TR 38.901 receiver 90 degrees off boresight (its gain -15 dBi)."""
    s, p = far_los(200.0)
    ant = Antenna("tr38901")
    cfg = FieldConfig(tx_power_dbm=30.0, tx_antenna=ant, rx_antenna=ant)
    r = compute_fields(s, p, cfg)
    tx_gain = 10 ** ((r.path_gain_db()[0, 0] + 20 * np.log10(4 * np.pi * 200.0 * 3.5e9 / speed_of_light)) / 20)
    assert r.field_strength_dbuv_m()[0, 0] == pytest.approx(free_space_dbuv_m(30.0, tx_gain, 200.0), abs=1e-9)


@pytest.fixture(scope="module")
def canyon_paths():
    scene = load_scene("street_canyon")
    rx = np.array([[-30.3, 1.2, 1.5], [10.7, -3.1, 1.5], [55.0, 0.4, 1.5]])
    return scene, trace(scene, [[-60, 0, 10], [40, 5, 8]], rx, TraceOptions(max_reflections=2))


def test_the_incident_field_carries_every_polarisation(canyon_paths):
    """The power sum of the field equals the power a dual-polarised isotropic receiver collects
    (its ports' theta and phi hats span the plane transverse to each arrival): with
    reflections and diffraction, not only on the line of sight."""
    scene, p = canyon_paths
    cfg = FieldConfig(rx_antenna=Antenna("iso", "VH"))
    r = compute_fields(scene, p, cfg)
    both_ports = r._pair_sum((np.abs(r.a_ports[:, :, 0]) ** 2).sum(axis=1))
    assert len(p) > 50 and (p.interactions > 0).any()
    np.testing.assert_allclose(r.field_gain(coherent=False), both_ports, rtol=1e-12)


@pytest.mark.parametrize("coherent", [True, False])
def test_field_strength_does_not_change_with_the_receive_antenna_on_many_paths(canyon_paths, coherent):
    scene, p = canyon_paths
    got = []
    for pattern in PATTERNS:
        cfg = FieldConfig(rx_antenna=Antenna(pattern), tx_power_dbm=20.0)
        got.append(compute_fields(scene, p, cfg).field_strength(coherent))
    for g in got[1:]:
        np.testing.assert_allclose(g, got[0], rtol=1e-12)


def test_incident_field_shape_is_checked(canyon_paths):
    scene, p = canyon_paths
    from wavepaths.fields.result import incident_fields

    r = compute_fields(scene, p)
    e = incident_fields(scene, p, FieldConfig())
    assert e.shape == (len(p), 1, 3)
    with pytest.raises(WavepathsError, match="incident_field"):
        FieldResult(p, r.a_ports, r.frequency_hz, r.tx_power_dbm, incident_field=e[:, :, :2])


def test_cli_field_strength_does_not_include_the_receive_antenna():
    """``paths --json`` for the review's line of sight (200 m, 30 dBm): with dipoles the field is
    that of the transmitting dipole's EIRP, not 1.76 dB more."""
    common = ["half_plane", "--tx", 500, 500, 0, "--rx", 500, 700, 0, "--max-reflections", 0, "--no-diffraction",
              "--tx-power-dbm", 30, "--json"]
    for antenna, tx_gain in (("iso", 1.0), ("dipole", 1.5), ("hw_dipole", None)):
        r = run_paths(*common, "--antenna", antenna)
        assert r.returncode == 0, r.stderr
        rec = strict_json(r.stdout)["receivers"][0]
        if tx_gain is None:  # half-wave dipole: its gain read from the path gain (both ends alike)
            friis = 20 * np.log10(speed_of_light / 3.5e9 / (4 * np.pi * 200.0))
            tx_gain = 10 ** ((rec["path_gain_db"] - friis) / 20)
        want = free_space_dbuv_m(30.0, tx_gain, 200.0)
        assert rec["field_strength_dbuv_m"] == pytest.approx(want, abs=1e-9)
        assert 20 * np.log10(rec["field_strength_v_m"] * 1e6) == pytest.approx(want, abs=1e-9)


def test_cli_antennas_per_side_and_their_orientation():
    """``--antenna`` sets both ends; ``--tx-antenna``/``--rx-antenna`` one end each, and
    ``--tx-orientation`` turns the transmit antenna [deg]. Line of sight along +y (200 m):
    a TR 38.901 panel gains 8 dBi on its boresight, +x by default; yawed by 90 deg it faces
    the receiver. Path gains against an isotropic pair, on the same path."""
    common = ["half_plane", "--tx", 500, 500, 0, "--rx", 500, 700, 0, "--max-reflections", 0, "--no-diffraction",
              "--json"]

    def gain(*flags):
        r = run_paths(*common, *flags)
        assert r.returncode == 0, r.stderr
        return strict_json(r.stdout)["receivers"][0]["path_gain_db"]

    iso = gain()
    facing = gain("--tx-antenna", "tr38901", "--tx-orientation", 90, 0, 0)
    assert facing - iso == pytest.approx(8.0, abs=1e-6)  # the panel's maximum gain, receiver isotropic
    both = gain("--antenna", "tr38901", "--tx-orientation", 90, 0, 0, "--rx-orientation", -90, 0, 0)
    assert both - iso == pytest.approx(16.0, abs=1e-6)
    assert gain("--antenna", "tr38901", "--rx-antenna", "iso", "--tx-orientation", 90, 0, 0) == pytest.approx(facing)


def test_paths_json_names_the_objects_and_gives_the_angles():
    """Each path of ``paths --json`` names the object of each interaction and carries its
    departure and arrival angles [deg] (zenith from +z, azimuth from +x): a ground
    reflection from (0, 0, 10) to (40, 0, 2) leaves at 90 + atan(10/(40 * 10/12)) deg and
    arrives from below, mirror-wise."""
    r = run_paths("street_canyon", "--tx", -60, 0.5, 10, "--rx", -20, 0.5, 2, "--max-reflections", 1,
                  "--no-diffraction", "--json")
    assert r.returncode == 0, r.stderr
    paths = strict_json(r.stdout)["paths"]
    los = [p for p in paths if not p["interactions"]][0]
    ground = [p for p in paths if p["objects"] == ["ground"]][0]
    assert los["objects"] == []
    assert los["departure_deg"]["zenith"] == pytest.approx(90 + np.degrees(np.arctan2(8, 40)), abs=1e-9)
    assert abs(los["arrival_deg"]["azimuth"]) == pytest.approx(180.0, abs=1e-9)  # from -x: +-180
    dive = np.degrees(np.arctan2(10, 40 * 10 / 12))  # the reflection point divides 40 m as 10 : 2
    assert ground["departure_deg"]["zenith"] == pytest.approx(90 + dive, abs=1e-9)
    assert ground["arrival_deg"]["zenith"] == pytest.approx(90 + dive, abs=1e-9)


def test_paths_json_says_what_a_holds_and_its_units_add_up():
    """``paths --json`` names the unit of its numbers (``units``), and what it says of ``a``
    holds: the receiver's coherent total is ``|sum a exp(-j 2 pi f tau)|^2`` (``a`` without
    the carrier phase), its power sum ``sum |a|^2``, and ``gain_db`` is ``20 log10 |a|``. On
    the street canyon with reflections and diffraction, several paths of different delays."""
    r = run_paths("street_canyon", "--tx", -60, 0.5, 10, "--rx", 20, 3, 1.5, "--max-reflections", 1,
                  "--tx-orientation", 30, 0, 0, "--json")
    assert r.returncode == 0, r.stderr
    out = strict_json(r.stdout)
    units = out["units"]
    assert "carrier phase" in units["paths.a"] and units["paths.delay_s"] == "s"
    assert units["field_config.tx_antenna.orientation"].startswith("rad")
    assert out["field_config"]["tx_antenna"]["orientation"][0] == pytest.approx(np.radians(30))
    paths, rec = out["paths"], out["receivers"][0]
    assert len(paths) >= 4 and len({round(p["delay_s"], 12) for p in paths}) >= 4
    a = np.array([complex(*p["a"]) for p in paths])
    tau = np.array([p["delay_s"] for p in paths])
    coherent = np.abs(np.sum(a * np.exp(-2j * np.pi * out["frequency_hz"] * tau))) ** 2
    assert 10 * np.log10(coherent) == pytest.approx(rec["path_gain_db"], abs=1e-9)
    assert 10 * np.log10(np.sum(np.abs(a) ** 2)) == pytest.approx(rec["path_gain_incoherent_db"], abs=1e-9)
    assert [p["gain_db"] for p in paths] == pytest.approx(list(20 * np.log10(np.abs(a))), abs=1e-9)
    # every key the file holds a unit for exists in it
    for key in units:
        node = out
        for part in key.split("."):
            node = node[0] if isinstance(node, list) else node
            assert part in node, key
            node = node[part]


# ---- strict JSON --------------------------------------------------------------------------
def test_paths_json_is_strict_json_when_no_path_arrives():
    r = run_paths("half_plane", "--tx", -10, 5, -5, "--rx", 10, -5, -60, "--max-reflections", 0, "--no-diffraction",
                  "--json")
    assert r.returncode == 0, r.stderr
    out = strict_json(r.stdout)
    rec = out["receivers"][0]
    assert out["paths"] == [] and rec["num_paths"] == 0
    for key in ("path_gain_db", "path_gain_incoherent_db", "received_power_dbm", "field_strength_dbuv_m"):
        assert rec[key] is None
    assert rec["field_strength_v_m"] == 0.0
    assert rec["best_server"] is None
    assert rec["per_tx"][0]["path_gain_db"] is None


# ---- several transmitters -----------------------------------------------------------------
def test_paths_reports_totals_per_transmitter_and_receiver():
    args = ["street_canyon", "--tx", -60, 0, 10, "--tx", 60, 0, 10, "--rx", 55, 0, 1.5, "--rx", -20, 3, 1.5,
            "--max-reflections", 1, "--no-diffraction"]
    r = run_paths(*args, "--json")
    assert r.returncode == 0, r.stderr
    out = strict_json(r.stdout)
    f = out["frequency_hz"]
    for rec in out["receivers"]:
        j = rec["rx"]
        mine = [p for p in out["paths"] if p["rx"] == j]
        assert rec["num_paths"] == len(mine)  # over all transmitters, as before
        assert [t["tx"] for t in rec["per_tx"]] == [0, 1]
        gains = []
        for t in rec["per_tx"]:
            ps = [p for p in mine if p["tx"] == t["tx"]]
            assert t["num_paths"] == len(ps) > 0
            total = sum(complex(*p["a"]) * np.exp(-2j * np.pi * f * p["delay_s"]) for p in ps)
            power = sum(abs(complex(*p["a"])) ** 2 for p in ps)
            assert t["path_gain_db"] == pytest.approx(10 * np.log10(abs(total) ** 2), abs=1e-9)
            assert t["path_gain_incoherent_db"] == pytest.approx(10 * np.log10(power), abs=1e-9)
            gains.append(t["path_gain_db"])
        # the receiver's own totals are its best server's, and say so
        assert rec["best_server"] == rec["totals_tx"] == int(np.argmax(gains))
        best = rec["per_tx"][rec["best_server"]]
        for key in ("path_gain_db", "path_gain_incoherent_db", "received_power_dbm", "field_strength_v_m",
                    "field_strength_dbuv_m"):
            assert rec[key] == best[key]
    # receiver 0 (x = 55) is near transmitter 1: a report of transmitter 0 only would miss it
    assert out["receivers"][0]["best_server"] == 1
    text = run_paths(*args)
    assert text.returncode == 0, text.stderr
    for rec in out["receivers"]:
        for t in rec["per_tx"]:
            assert f"tx {t['tx']} -> rx {rec['rx']}: {t['num_paths']} paths, path gain {t['path_gain_db']:.2f} dB" \
                in text.stdout
        assert f"rx {rec['rx']}: best server tx {rec['best_server']}" in text.stdout


# ---- transmit power -----------------------------------------------------------------------
@pytest.mark.parametrize("power", [np.nan, np.inf, -np.inf, "30", None])
def test_tx_power_must_be_a_finite_number(power):
    with pytest.raises(WavepathsError, match="tx_power_dbm"):
        FieldConfig(tx_power_dbm=power)
    assert FieldConfig(tx_power_dbm=np.float32(-12.5)).tx_power_dbm == -12.5


@pytest.mark.parametrize("power", ["nan", "inf", "-inf"])
def test_cli_non_finite_tx_power_exits_2(power):
    r = run_paths("half_plane", "--tx", -10, 5, -5, "--rx", 10, -5, -5, f"--tx-power-dbm={power}", "--json")
    assert r.returncode == 2 and "Traceback" not in r.stderr and "--tx-power-dbm" in r.stderr  # named by its flag


def test_the_impulse_response_of_a_pair_that_does_not_exist_is_an_error():
    """``cir(tx=5)`` of a one-transmitter result returned empty arrays, as for a pair that no
    path joins; now only the latter is empty."""
    s, p = far_los()
    res = compute_fields(s, p)
    a, tau = res.cir(0, 0)
    assert len(a) == len(tau) == 1
    for kwargs, name in (({"tx": 5}, "tx"), ({"rx": -1}, "rx"), ({"tx": 0.0}, "tx")):
        with pytest.raises(WavepathsError, match=f"`{name}` must be an index in 0..0"):
            res.cir(**kwargs)



def test_power_db_is_the_one_db_conversion_zero_is_minus_inf_and_nan_is_kept():
    """``power_db``: 10 log10 of powers, -inf for no power, NaN kept for a cell not traced (the
    map, the validation report and the benchmarks all convert with it); no warning."""
    import warnings

    import numpy as np

    from wavepaths.fields.result import power_db

    x = np.array([[1e-3, 0.0], [np.nan, 2.5]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = power_db(x)
    assert got[0, 0] == pytest.approx(-30.0, abs=1e-12)
    assert got[0, 1] == -np.inf
    assert np.isnan(got[1, 0])
    assert got[1, 1] == pytest.approx(10 * np.log10(2.5), abs=1e-12)
    assert power_db(4.0).shape == ()
