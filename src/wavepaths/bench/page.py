"""The benchmark page ``index.html``: the targets, the machine, one section per benchmark.

The job of this module is the HTML of the benchmark report, from a run's summary (the
content of ``bench.json`` with the figures of :mod:`wavepaths.bench.figures`):

* :func:`write_html`: the page, the targets of issue #7 and the headline figures first,
  then the machine and versions, one section per benchmark (tables, notes and its plot:
  point search, path queries against Sionna RT, run time against error, scaling, cost of
  diffraction, what each skip saves, munich) and the profiles of missed targets;
* :func:`render`: the page written again from ``bench.json`` (after a change to the page);
* the formatting of the tables' cells (``_fmt``, ``_table``, ``_img``, ``_opt_label``).
"""

from __future__ import annotations

import html
import json
import os

import numpy as np

from .figures import make_figures
from .summary import _json_default

__all__ = ["render", "write_html"]


def _fmt(x, spec=".3g"):
    if x is None:
        return "–"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, (int, np.integer)):
        return f"{x:,}"
    if isinstance(x, float):
        return format(x, spec)
    return html.escape(str(x))


def _table(rows: list[list], header: list[str]) -> str:
    out = ["<table><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in header) + "</tr>"]
    for r in rows:
        out.append("<tr>" + "".join(f"<td>{_fmt(c)}</td>" for c in r) + "</tr>")
    return "\n".join(out) + "</table>"


def _img(b64: str | None) -> str:
    return f'<img src="data:image/png;base64,{b64}">' if b64 else ""


def write_html(summary: dict, path: str) -> None:
    """The benchmark page: headline table, then one section per benchmark with its plot."""
    res = summary["results"]
    head = summary["headline"]
    parts = [f"""<!doctype html><html><head><meta charset="utf-8"><title>wavepaths benchmarks</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}}
table{{border-collapse:collapse;margin:.5em 0}}td,th{{border:1px solid #ccc;padding:3px 8px;font-size:13px}}
th{{background:#f3f3f3}}.ok{{color:#070}}.miss{{color:#b00}}code{{background:#f5f5f5}}</style></head><body>
<h1>wavepaths benchmarks</h1>
<p>{'Quick run (<code>--quick</code>): fewer repeats, smaller grids.' if summary['quick'] else 'Full run.'}
Written {html.escape(summary['date'])} in {summary['elapsed_s']:.0f} s. Command: <code>{html.escape(summary['command'])}</code></p>
<p>The machine is shared and noisy (2 cores, other jobs running: load average {summary['load_before']} before,
{summary['load_after']} after). Speeds that are compared are measured in one run, the contenders
interleaved round by round, and reported as medians over the rounds.</p>
<h2>Targets (issue #7)</h2>"""]
    rows = []
    for k, v in head["targets"].items():
        cls = "ok" if v else ("miss" if v is False else "")
        rows.append(f"<tr><td>{html.escape(k)}</td><td class='{cls}'>{'met' if v else ('missed' if v is False else 'not run')}</td></tr>")
    parts.append("<table><tr><th>target</th><th>result</th></tr>" + "".join(rows) + "</table>")
    parts.append(_table([["point_search_ns", head["point_search_ns"]], ["point_search_speedup", head["point_search_speedup"]],
                         ["engine_candidate_ns", head.get("engine_candidate_ns")],
                         ["sionna_paths_time_ratio", head["sionna_paths_time_ratio"]],
                         ["diffraction_cost_ratio", head["diffraction_cost_ratio"]]], ["figure", "value"]))
    parts.append("<h2>Machine and versions</h2>" + _table([[k, v] for k, v in summary["machine"].items()], ["", ""]))

    sections = (("point_search", _point_search_section), ("sionna_paths", _sionna_paths_section),
                ("tradeoff", _tradeoff_section), ("scaling", _scaling_section),
                ("diffraction_cost", _diffraction_cost_section))
    for key, section in sections:  # the benchmarks that ran, in order
        if res.get(key):
            parts += section(res[key], summary["figures"])
    if res.get("skips"):
        parts += _skips_section(res["skips"])

    mu = res.get("munich")
    if mu:
        parts += _munich_section(mu)
    if summary.get("profiles"):
        parts.append("<h2>Profiles of missed targets</h2>")
        for name, text in summary["profiles"].items():
            parts.append(f"<h3>{html.escape(name)}</h3><pre>{html.escape(text)}</pre>")
    parts.append("</body></html>")
    with open(path, "w") as f:
        f.write("\n".join(parts))


def _point_search_section(ps: dict, figures: dict) -> list[str]:
    """Benchmark 1: the diffraction point search."""
    parts: list[str] = []
    parts.append("<h2>1. Diffraction point search (seed §4, fig. 7)</h2>")
    parts.append(f"<p>{ps['n_pairs']:,} random pairs E, R and edges AB (all in a 20 m cube; "
                 f"{ps['fraction_on_edge']:.0%} have their point on the segment), solved over all pairs at once as numpy "
                 f"arrays, the closed form {ps['methods']['closed_form']['calls']:,} times and each numerical search "
                 f"{ps['methods'][ps['fastest_numerical']]['calls']:,} times, in {ps['rounds']} interleaved rounds. The seed: "
                 f"{ps['seed']['ns_per_point']:.0f} ns per point, {ps['seed']['speedup'][0]}-{ps['seed']['speedup'][1]}x "
                 f"faster than the numerical search, on {html.escape(ps['seed']['hardware'])}.</p>")
    rows = []
    for name, m in ps["methods"].items():
        ag = m.get("agreement_with_closed_form") or {}
        rows.append([name, m["ns_per_point_median"], m["ns_per_point_min"], m.get("iterations"),
                     m.get("speedup_of_closed_form"), ag.get("max_point_distance_m"),
                     ag.get("on_edge_disagreements")])
    parts.append(_table(rows, ["method", "ns/point (median)", "ns/point (min)", "iterations",
                               "closed form faster by", "max |P - P_closed| [m]", "on-edge disagreements"]))
    both = ps.get("both_compiled")
    if both:
        parts.append("<p>Both searches compiled (numba loops over the pairs, the same formulas and stopping "
                     "step): the algorithms' own ratio, without numpy's array passes per Newton iteration.</p>")
        ag = both["newton_agreement_with_closed_form"]
        parts.append(_table([["closed form, compiled", both["closed_form_ns_per_point"], None, None, None],
                             ["Newton (reduced), compiled", both["newton_reduced_ns_per_point"],
                              both["newton_iterations"], both["speedup"], ag["max_point_distance_m"]]],
                            ["method", "ns/point (median)", "iterations", "closed form faster by",
                             "max |P - P_closed| [m]"]))
    sc = ps["scalar_per_call"]
    parts.append(_table([["closed form, pure Python", sc["closed_form_python_ns"]],
                         ["Newton (reduced), pure Python", sc["newton_python_ns"]],
                         ["closed form from 3-D points, numpy, one pair", sc["closed_form_numpy_one_pair_ns"]],
                         ["ratio, pure Python", sc["speedup_python"]]], ["one pair per call", "ns"]))
    if ps.get("variants"):
        parts.append("<p>The same closed form written differently (not the engine's kernel; what it could reach):</p>")
        parts.append(_table([[k, v] for k, v in ps["variants"].items()], ["variant", "ns/point (median)"]))
    parts.append(_img(figures.get("point_search")))
    return parts


def _sionna_paths_section(sp: dict, figures: dict) -> list[str]:
    """Benchmark 2: path queries against Sionna RT."""
    parts: list[str] = []
    parts.append("<h2>2. Path queries against Sionna RT</h2>")
    if "skipped" in sp:
        parts.append(f"<p>Skipped: {html.escape(sp['skipped'])}</p>")
    else:
        parts.append("<p>Same XML file, transmitter, 100 receivers and path types: Sionna <code>max_depth=3</code>, "
                     "LOS, specular reflections, diffraction with edge diffraction (free edges) and the lit region; "
                     "wavepaths <code>TraceOptions(max_reflections=3, diffraction=True, diffraction_reflections=2)</code> "
                     "plus the fields of every path (Sionna's timed call computes its coefficients too). "
                     f"{html.escape(sp['method'])}.</p>")
        rows = []
        for s in sp["scenes"].values():
            wp = s["wavepaths"]
            ag = s.get("agreement") or {}
            rows.append([s["scene"], s["sionna"]["median_s"], wp.get("median_s"), s.get("time_ratio"),
                         s["sionna"]["num_paths"], wp.get("num_paths"), ag.get("sionna_paths_found_by_wavepaths"),
                         ag.get("only_sionna"), ag.get("only_wavepaths"),
                         (ag.get("gain_diff_db") or {}).get("median"), (ag.get("delay_rel_error") or {}).get("max")])
        parts.append(_table(rows, ["scene", "Sionna [s]", "wavepaths [s]", "ratio", "Sionna paths",
                                   "wavepaths paths", "Sionna's found by wavepaths", "only Sionna", "only wavepaths",
                                   "median |Δa| [dB]", "max delay rel. error"]))
        for s in sp["scenes"].values():
            parts.append(f"<h3>{html.escape(s['scene'])}</h3><p>{html.escape(s['note'])}</p>")
            if not s["wavepaths"].get("finished"):
                parts.append(f"<p class='miss'>wavepaths did not finish: {html.escape(str(s['wavepaths'].get('error')))}; "
                             f"ratio at most {_fmt(s.get('time_ratio_upper_bound'))}.</p>")
            kinds = sorted(set(s["sionna"]["kinds"]) | set(s["wavepaths"].get("kinds", {})), key=lambda k: (len(k), k))
            parts.append(_table([[k, s["sionna"]["kinds"].get(k, 0), s["wavepaths"].get("kinds", {}).get(k, 0),
                                  ((s.get("agreement") or {}).get("by_kind", {}).get(k) or {}).get("matched")]
                                 for k in kinds], ["sequence", "Sionna", "wavepaths", "matched"]))
        parts.append(_img(figures.get("sionna_paths")))
    return parts


def _tradeoff_section(to: dict, figures: dict) -> list[str]:
    """Benchmark 3: run time against error."""
    parts: list[str] = []
    parts.append("<h2>3. Run time against error</h2>")
    parts.append(f"<p>Error: {html.escape(to['error_metric'])}. The reference is wavepaths with all paths of depth 3 "
                 "(R3+D2) and Sionna's coefficient model (compat), cell-averaged over sub-cells for maps. "
                 "wavepaths' knobs: reflection order, diffraction and its reflections, sub-cells per cell, the "
                 "reflections' pruning threshold (prune N dB: reflections at least N dB below free space dropped) "
                 "and the tolerance in dB (tol: diffracted contributions that cannot change a cell's power sum by "
                 "more dropped); it has no float32 mode (geometry is float64). Sionna's knob: samples per source. "
                 "Each setting is timed once per run (the path queries three times back to back), not in "
                 "alternating rounds.</p>")
    for part in ("paths", "maps"):
        sec = to[part]
        parts.append(_img(figures.get(f"tradeoff_{part}")))
        rows = [["wavepaths", p["label"], p["time_s"], p["error"]["mean_abs_db"], p["error"]["median_abs_db"],
                 p["error"]["missed_fraction"], None] for p in sec["wavepaths"]]
        if "points" in (sec.get("sionna") or {}):
            rows += [["Sionna RT", p["label"], p["time_s"], p["error"]["mean_abs_db"], p["error"]["median_abs_db"],
                      p["error"]["missed_fraction"], (p.get("error_vs_own_limit") or {}).get("mean_abs_db")]
                     for p in sec["sionna"]["points"]]
        parts.append(_table(rows, ["engine", "setting", "time [s]", "mean |err| [dB]", "median |err| [dB]",
                                   "missed fraction", "vs own limit [dB]"]))
        v = sec.get("verdict")
        if v:
            parts.append(f"<p>Every Sionna point beaten (a wavepaths point at most as slow and at most as wrong), "
                         f"against wavepaths' converged answer: <b>{_fmt(v['every_sionna_point_beaten'])}</b>.")
            own = sec.get("verdict_self_convergence")
            if own:
                parts.append(f" Each engine against its own limit (Sionna against its largest run, wavepaths "
                             f"against its converged answer): <b>{_fmt(own['every_sionna_point_beaten'])}</b>.")
            apart = (sec.get("sionna") or {}).get("reference_vs_sionna_limit")
            if apart:
                parts.append(f" The two converged answers differ by {_fmt(apart['mean_abs_db'])} dB (mean |err|): "
                             "model differences (Sionna's D-R coefficients that depend on max_depth, paths its "
                             "sampling never finds; docs/validation), which the common reference counts against "
                             "Sionna.")
            parts.append("</p>")
    return parts


def _scaling_section(sc: dict, figures: dict) -> list[str]:
    """Benchmark 4: scaling."""
    parts: list[str] = []
    parts.append("<h2>4. Scaling</h2>")
    parts.append(_img(figures.get("scaling")))
    rows = []
    for sweep, label in (("receivers", "receivers"), ("order", "order")):
        for r in sc[sweep]["points"]:
            rows.append([label, r.get("num_rx"), _opt_label(r.get("options", {})), r.get("time_s"),
                         _gb(r.get("peak_numpy_bytes")), _gb(r.get("max_rss_bytes")), r.get("num_paths"),
                         _dominant(r), r.get("error")])
    for key in ("first_order", "default"):
        for r in sc["triangles"][key]["points"]:
            rows.append([f"{r.get('square_m'):g} m etoile: {r.get('triangles')} tri, {r.get('diffracting_dihedra')} dih",
                         r.get("num_rx"), _opt_label(r.get("options", {})), r.get("time_s"),
                         _gb(r.get("peak_numpy_bytes")), _gb(r.get("max_rss_bytes")), r.get("num_paths"),
                         _dominant(r), r.get("error")])
    parts.append(_table(rows, ["sweep", "receivers", "options", "time [s]", "numpy peak [GB]", "process peak [GB]",
                               "paths", "largest counters", "error"]))
    if sc.get("analysis"):
        parts.append(f"<p>{html.escape(sc['analysis'])}</p>")
    oc = sc.get("occlusion")
    if oc and "ns_per_segment" in oc:
        parts.append(f"<p>Occlusion (Embree's half-rays, each hit decided in float64, and the float64 tree): {oc['segments']:,} legs of "
                     f"simple_street_canyon ({oc['blocked_fraction']:.0%} blocked), ns per segment.</p>")
        parts.append(_table([[k, v] for k, v in oc["ns_per_segment"].items()]
                            + [["speed-up", oc.get("speedup")], ["same verdicts", oc.get("same_verdicts")],
                               ["float64 tree: speed-up over the compiled half-rays",
                                oc.get("tree_speedup_over_compiled")],
                               ["float64 tree: the float64 rule's verdict on every segment",
                                oc.get("tree_matches_rule")],
                               ["Embree's half-rays: segments off the float64 rule", oc.get("embree_misses_of_rule")]],
                            ["set-up and confirmation", "ns per segment"]))
    return parts


def _diffraction_cost_section(dc: dict, figures: dict) -> list[str]:
    """Benchmark 5: the cost of diffraction."""
    parts: list[str] = []
    parts.append("<h2>5. Cost of diffraction</h2>")
    parts.append(f"<p>Coverage map of simple_street_canyon, {dc['grid_shape'][0]} x {dc['grid_shape'][1]} cells of "
                 f"{dc['cell_size_m']:g} m; the seed paid {dc['seed_ratio']:g}x for one diffraction between two fixed "
                 f"points (its §4), the case of R2 / R2+D0. Headline: {dc['headline_pair']}. One process, its "
                 f"tiles on {dc.get('threads', 1)} thread(s) (the default), the headline pair on one thread "
                 "beside it.</p>")
    parts.append(_table([[f"{p['off']} / {p['on']}", p.get("threads", 1), p["off_s"]["median_s"], p["on_s"]["median_s"], p["ratio"],
                          p["diffracted_paths"], p["all_paths"], p.get("paths_ratio"), p.get("us_per_path_off"),
                          p.get("us_per_diffracted_path")] for p in dc["pairs"]],
                        ["pair", "threads", "off [s]", "on [s]", "ratio", "diffracted paths (on)", "all paths (on)",
                         "paths on / off", "us per path (off)", "us per diffracted path (added)"]))
    parts.append(_img(figures.get("diffraction_cost")))
    if dc.get("stages"):
        parts.append(f"<p>Where the time of {dc['headline_pair']} goes: both maps once more under cProfile, on one "
                     "thread, "
                     "by stage (the profiler inflates Python calls; read the shares).</p>")
        parts.append(_table([[r["stage"], r["off_s"], r["on_s"], r["added_s"], r["share_of_added"]]
                             for r in dc["stages"]],
                            ["stage", "off [s]", "on [s]", "added by diffraction [s]", "share of the added time"]))
    fl = dc.get("floor")
    if fl:
        parts.append(
            f"<p>The floor of {dc['headline_pair']}: what the map with diffraction cannot do without, timed on "
            f"one thread against the map without diffraction (median of {fl['off_s']['rounds']} alternating "
            f"rounds): the fields of its {fl['diffracted_paths']:,} diffracted paths and one occlusion query for "
            f"each of their {fl['legs']:,} legs. A search that found those paths at no other cost would give "
            f"the one-thread floor below, and, with that work spread ideally over {fl['threads']} threads, "
            f"the ideal floor after it. The search's own time on {fl['threads']} threads is what the measured map "
            "takes beyond that floor; to meet a ratio of 3 it would have to fit in the budget.</p>")
        parts.append(_table([["map without diffraction, one thread [s]", fl["off_s"]["median_s"]],
                             ["fields of the diffracted paths [s]", fl["fields_s"]["median_s"]],
                             ["ns per diffracted path (fields)", fl["ns_per_path_fields"]],
                             ["casts of their legs [s]", fl["casts_s"]["median_s"]],
                             ["ns per leg (casts)", fl["ns_per_leg_cast"]],
                             ["floor of the ratio, one thread", fl["floor_one_thread"]],
                             [f"floor of the ratio, {fl['threads']} threads (ideal)", fl["floor_threads_ideal"]],
                             [f"search now, {fl['threads']} threads [s]", fl["search_s"]],
                             [f"search budget for 3x, {fl['threads']} threads [s]", fl["search_budget_s"]]],
                            ["figure", "value"]))
    return parts


def _skips_section(sk: dict) -> list[str]:
    """Benchmark 6: what each skip saves."""
    parts: list[str] = []
    parts.append("<h2>6. What each skip saves</h2>")
    parts.append(f"<p>Benchmark 2's query ({html.escape(sk['scene'])}, {sk['num_rx']} receivers, "
                 f"{html.escape(_opt_label(sk['options']))}, fields included) with every culling test on, each "
                 f"switched off in turn (<code>TraceOptions(disable_culling=...)</code>), and all off; rounds "
                 f"alternate. Same paths in every setting: {_fmt(sk['all_same_paths'])}.</p>")
    parts.append(_table([[r["setting"], r["time_s"]["median_s"], r["saved_s"], r["saved_fraction"],
                          r["culled_with_it_on"], r["num_paths"], r["same_paths"], r["description"]]
                         for r in sk["rows"]],
                        ["setting", "time [s]", "saved by the test [s]", "share of the time without it",
                         "pairs it culls", "paths", "same paths", "test"]))
    parts.append("<p>Counters of the other skips (all on):</p>")
    parts.append(_table([[k, v] for k, v in sorted(sk["counters_all_on"].items())], ["counter", "value"]))
    return parts


def _munich_section(mu: dict) -> list[str]:
    """The optional munich scale benchmark."""
    parts: list[str] = []
    parts.append("<h2>Scale: munich (optional)</h2>")
    la = mu.get("launched") or {}
    if la.get("finished"):
        ck = la.get("check") or {}
        parts.append(_table([[
            f"{la.get('total_s', 0):.0f}", f"{(la.get('timings') or {}).get('context_s', 0):.0f}",
            f"{(la.get('timings') or {}).get('launch_s', 0):.0f}", f"{(la.get('timings') or {}).get('tiles_s', 0):.0f}",
            f"{(la.get('max_group_rss_bytes') or 0) / 2**30:.2f}", la.get("cells_traced"),
            f"{ck.get('paths_launched')} of {ck.get('paths_exhaustive')}" if ck.get("paths_exhaustive") else "-",
            f"{ck.get('max_cell_error_db', float('nan')):.2g}" if ck.get("paths_exhaustive") else "-",
            la.get("meets_target")]],
            ["map [s]", "context [s]", "launch [s]", "tiles [s]", "peak memory, process and workers [GiB]",
             "cells", "paths found on the check cells", "worst cell error [dB]", "meets target"]))
    parts.append("<pre>" + html.escape(json.dumps({k: v for k, v in mu.items() if k != "stats"}, indent=1,
                                                   default=_json_default)) + "</pre>")
    return parts


def _gb(x):
    return None if x is None else x / 1e9


def _opt_label(o: dict) -> str:
    if not o:
        return ""
    s = f"R{o.get('max_reflections', 2)}"
    if o.get("diffraction", True):
        s += f"+D{o.get('diffraction_reflections', 1)}"
    return s


def _dominant(r: dict) -> str:
    from .scaling import dominant_terms

    st = r.get("stats")
    if not st:
        return ""
    return "; ".join(f"{k} {v:,}" for k, v in dominant_terms(st, 3))


def render(out_dir: str) -> None:
    """Write ``out_dir/index.html`` again from ``out_dir/bench.json`` (after a change to the page)."""
    with open(os.path.join(out_dir, "bench.json")) as f:
        summary = json.load(f)
    summary["figures"] = make_figures(summary["results"])
    write_html(summary, os.path.join(out_dir, "index.html"))
