"""Smoke test of the benchmark package: tiny sizes, no timings checked.

Checks that benchmark 1 runs, that the closed form and every numerical search find the
same diffraction points (to 1e-9 m) and the same on-edge verdicts, and that
``run_bench`` writes ``bench.json`` with the headline keys.
"""

import json

import numpy as np
import pytest

from wavepaths.bench.point_search import (
    closed_form,
    closed_form_scalar,
    newton_3d,
    newton_reduced,
    newton_scalar,
    random_instances,
    run_point_search,
)
from wavepaths.bench.report import run_bench


def test_closed_form_and_numerical_search_agree():
    inst = random_instances(500, seed=3)
    t, on = closed_form(inst)
    assert 0.2 < on.mean() < 0.9
    for search in (newton_3d, newton_reduced):
        tn, onn, _ = search(inst)
        assert (onn == on).all()
        assert np.abs(tn[on] - t[on]).max() < 1e-9
    for i in range(50):
        args = (inst.e[i], inst.r[i], inst.origin[i], inst.direction[i], inst.length[i])
        ts, ons = closed_form_scalar(*args)
        assert ons == on[i]
        if ons:
            assert abs(ts - t[i]) < 1e-9
            assert abs(newton_scalar(*args)[0] - t[i]) < 1e-9


def test_point_search_benchmark_figures():
    r = run_point_search(n_pairs=200, repeats=2, rounds=2, numerical_repeats=2, scalar_pairs=20)
    for key in ("point_search_ns", "point_search_speedup", "point_search_max_point_distance_m", "methods"):
        assert key in r
    # the Newton searches stop at a 1e-11 m step; golden section locates the flat minimum only to
    # about sqrt(eps) of the scale. Which one is fastest on 200 pairs is the timing's noise, so the
    # headline distance is held to the loosest of the three
    for name, tol in (("newton", 1e-9), ("newton_reduced", 1e-9), ("golden", 1e-5)):
        agreement = r["methods"][name]["agreement_with_closed_form"]
        assert agreement["max_point_distance_m"] < tol and agreement["on_edge_disagreements"] == 0, name
    assert r["point_search_max_point_distance_m"] < 1e-5
    assert r["point_search_ns"] > 0 and r["point_search_speedup"] > 0


def test_the_compiled_searches_find_the_numpy_searches_points():
    """Benchmark 1's compiled pair (numba) solves the same pairs as the numpy versions: the
    closed form to 1e-12 m, the Newton search to its 1e-11 m stopping step, the same
    on-edge verdicts, and the benchmark reports their ratio."""
    pytest.importorskip("numba")
    from wavepaths.bench.point_search_compiled import run_compiled

    inst = random_instances(2_000, seed=5)
    t, on = closed_form(inst)
    tn_np, on_np, _ = newton_reduced(inst)
    (t_c, on_c), (t_n, on_n, iters) = run_compiled(inst)
    assert (on_c == on).all() and (on_n == on).all() and (on_np == on).all()
    assert np.abs(t_c[on] - t[on]).max() < 1e-12
    assert np.abs(t_n[on] - t[on]).max() < 2e-11 and iters > 3
    assert np.abs(t_n[on] - tn_np[on]).max() < 2e-11
    r = run_point_search(n_pairs=200, repeats=2, rounds=2, numerical_repeats=2, scalar_pairs=20)
    both = r["both_compiled"]
    assert both["newton_agreement_with_closed_form"]["on_edge_disagreements"] == 0
    assert r["point_search_speedup_compiled"] == both["speedup"] > 0


def test_scaling_fit_separates_the_fixed_cost_from_the_linear_part():
    """A fixed cost plus a linear part is recovered exactly, where one power law over it reads
    low; the local exponent of a power law is its exponent; missing points are skipped."""
    from wavepaths.bench.scaling import fixed_plus_linear, log_slope

    n = [10, 30, 100, 300, 1000, 3000]
    t = [0.01 + 5e-5 * x for x in n]
    fit = fixed_plus_linear(n, t)
    assert fit["fixed_s"] == pytest.approx(0.01, rel=1e-9) and fit["per_item_s"] == pytest.approx(5e-5, rel=1e-9)
    assert log_slope(n, t) < 0.6 < fit["local_exponent"] < 1.0
    assert fixed_plus_linear(n, [2.0 * x**1.3 for x in n])["local_exponent"] == pytest.approx(1.3, rel=1e-12)
    assert fixed_plus_linear([10, 20, 30], [None, 1.0, None]) is None


