"""``wavepaths bench``: run the benchmarks, write ``bench.json`` and an HTML page with plots.

The page and the JSON carry the machine (CPU, cores, load average before and after),
the versions (wavepaths, numpy, scipy, embreex, Sionna RT, Mitsuba, Dr.Jit), each
benchmark's figures and the targets of issue #7 beside them. ``bench.json`` has the
headline keys at its top level: ``point_search_ns``, ``point_search_speedup``,
``sionna_paths_time_ratio``, ``diffraction_cost_ratio`` and ``tradeoff_points`` (the
error-against-time points of benchmark 3).
"""

from __future__ import annotations

import base64
import html
import io
import json
import os
import platform
import sys
import time

import numpy as np

from .timing import load_average

BENCHMARKS = ("point_search", "sionna_paths", "tradeoff", "scaling", "diffraction_cost", "skips")


def machine_info() -> dict:
    """CPU, cores, memory, OS and the versions of everything that is timed."""
    import numpy
    import scipy

    from .. import __version__

    out = {"wavepaths": __version__, "python": sys.version.split()[0], "numpy": numpy.__version__,
           "scipy": scipy.__version__, "platform": platform.platform(), "machine": platform.machine(),
           "cpus": os.cpu_count(), "openblas_coretype": os.environ.get("OPENBLAS_CORETYPE")}
    try:
        from importlib.metadata import version

        out["embreex"] = version("embreex")
    except Exception:  # pragma: no cover
        pass
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    out["cpu"] = line.split(":", 1)[1].strip()
                    break
        with open("/proc/meminfo") as f:
            out["memory_bytes"] = int(f.readline().split()[1]) * 1024
    except OSError:  # pragma: no cover
        pass
    try:
        from ..validation.sionna_env import sionna_version

        v = sionna_version()
        if v:
            out["sionna-rt"] = v
            from importlib.metadata import version

            out["mitsuba"] = version("mitsuba")
            out["drjit"] = version("drjit")
    except Exception:  # pragma: no cover
        pass
    return out


def _json_default(x):
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.floating,)):
        return float(x)
    return str(x)


def headline(results: dict) -> dict:
    """The top-level figures of ``bench.json`` and their targets."""
    ps = results.get("point_search") or {}
    sp = results.get("sionna_paths") or {}
    dc = results.get("diffraction_cost") or {}
    to = results.get("tradeoff") or {}
    points = []
    for part in ("maps", "paths"):
        sec = to.get(part) or {}
        for engine in ("wavepaths", "sionna"):
            rows = sec.get(engine)
            rows = rows.get("points", []) if isinstance(rows, dict) else (rows or [])
            for r in rows:
                points.append({"benchmark": part, "engine": engine, "setting": r["label"], "time_s": r["time_s"],
                               "error_db": r["error"]["mean_abs_db"], "missed_fraction": r["error"]["missed_fraction"]})
    head = {
        "point_search_ns": ps.get("point_search_ns"),
        "point_search_speedup": ps.get("point_search_speedup"),
        "engine_candidate_ns": ps.get("engine_candidate_ns"),
        "sionna_paths_time_ratio": sp.get("sionna_paths_time_ratio"),
        "diffraction_cost_ratio": dc.get("diffraction_cost_ratio"),
        "diffraction_cost_ratio_seed_case": dc.get("seed_case_ratio"),
        "diffraction_cost_ratio_seed_case_one_thread": dc.get("seed_case_ratio_one_thread"),
        "diffraction_cost_ratio_one_thread": dc.get("diffraction_cost_ratio_one_thread"),
        # what the headline ratio would be on one thread if finding the diffracted paths cost
        # nothing beyond their fields and casts (diffraction_cost.cost_floor)
        "diffraction_cost_floor_one_thread": (dc.get("floor") or {}).get("floor_one_thread"),
        "tradeoff_points": points,
    }
    maps_verdict = (to.get("maps") or {}).get("verdict") or {}
    paths_verdict = (to.get("paths") or {}).get("verdict") or {}
    munich = results.get("munich") or {}
    head["targets"] = {
        "point_search_ns <= 50": _ok(head["point_search_ns"], lambda v: v <= 50),
        "point_search_speedup >= 5": _ok(head["point_search_speedup"], lambda v: v >= 5),
        "sionna_paths_time_ratio >= 20": _ok(head["sionna_paths_time_ratio"], lambda v: v >= 20),
        "every Sionna path found": _ok(_found_all(sp), lambda v: v),
        "coverage curve below-left of Sionna (maps)": maps_verdict.get("every_sionna_point_beaten"),
        "path curve below-left of Sionna (paths)": paths_verdict.get("every_sionna_point_beaten"),
        "diffraction_cost_ratio <= 3": _ok(head["diffraction_cost_ratio"], lambda v: v <= 3),
        "munich < 10 min and < 8 GB": munich.get("meets_target") if munich and "skipped" not in munich else None,
        "munich < 10 min and < 8 GB (launched candidates)": (munich.get("launched") or {}).get("meets_target"),
    }
    return head


