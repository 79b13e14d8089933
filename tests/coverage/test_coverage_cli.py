"""The installed ``wavepaths coverage`` console script."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np

WAVEPATHS = os.path.join(os.path.dirname(sys.executable), "wavepaths")


def run(*args):
    return subprocess.run([WAVEPATHS, "coverage", *map(str, args)], capture_output=True, text=True, timeout=300)


def test_cli_writes_png_and_npz(tmp_path):
    r = run("box_on_ground", "--tx", -14.2, -8.1, 7, "--height", 5, "--cell", 2, "--size", 30, 20, "--center", 0.3, 0.3,
            "--max-reflections", 1, "--out", tmp_path, "--workers", 1, "--quiet")
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    assert (tmp_path / "coverage.png").stat().st_size > 1000
    with np.load(tmp_path / "coverage.npz", allow_pickle=False) as data:
        gain, centres = data["path_gain_db"], data["cell_centers"]
        assert gain.shape == (10, 15) and centres.shape == (10, 15, 3)
        inside = (np.abs(centres[..., 0]) < 5) & (np.abs(centres[..., 1]) < 5)
        np.testing.assert_array_equal(np.isnan(gain), inside)
        np.testing.assert_allclose(centres[..., 2], 5.0)
    assert "cells/s" in r.stdout
    assert "replacing" not in r.stdout


def test_a_second_map_in_the_same_folder_says_which_files_it_replaced(tmp_path):
    """The default --out is the current folder: a second run there replaces the first run's
    map, and says so (in the text and in --json's ``replaced``); a first run replaces nothing."""
    import json

    args = ("box_on_ground", "--tx", -14.2, -8.1, 7, "--height", 5, "--cell", 4, "--size", 30, 20, "--max-reflections", 0,
            "--out", tmp_path, "--workers", 1, "--quiet", "--json")
    first = json.loads(run(*args).stdout)
    assert first["replaced"] == []
    second = run(*args)
    assert second.returncode == 0, second.stderr
    got = json.loads(second.stdout)
    assert sorted(map(os.path.basename, got["replaced"])) == ["coverage.npz", "coverage.png"]
    text = run(*args[:-1])
    assert "replacing the earlier coverage.npz and coverage.png" in text.stdout


def test_cli_bad_input_exits_2_without_traceback(tmp_path):
    for args in (["--tx", "nan", 0, 1, "--height", 5, "--cell", 2],
                 ["--tx", 0, 0, 20, "--height", 5, "--cell", 0],
                 ["--tx", 0, 0, 20, "--cell", 2],
                 ["--tx", 0, 0, 5, "--height", 5, "--cell", 2]):
        r = run("box_on_ground", *args, "--out", tmp_path, "--workers", 1, "--quiet")
        assert r.returncode == 2, (args, r.stderr)
        assert "Traceback" not in r.stderr and "wavepaths coverage: error:" in r.stderr


def test_an_output_folder_that_cannot_be_one_is_refused_before_any_work(tmp_path):
    """--out naming an existing file, or a path under one: exit 2 with one line, before the
    map is traced (it used to raise FileExistsError after the whole map); a cell far too small
    for the grid: exit 2 (it silently became a 1 x 1 map)."""
    f = tmp_path / "a_file"
    f.write_text("")
    for out in (f, f / "below"):
        r = run("street_canyon", "--tx", 0, 0, 10, "--height", 1.5, "--cell", 4, "--size", 40, 16, "--out", out,
                "--workers", 1, "--quiet")
        assert r.returncode == 2, r.stderr
        assert "Traceback" not in r.stderr and "cannot be used as an output folder" in r.stderr
    r = run("street_canyon", "--tx", -60, 0, 10, "--height", 1.5, "--cell", 1e-20, "--out", tmp_path / "m",
            "--workers", 1, "--quiet")
    assert r.returncode == 2 and "too small" in r.stderr and "Traceback" not in r.stderr
