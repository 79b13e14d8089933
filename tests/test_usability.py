"""Usability, from a user's review (twenty-eighth session): what ``paths`` says about transmit power and its settings,
clear errors for misused API arguments, the coordinate limit on coverage grids, plurals and
directories in messages, and a warning for free-space materials."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wavepaths import TraceOptions, WavepathsError, load_scene, trace
from wavepaths.cli import main, plural
from wavepaths.coverage.cli import check_grid_reach
from wavepaths.em.antennas import Antenna
from wavepaths.em.materials import Material
from wavepaths.errors import SceneError
from wavepaths.fields import FieldConfig
from wavepaths.scene import WavepathsWarning
from wavepaths.search.options import BOOLEAN_FIELDS, check_trace_arguments

TX = ["--tx", "-60", "0", "10"]
RX = ["--rx", "20", "0", "1.5"]
LOS_ONLY = ["--max-reflections", "0", "--no-diffraction"]


def run_cli(capsys, *args) -> tuple[int, str, str]:
    """``wavepaths ARGS`` in this process: exit status, stdout, stderr."""
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


# ---- 1. received power in the text, settings in the JSON ----------------------------------
def test_paths_text_shows_received_power_when_tx_power_is_given(capsys):
    code, out, _ = run_cli(capsys, "paths", "street_canyon", *TX, *RX, *LOS_ONLY, "--tx-power-dbm", 30)
    assert code == 0
    gain = float(out.split("path gain ")[1].split(" dB")[0])
    power = float(out.split("received power ")[1].split(" dBm")[0])
    assert power == pytest.approx(gain + 30.0, abs=0.011)
    assert "field strength" in out and "dBuV/m" in out
    code, out, _ = run_cli(capsys, "paths", "street_canyon", *TX, *RX, *LOS_ONLY)
    assert code == 0 and "received power" not in out  # no power given: the gain alone, as before


def test_paths_json_records_the_settings_behind_its_numbers(capsys):
    code, out, _ = run_cli(capsys, "paths", "street_canyon", *TX, *RX, *LOS_ONLY, "--tx-power-dbm", 30,
                           "--tx-antenna", "dipole", "--tx-orientation", 90, 0, 0, "--json")
    assert code == 0
    d = json.loads(out)
    for key in ("scene", "tx", "rx", "paths", "receivers", "frequency_hz"):  # the fields of before stay
        assert key in d
    assert d["tx_power_dbm"] == 30.0
    cfg = d["field_config"]  # named as coverage's .npz metadata names it
    assert cfg["tx_antenna"]["pattern"] == "dipole" and cfg["rx_antenna"]["pattern"] == "iso"
    assert cfg["tx_antenna"]["orientation"][0] == pytest.approx(np.pi / 2)
    assert cfg["frequency_hz"] == d["frequency_hz"] and cfg["tx_power_dbm"] == 30.0
    opts = TraceOptions(**d["trace_options"])
    assert opts == TraceOptions(max_reflections=0, diffraction=False)
    received = d["receivers"][0]["received_power_dbm"]
    assert received == pytest.approx(d["receivers"][0]["path_gain_db"] + 30.0)


def test_paths_json_default_tx_power_is_zero(capsys):
    code, out, _ = run_cli(capsys, "paths", "street_canyon", *TX, *RX, *LOS_ONLY, "--json")
    d = json.loads(out)
    assert code == 0 and d["tx_power_dbm"] == 0.0 and "trace_options" in d


def test_coverage_json_records_the_settings_behind_its_numbers(capsys, tmp_path):
    code, out, _ = run_cli(capsys, "coverage", "street_canyon", *TX, "--height", "1.25", "--cell", "16",
                           "--max-reflections", "1", "--no-diffraction", "--tx-power-dbm", "20", "--incoherent",
                           "--workers", "1", "--out", tmp_path, "--quiet", "--json")
    assert code == 0
    d = json.loads(out)
    for key in ("scene", "shape", "cells", "min", "max", "png", "npz"):  # the fields of before stay
        assert key in d
    assert d["tx_power_dbm"] == 20.0 and d["field_config"]["tx_power_dbm"] == 20.0
    assert TraceOptions(**d["trace_options"]) == TraceOptions(max_reflections=1, diffraction=False)
    assert d["coverage_options"]["coherent"] is False and d["coverage_options"]["workers"] == 1
    with np.load(d["npz"], allow_pickle=False) as saved:  # the same settings as the map's own file records
        meta = json.loads(str(saved["metadata"]))
    for key in ("trace_options", "field_config", "coverage_options"):
        assert meta[key] == d[key]
    # where and at what frequency (a CLI review: `paths --json` had them, `coverage --json` not)
    assert d["frequency_hz"] == meta["frequency_hz"] == 3.5e9 and d["tx"] == [[-60.0, 0.0, 10.0]]
    assert d["grid"] == meta["grid"] and d["coherent"] is False


# ---- 2. misused API arguments -----------------------------------------------------------------
def test_check_trace_arguments_refuses_a_scene_name():
    with pytest.raises(WavepathsError, match=r"`scene` must be a Scene, got str; load it first"):
        check_trace_arguments("street_canyon", None)


def test_build_tx_context_checks_its_arguments_as_trace_does():
    from wavepaths import build_tx_context

    scene = load_scene("half_plane")
    with pytest.raises(WavepathsError, match=r"`scene` must be a Scene, got str"):
        build_tx_context("half_plane", [[0.0, 0.0, 1.0]], TraceOptions())
    with pytest.raises(WavepathsError, match=r"`options` must be a TraceOptions or None, got dict"):
        build_tx_context(scene, [[0.0, 0.0, 1.0]], {"max_reflections": 1})
    with pytest.raises(WavepathsError, match=r"tx"):
        build_tx_context(scene, [[0.0, float("nan"), 1.0]], TraceOptions())
    ctx = build_tx_context(scene, [0.0, 0.0, 1.0], None)  # one position, default options
    assert ctx.tx.shape == (1, 3)


def test_check_trace_arguments_refuses_an_options_dict():
    scene = load_scene("half_plane")
    with pytest.raises(WavepathsError, match=r"`options` must be a TraceOptions or None, got dict"):
        check_trace_arguments(scene, {"max_reflections": 1})
    assert check_trace_arguments(scene, None) == TraceOptions()
    opts = TraceOptions(max_reflections=1)
    assert check_trace_arguments(scene, opts) is opts


@pytest.mark.parametrize("bad", ["scene", "options"])
def test_trace_refuses_wrong_argument_types(bad):
    scene = load_scene("half_plane")
    args = ("half_plane", None) if bad == "scene" else (scene, {"max_reflections": 1})
    with pytest.raises(WavepathsError, match=f"`{bad}` must be"):
        trace(args[0], [[-10, 5, -5]], [[10, -5, -5]], args[1])


@pytest.mark.parametrize("name", BOOLEAN_FIELDS)
@pytest.mark.parametrize("value", ["no", "False", 1, 0, None])
def test_trace_options_booleans_must_be_booleans(name, value):
    with pytest.raises(WavepathsError, match=f"`{name}` must be True or False"):
        TraceOptions(**{name: value})


@pytest.mark.parametrize("name", BOOLEAN_FIELDS)
def test_trace_options_take_python_and_numpy_booleans(name):
    assert getattr(TraceOptions(**{name: False}), name) is False
    assert not getattr(TraceOptions(**{name: np.bool_(False)}), name)
    assert getattr(TraceOptions(**{name: np.bool_(True)}), name)


@pytest.mark.parametrize("name", ["prune_db", "prune_frequency_hz", "tolerance_db"])
def test_trace_options_numbers_must_be_numbers(name):
    with pytest.raises(WavepathsError, match=f"`{name}` must be a number or None"):
        TraceOptions(**{name: "3"})


def test_trace_options_disable_culling_refuses_a_bare_name():
    with pytest.raises(WavepathsError, match="write {'keller_cone'}"):
        TraceOptions(disable_culling="keller_cone")
    assert TraceOptions(disable_culling=["keller_cone"]).disable_culling == frozenset({"keller_cone"})


@pytest.mark.parametrize("side", ["tx_antenna", "rx_antenna"])
@pytest.mark.parametrize("value", ["dipole", ("iso", "V"), None])
def test_field_config_antennas_must_be_antennas(side, value):
    with pytest.raises(WavepathsError, match=f"`{side}` must be an Antenna"):
        FieldConfig(**{side: value})


def test_field_config_names_the_antenna_to_write():
    with pytest.raises(WavepathsError, match=r"write Antenna\('dipole'\)"):
        FieldConfig(tx_antenna="dipole")
    assert FieldConfig(tx_antenna=Antenna("dipole")).tx_antenna.pattern == "dipole"


def test_field_config_compiled_must_be_a_boolean():
    with pytest.raises(WavepathsError, match="`compiled` must be True or False"):
        FieldConfig(compiled="yes")
    assert FieldConfig(compiled=np.bool_(False)).compiled == np.bool_(False)


# ---- 3. the coordinate limit on coverage grids ------------------------------------------------
@pytest.mark.parametrize("flags, named", [
    (["--height", "1e12", "--cell", "2"], "--height 1e+12 is beyond 1e+09 m"),
    (["--height", "1.5", "--cell", "2", "--center", "2e9", "0"], "--center 2e+09 0 is beyond 1e+09 m"),
    (["--height", "1.5", "--cell", "1e9", "--size", "3e9", "10"], "reaches beyond 1e+09 m"),
])
def test_coverage_refuses_a_grid_beyond_the_coordinate_limit(capsys, tmp_path, flags, named):
    code, _, err = run_cli(capsys, "coverage", "street_canyon", *TX, *flags, "--out", tmp_path, "--quiet")
    assert code == 2 and named in err and "float64" in err
    assert not (tmp_path / "coverage.npz").exists()


def test_coverage_refuses_a_measurement_mesh_beyond_the_limit(capsys, tmp_path):
    mesh = tmp_path / "far.obj"
    mesh.write_text("v 2e9 0 1.5\nv 2e9 1 1.5\nv 2.000000001e9 0 1.5\nf 1 2 3\n")
    code, _, err = run_cli(capsys, "coverage", "street_canyon", *TX, "--mesh", mesh, "--out", tmp_path, "--quiet")
    assert code == 2 and "beyond 1e+09 m" in err and "--mesh" in err


def test_check_grid_reach_accepts_a_grid_within_the_limit():
    check_grid_reach(1.5, np.array([0.0, 0.0]), np.array([200.0, 100.0]))
    check_grid_reach(1.5, np.array([0.9e9, 0.0]), np.array([0.1e9, 10.0]))  # its edge on the limit
    check_grid_reach(float("nan"), np.array([0.0, 0.0]), np.array([1.0, 1.0]))  # left to PlanarGrid


# ---- 4. plurals and directories ----------------------------------------------------------------
def test_plural():
    assert [plural(n, "path") for n in (0, 1, 2)] == ["0 paths", "1 path", "2 paths"]


def test_paths_text_says_one_path(capsys):
    code, out, _ = run_cli(capsys, "paths", "street_canyon", *TX, *RX, *LOS_ONLY)
    assert code == 0 and out.startswith("1 path in street_canyon") and "1 paths" not in out
    code, out, _ = run_cli(capsys, "paths", "street_canyon", *TX, "--tx", 60, 0, 10, *RX, *LOS_ONLY)
    assert code == 0 and "tx 0 -> rx 0: 1 path, path gain" in out and "1 paths" not in out


def test_a_directory_is_not_a_scene(capsys, tmp_path):
    with pytest.raises(SceneError, match="is a directory"):
        load_scene(str(tmp_path))
    code, _, err = run_cli(capsys, "info", tmp_path)
    assert code == 2 and "is a directory" in err and "unknown format" not in err


# ---- 5. free-space materials ---------------------------------------------------------------
def wall_obj(path, material: str):
    path.write_text(f"o wall\nusemtl {material}\nv 0 -10 0\nv 0 10 0\nv 0 10 10\nv 0 -10 10\nf 1 2 3 4\n"
                    "o ground\nusemtl concrete\nv -20 -20 0\nv 20 -20 0\nv 20 20 0\nv -20 20 0\nf 5 6 7 8\n")
    return str(path)


def test_a_vacuum_object_is_named_in_a_warning(tmp_path):
    path = wall_obj(tmp_path / "vacuum.obj", "vacuum")
    with pytest.warns(WavepathsWarning, match=r"object\(s\) wall have a free-space material.*block rays") as rec:
        scene = load_scene(path)
    assert "ground" not in str(rec[0].message) and "no transmission" in str(rec[0].message)
    # the physics is unchanged: the wall still blocks the line of sight
    paths = trace(scene, [[-5, 0, 5]], [[5, 0, 5]], TraceOptions(max_reflections=0, diffraction=False))
    assert len(paths) == 0


def test_a_vacuum_face_reflects_nothing_and_is_not_traced(tmp_path):
    from wavepaths.fields import FieldConfig, compute_fields

    path = wall_obj(tmp_path / "vacuum.obj", "vacuum")
    with pytest.warns(WavepathsWarning, match="free-space material"):
        scene = load_scene(path)
    tx, rx = [[-5.0, -2.0, 5.0]], [[-5.0, 2.0, 5.0]]  # both in front of the wall (x = 0), above the ground
    opts = TraceOptions(max_reflections=1, diffraction=False)
    # the default skips the wall as it skips absorbers: line of sight and the ground's reflection remain
    paths = trace(scene, tx, rx, opts)
    assert len(paths) == 2 and sorted(paths.depth.tolist()) == [0, 1]
    # traced anyway, the wall's reflection is there, with a zero coefficient (permittivity 1)
    every = trace(scene, tx, rx, opts.with_(skip_absorbers=False))
    assert len(every) == 3
    wall = (every.depth == 1) & (np.abs(every.vertices[:, 1, 0]) < 1e-9)
    assert wall.sum() == 1
    a = compute_fields(scene, every.select(wall), FieldConfig(3.5e9)).a
    assert np.all(np.abs(a) == 0.0)


def test_an_air_material_is_named_in_a_warning(tmp_path):
    path = wall_obj(tmp_path / "air.obj", "air")
    with pytest.warns(WavepathsWarning, match=r"wall have a free-space material \(air"):
        load_scene(path, materials={"air": Material("air", "custom", a=1.0, c=0.0)})


def test_solid_materials_give_no_warning(tmp_path):
    load_scene(wall_obj(tmp_path / "brick.obj", "brick"))  # warnings are errors here
    load_scene("street_canyon")


def test_the_coverage_api_refuses_cells_beyond_the_coordinate_limit():
    from wavepaths.coverage import PlanarGrid, coverage

    scene = load_scene("half_plane")
    grid = PlanarGrid(center=[0.0, 0.0], height=1e12, size=[4.0, 4.0], cell_size=2.0)
    with pytest.raises(WavepathsError, match="grid cell centres.*beyond"):
        coverage(scene, [[-10.0, 5.0, -5.0]], grid)


# ---- from a CLI review (thirtieth session) --------------------------------------------------
def test_negative_numbers_with_an_exponent_are_values(capsys):
    """argparse took -1e-6 and -3e9 for options: `--rx 20 -1e-6 1.5` could not be written at all."""
    code, out, err = run_cli(capsys, "paths", "street_canyon", *TX, "--rx", "20", "-1e-6", "1.5", *LOS_ONLY, "--json")
    assert code == 0, err
    assert json.loads(out)["rx"][0] == [20.0, -1e-6, 1.5]
    code, out, err = run_cli(capsys, "paths", "street_canyon", *TX, "--rx", "2e1", "-0.0", "15e-1", *LOS_ONLY,
                             "--json")
    assert code == 0 and json.loads(out)["rx"][0] == [20.0, 0.0, 1.5], err
    code, _, err = run_cli(capsys, "paths", "street_canyon", *TX, *RX, "--frequency", "-3e9")
    assert code == 2 and "frequency" in err and "expected one argument" not in err  # the range error


def test_paths_checks_the_materials_frequency_before_the_search(capsys, monkeypatch):
    import wavepaths.search

    def no_search(*args, **kwargs):
        raise AssertionError("searched before the frequency was checked")

    monkeypatch.setattr(wavepaths.search, "trace", no_search)
    code, _, err = run_cli(capsys, "paths", "street_canyon", *TX, *RX, "--frequency", "28e9")
    assert code == 2 and "outside the valid range of material" in err


def test_a_failed_run_leaves_no_empty_output_folder(capsys, tmp_path):
    new = tmp_path / "new"
    code, _, err = run_cli(capsys, "coverage", "box_on_ground", "--tx", -20, 0, 5, "--height", 1.5, "--cell", 0, "--quiet",
                           "--out", new)
    assert code == 2 and "cell" in err and not new.exists()
    kept = tmp_path / "kept"
    kept.mkdir()
    code, _, _ = run_cli(capsys, "coverage", "box_on_ground", "--tx", -20, 0, 5, "--height", 1.5, "--cell", 0, "--quiet",
                         "--out", kept)
    assert code == 2 and kept.is_dir()  # a folder the user had stays


def test_out_of_memory_is_one_line_and_status_2(capsys, monkeypatch):
    import wavepaths.cli as cli

    def exhausted(args):
        raise MemoryError("Unable to allocate 7.45 GiB")

    monkeypatch.setattr(cli, "_cmd_info", exhausted)
    code, _, err = run_cli(capsys, "info", "street_canyon")
    assert code == 2 and err.count("\n") == 1 and "out of memory" in err and "Traceback" not in err


def test_launched_sampling_has_an_upper_bound():
    from wavepaths.search.options import MAX_LAUNCH_FAN, MAX_LAUNCH_RAYS

    TraceOptions(launch_rays=MAX_LAUNCH_RAYS, launch_fan=MAX_LAUNCH_FAN)
    with pytest.raises(WavepathsError, match="launch_rays"):
        TraceOptions(launch_rays=MAX_LAUNCH_RAYS + 1)
    with pytest.raises(WavepathsError, match="launch_fan"):
        TraceOptions(launch_fan=100_000_000)


def test_gtd_on_a_boundary_is_warned_about():
    """The README's receiver lies exactly on a reflection boundary of two R-D paths: Keller's
    coefficient diverges there (+51 dB each), the UTD does not."""
    from wavepaths.fields import compute_fields

    scene = load_scene("street_canyon")
    paths = trace(scene, np.array([[-60.0, 0, 10]]), np.array([[20.0, 0, 1.5]]), TraceOptions())
    with pytest.warns(WavepathsWarning, match="GTD diverges"):
        gtd = compute_fields(scene, paths, FieldConfig(model="gtd"))
    assert gtd.path_gain_db().max() > 0  # the divergence the warning is about
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        utd = compute_fields(scene, paths, FieldConfig())
    assert utd.path_gain_db().max() < -60


def test_bench_refuses_an_empty_list_of_benchmarks(capsys, tmp_path):
    """`--only ""` used to start the full suite."""
    code, _, err = run_cli(capsys, "bench", "--out", tmp_path / "b", "--only", "")
    assert code == 2 and "unknown benchmark" in err and not (tmp_path / "b").exists()


def test_flags_that_do_nothing_are_warned_about(capsys):
    """A CLI review found --tolerance-db with --no-diffraction, --launch-fan without launched
    candidates and a search of nothing all accepted in silence."""
    code, _, err = run_cli(capsys, "paths", "street_canyon", *TX, *RX, "--no-diffraction", "--diffraction-reflections",
                           0, "--launch-fan", 512, "--max-reflections", 0)
    assert code == 0
    assert "ignored: --diffraction-reflections (with --no-diffraction)" in err
    assert "--launch-fan (without --diffraction-candidates launched)" in err
    code, _, err = run_cli(capsys, "paths", "street_canyon", *TX, *RX, "--no-los", "--no-diffraction",
                           "--max-reflections", 0)
    assert code == 0 and "leave nothing to search" in err
    code, _, err = run_cli(capsys, "paths", "street_canyon", *TX, *RX, *LOS_ONLY)
    assert code == 0 and "warning" not in err  # the usual flags: no word


def test_a_cell_larger_than_the_area_is_refused(capsys, tmp_path):
    code, _, err = run_cli(capsys, "coverage", "box_on_ground", "--tx", -20, 0, 5, "--height", 1.5, "--cell", 1e300,
                           "--quiet", "--out", tmp_path / "c")
    assert code == 2 and "larger than the area" in err and not (tmp_path / "c").exists()


def test_cli_errors_name_the_flags_not_the_api(capsys, tmp_path):
    """A review found `cell_size` in the error where the user had typed --cell."""
    code, _, err = run_cli(capsys, "coverage", "box_on_ground", "--tx", -20, 0, 5, "--height", 1.5, "--cell", 0,
                           "--quiet", "--out", tmp_path / "c")
    assert code == 2 and "--cell must be positive" in err and "cell_size" not in err
    code, _, err = run_cli(capsys, "paths", "street_canyon", *TX, *RX, "--launch-fan", 2)
    assert code == 2 and "--launch-fan must be in" in err
    code, _, err = run_cli(capsys, "paths", "street_canyon", *TX, *RX, "--frequency", 2e13)
    assert code == 2 and "--frequency must be in" in err


def test_a_tolerance_on_a_coherent_map_is_warned_about(capsys, tmp_path):
    """The tolerance's bound is on the power sum; a review measured the coherent example map
    moving by 8 dB in a cell at 0.1 dB."""
    args = ["coverage", "box_on_ground", "--tx", -20, 0, 5, "--height", 1.5, "--cell", 10, "--max-reflections", 1,
            "--tolerance-db", 0.1, "--workers", 1, "--quiet"]
    code, _, err = run_cli(capsys, *args, "--out", tmp_path / "a")
    assert code == 0 and "bounds the power sum (--incoherent)" in err
    code, _, err = run_cli(capsys, *args, "--incoherent", "--out", tmp_path / "b")
    assert code == 0 and "bounds the power sum" not in err