def _ok(value, test):
    return None if value is None else bool(test(value))


def _found_all(sp: dict):
    sc = (sp.get("scenes") or {}).get("simple_street_canyon") or {}
    ag = sc.get("agreement")
    return None if ag is None else ag.get("only_sionna_not_found_by_wavepaths", ag["only_sionna"]) == 0


# ---- plots -------------------------------------------------------------------------------
def _png(fig) -> str:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()


def _fig_point_search(ps: dict):
    import matplotlib.pyplot as plt

    names = list(ps["methods"])
    vals = [ps["methods"][n]["ns_per_point_median"] for n in names]
    fig, ax = plt.subplots(figsize=(6, 3))
    ax.barh(names + ["seed (1999)"], vals + [ps["seed"]["ns_per_point"]],
            color=["tab:green"] + ["tab:gray"] * (len(names) - 1) + ["tab:blue"])
    ax.set_xscale("log")
    ax.axvline(50, color="r", ls="--", lw=1, label="target 50 ns")
    ax.set_xlabel("ns per diffraction point (median over rounds)")
    ax.legend(loc="lower right")
    return fig


def _fig_tradeoff(to: dict, part: str, key: str = "error"):
    import matplotlib.pyplot as plt

    sec = to[part]
    fig, ax = plt.subplots(figsize=(6.5, 4))
    wp = [p for p in sec["wavepaths"] if p.get(key) and (p[key]["mean_abs_db"] or 0) > 0]  # the reference: error 0
    ax.plot([p["time_s"] for p in wp], [p[key]["mean_abs_db"] if p.get(key) else np.nan for p in wp], "o",
            color="tab:green", label="wavepaths")
    for p in wp:
        ax.annotate(p["label"], (p["time_s"], p[key]["mean_abs_db"] if p.get(key) else np.nan), fontsize=7,
                    xytext=(3, 3), textcoords="offset points")
    sn = sec.get("sionna") or {}
    if "points" in sn:
        pts = sn["points"]
        ax.plot([p["time_s"] for p in pts], [p["error"]["mean_abs_db"] for p in pts], "s-", color="tab:orange",
                label="Sionna RT (samples)")
        for p in pts:
            ax.annotate(p["label"].replace(" samples", ""), (p["time_s"], p["error"]["mean_abs_db"]), fontsize=7,
                        xytext=(3, -9), textcoords="offset points")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("run time [s]")
    ax.set_ylabel("mean |error| [dB] vs converged reference")
    ax.set_title({"maps": "coverage maps", "paths": "path queries (100 receivers)"}[part])
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    return fig


def _fig_scaling(sc: dict):
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    rec = sc["receivers"]["points"]
    ax = axes[0]
    ok = [r for r in rec if "time_s" in r]
    ax.loglog([r["num_rx"] for r in ok], [r["time_s"] for r in ok], "o-", label="time [s]")
    mem = [r for r in ok if r.get("peak_numpy_bytes")]
    ax.loglog([r["num_rx"] for r in mem], [r["peak_numpy_bytes"] / 1e9 for r in mem], "s--", label="numpy peak [GB]")
    ax.set_xlabel("receivers")
    ax.legend()
    ax.set_title("street canyon, R2+D1")
    ax = axes[1]
    order = [r for r in sc["order"]["points"] if "time_s" in r]
    labels = [(f"R{r['options']['max_reflections']}" + (f"+D{r['options']['diffraction_reflections']}"
                                                       if r["options"].get("diffraction") else "")) for r in order]
    ax.bar(labels, [r["time_s"] for r in order])
    ax.tick_params(axis="x", labelrotation=45)
    ax.set_yscale("log")
    ax.set_ylabel("time [s], 100 receivers")
    ax.set_title("reflection order")
    ax = axes[2]
    for key, style in (("first_order", "o-"), ("default", "s-")):
        rows = [r for r in sc["triangles"][key]["points"] if "time_s" in r]
        if rows:
            ax.loglog([r["triangles"] for r in rows], [r["time_s"] for r in rows], style,
                      label={"first_order": "R1+D0", "default": "R2+D1"}[key])
    ax.set_xlabel("triangles (etoile crops)")
    ax.set_ylabel("time [s], 100 receivers")
    ax.legend()
    return fig


def _fig_diffraction_cost(dc: dict):
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3))
    labels = [f"{p['off']} / {p['on']}" + (", 1 thread" if p.get("threads") == 1 and dc.get("threads", 1) > 1 else "")
              for p in dc["pairs"]]
    ax.bar(labels, [p["ratio"] for p in dc["pairs"]], color="tab:green")
    ax.axhline(dc["target_ratio_max"], color="r", ls="--", lw=1, label="target 3x")
    ax.axhline(dc["seed_ratio"], color="tab:blue", ls=":", lw=1, label="seed 46x")
    ax.set_yscale("log")
    ax.set_ylabel("time with / without diffraction")
    ax.legend()
    return fig


