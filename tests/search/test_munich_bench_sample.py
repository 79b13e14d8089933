"""``run_munich`` runs the map with launched candidates and checks it against the exhaustive
search on random cells; it runs the exhaustive map only when its sample (context and one
tile) says it can fit."""

from __future__ import annotations

import os

from wavepaths.bench import munich
from wavepaths.bench.isolated import group_rss_bytes


def _fake(calls, launched_total_s=300.0, group_rss=6 << 30, exhaustive_estimate=1e6):
    def fake_run_isolated(module, name, kwargs, timeout_s, memory_limit_bytes):
        calls.append((name, kwargs.get("options")))
        if name == "munich_map" and kwargs.get("options") == munich.LAUNCHED_OPTIONS:
            return {"ok": True, "wall_s": launched_total_s, "max_rss_bytes": 3 << 30, "max_group_rss_bytes": group_rss,
                    "result": {"load_s": 5.0, "map_s": launched_total_s - 5.0, "total_s": launched_total_s}}
        if name == "munich_map":
            return {"ok": True, "wall_s": 60.0, "max_rss_bytes": 1 << 30, "max_group_rss_bytes": 1 << 30,
                    "result": {"load_s": 5.0, "map_s": 50.0, "total_s": 55.0}}
        if name == "munich_check":
            return {"ok": True, "wall_s": 9.0, "result": {"cells": kwargs["cells"], "missed": 1, "extra": 0}}
        return {"ok": True, "wall_s": 1.0, "result": {"extrapolated_map_s": exhaustive_estimate, "context_s": 5.0,
                                                       "tile_s": 9.0}}

    return fake_run_isolated


def test_hopeless_sample_skips_the_full_map(monkeypatch, tmp_path):
    calls = []
    monkeypatch.setattr(munich, "run_isolated", _fake(calls))
    monkeypatch.setattr("wavepaths.validation.sionna_env.sionna_version", lambda: "0")
    out = munich.run_munich(str(tmp_path), timeout_s=1000.0, progress=lambda m: None)
    # the launched map and its check, the target sample, then the probe's sample
    assert [c[0] for c in calls] == ["munich_map", "munich_check", "munich_sample", "munich_sample"]
    assert calls[0][1] == munich.LAUNCHED_OPTIONS and calls[2][1] is None
    assert calls[3][1] == {"max_reflections": 1, "diffraction": True, "diffraction_reflections": 0}
    assert out["launched"]["options"] == munich.LAUNCHED_OPTIONS
    assert out["launched"]["meets_target"] is True and out["launched"]["check"]["cells"] == 32
    assert out["meets_target"] is False and "full_map_skipped" in out
    assert out["sample"]["extrapolated_map_s"] == 1e6
    assert out["probe"]["full_map_skipped"]


def test_the_launched_map_misses_the_target_on_time_or_on_summed_memory(monkeypatch, tmp_path):
    monkeypatch.setattr("wavepaths.validation.sionna_env.sionna_version", lambda: "0")
    for total, rss in ((700.0, 6 << 30), (300.0, 9 << 30)):
        calls = []
        monkeypatch.setattr(munich, "run_isolated", _fake(calls, launched_total_s=total, group_rss=rss))
        out = munich.run_munich(str(tmp_path), timeout_s=1000.0, progress=lambda m: None, sample_first=False,
                                probe=False, check_cells=0)
        assert [c[0] for c in calls] == ["munich_map", "munich_map"]
        assert out["launched"]["meets_target"] is False


def test_promising_sample_runs_the_full_map(monkeypatch, tmp_path):
    calls = []
    monkeypatch.setattr(munich, "run_isolated", _fake(calls, exhaustive_estimate=50.0))
    monkeypatch.setattr("wavepaths.validation.sionna_env.sionna_version", lambda: "0")
    out = munich.run_munich(str(tmp_path), timeout_s=100.0, progress=lambda m: None, launched=False)
    assert [c[0] for c in calls] == ["munich_sample", "munich_map"]
    assert out["finished"] and out["meets_target"] and out["sample"]["extrapolated_map_s"] == 50.0


def test_group_memory_counts_this_process():
    """The process group's summed resident memory holds at least this process's."""
    with open("/proc/self/statm") as f:
        mine = int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    assert group_rss_bytes(os.getpgrp()) >= 0.9 * mine > 0