def test_run_bench_writes_json(tmp_path):
    summary = run_bench(str(tmp_path), quick=True, only=["point_search"], profile=False, progress=lambda m: None)
    data = json.loads((tmp_path / "bench.json").read_text())
    for key in ("point_search_ns", "point_search_speedup", "sionna_paths_time_ratio", "diffraction_cost_ratio",
                "tradeoff_points", "machine", "targets"):
        assert key in data
    assert (tmp_path / "index.html").exists()
    assert summary["headline"]["point_search_ns"] == data["point_search_ns"]


def test_console_script_has_bench():
    import os
    import shutil
    import subprocess
    import sys

    # the script installed beside this interpreter (the venv's bin), else the one on PATH
    exe = os.path.join(os.path.dirname(sys.executable), "wavepaths")
    exe = exe if os.path.exists(exe) else shutil.which("wavepaths")
    assert exe is not None, "the wavepaths console script is not installed (pip install -e .)"
    out = subprocess.run([exe, "bench", "--help"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0
    assert "--quick" in out.stdout and "--munich" in out.stdout


def test_large_gain_differences_are_counted_by_reason_and_band():
    """Benchmark 2's agreement sorts matched pairs more than 6 dB apart by known reason; a
    depth-3 D-R goes to Sionna's known depth dependence only where Sionna's depth-2 coefficient
    of that path agrees with wavepaths' (checked path by path; it labelled every such D-R before,
    which could hide a real D-R error: found by a review), a reflection (no edge to blame) is
    unexplained, and pairs within 6 dB are not counted."""
    from types import SimpleNamespace

    from wavepaths.bench.sionna_paths import _large_gain_differences
    from wavepaths.scene import load_scene
    from wavepaths.validation.compare import Match

    def match(kinds, diff, i):
        return Match(0, i, kinds, i, i, 0.0, 0.0, diff, 0.0)

    comp = SimpleNamespace(matches=[match("D-R", 7.5, 0), match("R", 25.0, 1), match("R-R", 9.0, 2),
                                    match("R", 3.0, 3), match("LOS", float("nan"), 4), match("D-R", 30.0, 5),
                                    match("D-R", 8.0, 6)])
    scene = load_scene("street_canyon")
    # the wavepaths paths behind the matches: the D-R ones diffract on an edge of one object
    kinds = {"D-R": [2, 1], "R": [1, 0], "R-R": [1, 1], "LOS": [0, 0]}
    edge = next(d for d in range(len(scene.dihedra)) if scene.dihedra.diffracting[d])
    paths = SimpleNamespace(interactions=np.array([kinds[m.kinds] for m in comp.matches], np.int8),
                            primitive=np.array([[edge, 0] for _ in comp.matches], np.int64),
                            depth=np.array([len(m.kinds.split("-")) if m.kinds != "LOS" else 0 for m in comp.matches]))
    # at depth 2 Sionna agrees on path 0 (0.3 dB) and path 5 (2 dB), not on path 6 (8 dB)
    out = _large_gain_differences(scene, paths, None, None, comp, depth2={0: 0.3, 5: -2.0, 6: 8.0})
    assert out["by_reason"] == {"sionna-dr-depends-on-max-depth": {"6-20 dB": 1, "> 20 dB": 1},
                                "unexplained": {"6-20 dB": 2, "> 20 dB": 1}}
    assert [e["rx"] for e in out["unexplained_examples"]] == [1, 2, 6]
    # a path Sionna's depth-2 run did not find stays unchecked, not unexplained
    out = _large_gain_differences(scene, paths, None, None, comp, depth2={0: 0.3, 5: -2.0})
    assert out["by_reason"]["sionna-dr-depends-on-max-depth-not-checked"] == {"6-20 dB": 1, "> 20 dB": 0}
    # without the depth-2 run the class label says it was not checked
    out = _large_gain_differences(scene, paths, None, None, comp)
    assert out["by_reason"]["sionna-dr-depends-on-max-depth-not-checked"] == {"6-20 dB": 2, "> 20 dB": 1}


def test_diffraction_cost_benchmark_reports_per_path_costs(monkeypatch):
    """Benchmark 5 (quick): diffraction adds paths and removes none (the same line-of-sight
    and reflected paths in every cell), and the time ratio splits into the paths ratio and
    the per-path costs: t_on / t_off = 1 + (us per diffracted path x diffracted paths) /
    (us per path off x paths off). Its one-thread maps run numba's kernels on one thread too."""
    import sys

    from wavepaths.bench.diffraction_cost import run_diffraction_cost
    from wavepaths.search import kernels

    cov = sys.modules["wavepaths.coverage"]  # (the package's name is also its function's)
    seen = []
    real = cov.coverage

    def recording(*args, **kwargs):
        seen.append((kwargs["settings"].threads, kernels.threads()))
        return real(*args, **kwargs)

    monkeypatch.setattr(cov, "coverage", recording)
    r = run_diffraction_cost(quick=True, progress=lambda m: None)
    assert any(t == 1 for t, _ in seen) and all(k == 1 for t, k in seen if t == 1)
    # the headline pair on the default threads, then on one thread (with more than one core)
    assert r["pairs"][0]["threads"] == r["threads"]
    if r["threads"] > 1:
        one = r["pairs"][1]
        assert (one["on"], one["threads"]) == ("R2+D1", 1)
        assert r["diffraction_cost_ratio_one_thread"] == one["ratio"]
        # the same maps whatever the threads
        assert one["diffracted_paths"] == r["pairs"][0]["diffracted_paths"]
        assert one["all_paths"] == r["pairs"][0]["all_paths"]
    p = r["pairs"][0]
    assert p["same_geometrical_optics_paths"]
    assert p["diffracted_paths"] > 0 and p["paths_ratio"] > 1
    off_paths = p["all_paths"] - p["diffracted_paths"]
    rebuilt = 1 + p["us_per_diffracted_path"] * p["diffracted_paths"] / (p["us_per_path_off"] * off_paths)
    assert abs(rebuilt - p["ratio"]) < 1e-9 * p["ratio"]
    # the stages of the headline pair: disjoint, within the total; the diffraction stages
    # are empty without diffraction and take time with it (their share of the added time is
    # a timing, which a loaded host moves: it is reported by the benchmark, not asserted here;
    # a CI run with helpers beside it measured 39 % where a quiet one gives over 40 %)
    st = {row["stage"]: row for row in r["stages"]}
    parts = [k for k in st if k not in ("other", "total")]
    for key in ("off_s", "on_s"):
        assert all(st[k][key] >= 0 for k in st)
        assert sum(st[k][key] for k in parts) + st["other"][key] == pytest.approx(st["total"][key], rel=1e-9)
    diff = [k for k in parts if k.startswith("diffraction") or k.startswith("receivers'")]
    assert len(diff) == 4 and all(st[k]["off_s"] == 0 for k in diff)
    assert all(st[k]["on_s"] >= 0 for k in diff) and sum(st[k]["on_s"] for k in diff) > 0
    # the floor: trace() on the map's traced cells finds the map's diffracted paths, every leg
    # of them clear (one leg per segment of each path); the floor lies above 1 (the fields and
    # casts take time; no timing is compared here)
    fl = r["floor"]
    assert fl["diffracted_paths"] == fl["map_diffracted_paths"] == p["diffracted_paths"]
    assert fl["legs_blocked"] == 0 and fl["legs"] >= 2 * fl["diffracted_paths"]
    assert 1 < fl["floor_one_thread"] and 1 < fl["floor_threads_ideal"]
    assert fl["ns_per_path_fields"] > 0 and fl["ns_per_leg_cast"] > 0


def test_every_path_query_setting_of_the_tradeoff_sweep_is_accepted_by_trace():
    """Benchmark 3's path half runs trace() on each of its settings; the map-only ones
    (tolerance_db) are left to the map half, which runs them all."""
    import numpy as np

    from wavepaths import load_scene, trace
    from wavepaths.bench.tradeoff import WAVEPATHS_SETTINGS, path_query_settings, trace_options

    scene = load_scene("street_canyon")
    chosen = path_query_settings()
    assert any("tolerance_db" in (x[4] if len(x) > 4 else {}) for x in WAVEPATHS_SETTINGS)
    assert chosen and not any("tolerance_db" in (x[4] if len(x) > 4 else {}) for x in chosen)
    assert chosen[-1] == WAVEPATHS_SETTINGS[-1]  # the reference is a path setting
    for setting in chosen:
        trace(scene, np.array([[-60.0, 0.0, 10.0]]), np.array([[20.0, 2.0, 1.5]]), trace_options(setting))


def test_interleaved_rounds_turn_the_order_so_each_contender_runs_in_each_place():
    from wavepaths.bench.timing import interleaved

    calls: list[str] = []
    contenders = {name: (lambda n=name: calls.append(n)) for name in "abc"}
    times = interleaved(contenders, 3)
    assert all(len(times[n].times_s) == 3 for n in "abc")
    rounds = [calls[i : i + 3] for i in range(0, 9, 3)]
    assert sorted(rounds[0]) == sorted(rounds[1]) == sorted(rounds[2]) == ["a", "b", "c"]
    # every contender has been first, second and third once
    for n in "abc":
        assert sorted(r.index(n) for r in rounds) == [0, 1, 2]


def test_launch_completeness_benchmark_counts_found_sequences_and_power():
    """The launched-candidates benchmark on the street canyon, 8 receivers, one fan density:
    its counts add up (per order, found <= paths; the totals are their sums), and at 256
    directions per turn it finds every sequence there (the street-canyon test of
    ``search.launch`` asserts the same on other receivers)."""
    from wavepaths.bench.launch import launch_completeness
    from wavepaths.bench.scenes import STREET_CANYON_TX

    out = launch_completeness("simple_street_canyon", STREET_CANYON_TX, cells=8, fans=(256,), progress=lambda m: None)
    row = out["fans"][0]
    assert out["diffracted_paths"] > 50
    assert sum(v["paths"] for v in row["per_order"].values()) == out["diffracted_paths"]
    assert sum(v["found"] for v in row["per_order"].values()) == row["found"]
    assert row["found"] + len(row["missed"]) == out["diffracted_paths"]
    assert row["found"] == out["diffracted_paths"] and row["power_fraction"] == 1.0
    assert 0 < row["candidates_per_receiver"] < out["exhaustive_candidates_per_receiver"]


def test_occlusion_rates_compare_the_casters_and_the_rule():
    """Benchmark 4's occlusion figures: the Embree forms agree with each other, and the float64
    tree gives the float64 rule's verdict on every segment (no timing compared)."""
    from wavepaths.bench.scaling import occlusion_rates
    from wavepaths.bench.scenes import sionna_scene_xml
    from wavepaths.search import kernels

    r = occlusion_rates(sionna_scene_xml("simple_street_canyon"), n=3000, rounds=1)
    assert set(r["ns_per_segment"]) >= {"numpy"}
    assert 0.05 < r["blocked_fraction"] < 0.95
    if kernels.available():
        assert set(r["ns_per_segment"]) == {"numpy", "compiled", "float64 tree"}
        assert r["same_verdicts"] and r["tree_matches_rule"]
        assert r["embree_misses_of_rule"] >= 0


def test_the_tradeoff_verdict_is_also_taken_against_each_engines_own_limit():
    """The common reference is wavepaths' own converged answer (error 0 by construction): a
    review asked for the verdict with each engine against its own limit beside it. Sionna's
    largest run has no error against itself and is left out of that verdict."""
    from wavepaths.bench.tradeoff import _dominates

    wp = [{"label": "R3", "time_s": 0.01, "error": {"mean_abs_db": 2.0}},
          {"label": "R3+D2", "time_s": 0.05, "error": {"mean_abs_db": 0.0}}]
    sn = [{"label": "1e4", "time_s": 0.02, "error": {"mean_abs_db": 3.0}, "error_vs_own_limit": {"mean_abs_db": 1.0}},
          {"label": "1e6", "time_s": 0.5, "error": {"mean_abs_db": 1.2}, "error_vs_own_limit": {"mean_abs_db": 0.1}},
          {"label": "1e8", "time_s": 10.0, "error": {"mean_abs_db": 1.1}, "error_vs_own_limit": None}]
    common = _dominates(wp, sn)
    assert common["every_sionna_point_beaten"] and len(common["rows"]) == 3
    own = _dominates(wp, sn, "error_vs_own_limit")
    assert [r["sionna"] for r in own["rows"]] == ["1e4", "1e6"]
    assert [r["wavepaths_better"] for r in own["rows"]] == [False, True]  # 2.0 dB within 0.02 s against 1.0 dB
    assert not own["every_sionna_point_beaten"]
