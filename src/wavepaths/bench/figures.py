"""The plots of the benchmark page, as base64 PNGs (matplotlib, imported when drawn).

The job of this module is every figure of ``index.html``, drawn from the results alone:
the point-search times against the target and the seed (benchmark 1), the query times
against Sionna RT (2), error against run time for path queries and coverage maps (3), the
scaling sweeps (4) and the cost of diffraction (5). :func:`make_figures` returns them by
name, as :func:`wavepaths.bench.page.write_html` expects them.
"""

from __future__ import annotations

import base64
import io

import numpy as np

__all__ = ["make_figures"]


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
        own = [p for p in pts if p.get("error_vs_own_limit")]
        if own:  # its self-convergence: each engine against its own limit, as wavepaths' curve is
            ax.plot([p["time_s"] for p in own], [p["error_vs_own_limit"]["mean_abs_db"] for p in own], "s:",
                    color="tab:orange", alpha=0.6, mfc="none", label="Sionna RT vs its own largest run")
    ref = sec.get("reference") or {}
    ref_time = ref.get("time_s") or next((p["time_s"] for p in sec["wavepaths"]
                                          if p["label"] == ref.get("setting")), None)
    if ref_time:  # error 0 has no place on a log axis: the reference's time as a line
        ax.axvline(ref_time, color="tab:green", ls=":", lw=1, label=f"wavepaths {ref.get('setting', '')}: the reference")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("run time [s]")
    ax.set_ylabel("mean |error| [dB] vs wavepaths' converged answer\n(R3+D2, Sionna's coefficients: compat)",
                  fontsize=8)
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