def _fig_sionna_paths(sp: dict):
    import matplotlib.pyplot as plt

    scenes = [s for s in sp["scenes"].values() if s.get("wavepaths", {}).get("finished")]
    if not scenes:
        return None
    fig, ax = plt.subplots(figsize=(6, 3))
    x = np.arange(len(scenes))
    sn = [s["sionna"]["median_s"] for s in scenes]
    wp = [s["wavepaths"]["median_s"] for s in scenes]
    ax.bar(x - 0.2, sn, 0.4, label="Sionna RT", color="tab:orange")
    ax.bar(x + 0.2, wp, 0.4, label="wavepaths", color="tab:green")
    for i, s in enumerate(scenes):
        ax.annotate(f"{s['time_ratio']:.1f}x", (i, max(sn[i], wp[i])), ha="center", va="bottom")
    ax.set_xticks(x, [s["scene"] for s in scenes])
    ax.set_ylabel("time per query [s] (median)")
    ax.legend()
    return fig


# ---- HTML --------------------------------------------------------------------------------
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

    ps = res.get("point_search")
    if ps:
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
        sc = ps["scalar_per_call"]
        parts.append(_table([["closed form, pure Python", sc["closed_form_python_ns"]],
                             ["Newton (reduced), pure Python", sc["newton_python_ns"]],
                             ["closed form from 3-D points, numpy, one pair", sc["closed_form_numpy_one_pair_ns"]],
                             ["ratio, pure Python", sc["speedup_python"]]], ["one pair per call", "ns"]))
        if ps.get("variants"):
            parts.append("<p>The same closed form written differently (not the engine's kernel; what it could reach):</p>")
            parts.append(_table([[k, v] for k, v in ps["variants"].items()], ["variant", "ns/point (median)"]))
        parts.append(_img(summary["figures"].get("point_search")))

    sp = res.get("sionna_paths")
    if sp:
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
            parts.append(_img(summary["figures"].get("sionna_paths")))

    to = res.get("tradeoff")
    if to:
        parts.append("<h2>3. Run time against error</h2>")
        parts.append(f"<p>Error: {html.escape(to['error_metric'])}. The reference is wavepaths with all paths of depth 3 "
                     "(R3+D2) and Sionna's coefficient model (compat), cell-averaged over sub-cells for maps. "
                     "wavepaths' knobs: reflection order, diffraction and its reflections, sub-cells per cell; it has no "
                     "pruning tolerance (pruning is exact) and no float32 mode. Sionna's knob: samples per source.</p>")
        for part in ("paths", "maps"):
            sec = to[part]
            parts.append(_img(summary["figures"].get(f"tradeoff_{part}")))
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
                parts.append(f"<p>Every Sionna point beaten (a wavepaths point at most as slow and at most as wrong): "
                             f"<b>{_fmt(v['every_sionna_point_beaten'])}</b>.</p>")

    sc = res.get("scaling")
    if sc:
        parts.append("<h2>4. Scaling</h2>")
        parts.append(_img(summary["figures"].get("scaling")))
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

    dc = res.get("diffraction_cost")
    if dc:
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
        parts.append(_img(summary["figures"].get("diffraction_cost")))
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

    sk = res.get("skips")
    if sk:
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

    mu = res.get("munich")
    if mu:
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
    if summary.get("profiles"):
        parts.append("<h2>Profiles of missed targets</h2>")
        for name, text in summary["profiles"].items():
            parts.append(f"<h3>{html.escape(name)}</h3><pre>{html.escape(text)}</pre>")
    parts.append("</body></html>")
    with open(path, "w") as f:
        f.write("\n".join(parts))


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


def make_figures(results: dict) -> dict:
    """Every plot of the page, from the results alone (base64 PNGs by name)."""
    figs = {}
    if results.get("point_search"):
        figs["point_search"] = _png(_fig_point_search(results["point_search"]))
    sp = results.get("sionna_paths")
    if sp and "skipped" not in sp:
        fig = _fig_sionna_paths(sp)
        if fig is not None:
            figs["sionna_paths"] = _png(fig)
    if results.get("tradeoff"):
        figs["tradeoff_paths"] = _png(_fig_tradeoff(results["tradeoff"], "paths"))
        figs["tradeoff_maps"] = _png(_fig_tradeoff(results["tradeoff"], "maps"))
    if results.get("scaling"):
        figs["scaling"] = _png(_fig_scaling(results["scaling"]))
    if results.get("diffraction_cost"):
        figs["diffraction_cost"] = _png(_fig_diffraction_cost(results["diffraction_cost"]))
    return figs


def render(out_dir: str) -> None:
    """Write ``out_dir/index.html`` again from ``out_dir/bench.json`` (after a change to the page)."""
    with open(os.path.join(out_dir, "bench.json")) as f:
        summary = json.load(f)
    summary["figures"] = make_figures(summary["results"])
    write_html(summary, os.path.join(out_dir, "index.html"))


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
