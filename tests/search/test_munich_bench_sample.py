"""``run_munich`` runs the full map only when the sample (context and one tile) says it can fit."""

from __future__ import annotations

from wavepaths.bench import munich


def test_hopeless_sample_skips_the_full_map(monkeypatch, tmp_path):
    calls = []

    def fake_run_isolated(module, name, kwargs, timeout_s, memory_limit_bytes):
        calls.append((name, kwargs.get("options")))
        return {"ok": True, "wall_s": 1.0, "result": {"extrapolated_map_s": 1e6, "context_s": 5.0, "tile_s": 9.0}}

    monkeypatch.setattr(munich, "run_isolated", fake_run_isolated)
    monkeypatch.setattr("wavepaths.validation.sionna_env.sionna_version", lambda: "0")
    out = munich.run_munich(str(tmp_path), timeout_s=100.0, progress=lambda m: None)
    # the launched sample, the target sample, then the probe's sample (no launched one)
    assert [c[0] for c in calls] == ["munich_sample"] * 3
    assert calls[0][1] == munich.LAUNCHED_OPTIONS and calls[1][1] is None
    assert calls[2][1] == {"max_reflections": 1, "diffraction": True, "diffraction_reflections": 0}
    assert out["launched"]["options"] == munich.LAUNCHED_OPTIONS
    assert out["meets_target"] is False and "full_map_skipped" in out
    assert out["sample"]["extrapolated_map_s"] == 1e6
    assert out["probe"]["full_map_skipped"]


def test_promising_sample_runs_the_full_map(monkeypatch, tmp_path):
    calls = []

    def fake_run_isolated(module, name, kwargs, timeout_s, memory_limit_bytes):
        calls.append(name)
        if name == "munich_sample":
            return {"ok": True, "wall_s": 1.0, "result": {"extrapolated_map_s": 50.0}}
        return {"ok": True, "wall_s": 60.0, "max_rss_bytes": 1 << 30,
                "result": {"load_s": 5.0, "map_s": 50.0, "total_s": 55.0}}

    monkeypatch.setattr(munich, "run_isolated", fake_run_isolated)
    monkeypatch.setattr("wavepaths.validation.sionna_env.sionna_version", lambda: "0")
    out = munich.run_munich(str(tmp_path), timeout_s=100.0, progress=lambda m: None, launched_sample=False)
    assert calls == ["munich_sample", "munich_map"]
    assert out["finished"] and out["meets_target"] and out["sample"]["extrapolated_map_s"] == 50.0
