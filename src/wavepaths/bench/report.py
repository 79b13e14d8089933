"""``wavepaths bench``: run the benchmarks, write ``bench.json`` and an HTML page with plots.

The page and the JSON carry the machine (CPU, cores, load average before and after),
the versions (wavepaths, numpy, scipy, embreex, Sionna RT, Mitsuba, Dr.Jit), each
benchmark's figures and the targets of issue #7 beside them. ``bench.json`` has the
headline keys at its top level: ``point_search_ns``, ``point_search_speedup``,
``sionna_paths_time_ratio``, ``diffraction_cost_ratio`` and ``tradeoff_points`` (the
error-against-time points of benchmark 3).

This module is the runner: :func:`run_bench` runs the benchmarks of :data:`BENCHMARKS`
one by one, writing ``bench.json`` and ``index.html`` after each, and profiles the work
behind every missed target (:func:`profile_call`). The report's parts live beside it and
are re-exported here under their old names:

* :mod:`wavepaths.bench.summary`: :func:`machine_info` and :func:`headline` (the top-level
  figures and the targets);
* :mod:`wavepaths.bench.figures`: the plots, :func:`make_figures`;
* :mod:`wavepaths.bench.page`: the HTML page, :func:`write_html` and :func:`render`.
"""

from __future__ import annotations

import io
import json
import os
import time

from .figures import make_figures
from .page import render, write_html
from .summary import _json_default, headline, machine_info
from .timing import load_average

__all__ = [
    "BENCHMARKS",
    "headline",
    "machine_info",
    "make_figures",
    "profile_call",
    "render",
    "run_bench",
    "write_html",
]

BENCHMARKS = ("point_search", "sionna_paths", "tradeoff", "scaling", "diffraction_cost", "skips")


# ---- the runner --------------------------------------------------------------------------
def profile_call(fn, top: int = 25) -> str:
    """Function-level cProfile of ``fn()`` (cumulative and own time), as text."""
    import cProfile
    import pstats

    pr = cProfile.Profile()
    pr.enable()
    fn()
    pr.disable()
    buf = io.StringIO()
    st = pstats.Stats(pr, stream=buf)
    st.sort_stats("cumulative").print_stats(top)
    st.sort_stats("tottime").print_stats(15)
    text = buf.getvalue()
    root = os.path.dirname(os.path.dirname(os.path.dirname(__file__)))
    return text.replace(root + os.sep, "")


def run_bench(out_dir: str, quick: bool = False, only: list[str] | None = None, munich: bool = False,
              profile: bool = True, command: str = "wavepaths bench", progress=print) -> dict:
    """Run the benchmarks and write ``out_dir/bench.json`` and ``out_dir/index.html``."""
    os.makedirs(out_dir, exist_ok=True)
    t0 = time.perf_counter()
    load_before = load_average()
    names = only or list(BENCHMARKS)
    results: dict = {}
    figures: dict = {}

    def save():
        """Write what is done so far (a run stopped later keeps its finished benchmarks)."""
        figures.clear()
        figures.update(make_figures(results))
        summary = _summary()
        with open(os.path.join(out_dir, "bench.json"), "w") as f:
            json.dump({k: v for k, v in summary.items() if k != "figures"}, f, indent=1, default=_json_default)
        write_html(summary, os.path.join(out_dir, "index.html"))
        return summary

    def _summary():
        return {"date": time.strftime("%Y-%m-%d %H:%M:%S %Z"), "quick": quick, "command": command,
                "elapsed_s": time.perf_counter() - t0, "load_before": load_before, "load_after": load_average(),
                "machine": machine_info(), **headline(results), "headline": headline(results),
                "results": results, "figures": figures, "profiles": profiles}

    profiles: dict = {}
    if "point_search" in names:
        from .point_search import run_point_search, variant_timings

        progress("benchmark 1: diffraction point search")
        ps = run_point_search(repeats=100 if quick else 1000, rounds=5 if quick else 10,
                              numerical_repeats=20 if quick else 100)
        ps["variants"] = variant_timings(repeats=50 if quick else 300)
        results["point_search"] = ps
        save()
    if "sionna_paths" in names:
        from .sionna_paths import run_sionna_paths_bench

        sp = run_sionna_paths_bench(out_dir, quick=quick, progress=progress)
        results["sionna_paths"] = sp
        save()
    if "tradeoff" in names:
        from .tradeoff import run_tradeoff

        to = run_tradeoff(quick=quick, progress=progress)
        results["tradeoff"] = to
        save()
    if "scaling" in names:
        from .scaling import run_scaling

        sc = run_scaling(out_dir, quick=quick, timeout_s=120 if quick else 600, progress=progress)
        results["scaling"] = sc
        save()
    if "diffraction_cost" in names:
        from .diffraction_cost import run_diffraction_cost

        dc = run_diffraction_cost(quick=quick, progress=progress)
        results["diffraction_cost"] = dc
        save()
    if "skips" in names:
        from .skips import run_skips

        results["skips"] = run_skips(quick=quick, progress=progress)
        save()
    if munich:
        from .munich import run_munich

        results["munich"] = run_munich(out_dir, progress=progress)
        save()
    if profile:
        profiles.update(_profiles(results, quick, progress))
    return save()


def _profiles(results: dict, quick: bool, progress) -> dict:
    """cProfile of the work behind each missed target (so that it can be optimised)."""
    head = headline(results)["targets"]
    out = {}
    if head.get("point_search_ns <= 50") is False:
        from .point_search import closed_form, random_instances

        inst = random_instances(10_000)
        out["point search (engine kernel, 10,000 pairs x 200)"] = profile_call(
            lambda: [closed_form(inst) for _ in range(200)], top=12)
    if head.get("sionna_paths_time_ratio >= 20") is False:
        from ..fields import FieldConfig, compute_fields
        from ..scene import load_scene
        from ..search import TraceOptions, trace
        from .scenes import STREET_CANYON_TX, sionna_scene_xml, street_canyon_receivers

        progress("profiling the street-canyon path query")
        scene = load_scene(sionna_scene_xml("simple_street_canyon"))
        rx = street_canyon_receivers(100)
        opts = TraceOptions(max_reflections=3, diffraction=True, diffraction_reflections=2)
        trace(scene, STREET_CANYON_TX, rx, opts)
        out["path query, simple_street_canyon, 100 rx, R3+D2 (trace + fields)"] = profile_call(
            lambda: compute_fields(scene, trace(scene, STREET_CANYON_TX, rx, opts), FieldConfig(3.5e9, "utd", "sionna")))
    if head.get("diffraction_cost_ratio <= 3") is False:
        from ..coverage import CoverageOptions, PlanarGrid, coverage
        from ..scene import load_scene
        from ..search import TraceOptions
        from .scenes import STREET_CANYON_TX, sionna_scene_xml

        progress("profiling the R2+D1 coverage map")
        scene = load_scene(sionna_scene_xml("simple_street_canyon"))
        grid = PlanarGrid(center=[0.0, 0.0], height=1.5, size=[176.0, 120.0], cell_size=4.0 if quick else 2.0)
        out["coverage map R2+D1, simple_street_canyon"] = profile_call(
            lambda: coverage(scene, STREET_CANYON_TX, grid, TraceOptions(max_reflections=2, diffraction_reflections=1),
                             settings=CoverageOptions(workers=1, threads=1)))
    return out
