"""The report's figures, drawn from ``validation.json`` alone.

Every figure is a function of the summary as written to (and read back from)
``validation.json``: the boundary lines' complex fields (``lines.<name>.curves``), the
cases' total path gains and the coverage maps (``coverage.runs.<run>.*_db``). So the
report's figures can be rebuilt from the files it writes (:func:`report_figures`).
Each figure is returned as a base64 PNG.
"""

from __future__ import annotations

import base64
import io

import numpy as np

from .lines import curves_from_summary

LINE_STYLES = {"exact": dict(color="k", lw=2.4), "wavepaths UTD": dict(color="tab:blue", lw=1.4),
               "wavepaths GTD": dict(color="tab:gray", lw=0.9, ls=":"),
               "Sionna RT": dict(color="tab:red", lw=1.4, ls="--"),
               "wavepaths compat=sionna": dict(color="tab:orange", lw=0.9, ls="-.")}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def png(fig) -> str:
    """Base64 PNG of ``fig``, which is closed."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    _pyplot().close(fig)
    return base64.b64encode(buf.getvalue()).decode()


def line_figure(name: str, entry: dict) -> str:
    """|u| in dB along one boundary line, every engine and the exact solution, soft and hard.

    ``entry`` is ``summary["lines"][name]`` (:func:`wavepaths.validation.lines.line_summary`).
    """
    plt = _pyplot()
    curves = curves_from_summary(entry)
    phi_deg = np.asarray(entry["phi_deg"], dtype=float)
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.2), sharey=True)
    for ax, pol in zip(axes, ("H", "V")):
        for label, style in LINE_STYLES.items():
            u = curves.get((label, pol))
            if u is None:
                continue
            ax.plot(phi_deg, 20 * np.log10(np.maximum(np.abs(u), 1e-6)), label=label, **style)
        for bname, b in entry["boundaries_deg"].items():
            ax.axvline(b, color="0.6", lw=0.8)
            ax.text(b, 7.5, bname.replace(" boundary", "\nboundary"), fontsize=7, ha="center", va="top")
        pp = entry["phi_prime_deg"]  # the source's direction
        ax.axvline(pp, color="tab:green", lw=0.8, ls=":")
        ax.text(pp, -29.0, "source phi'", fontsize=7, ha="center", va="bottom", color="tab:green")
        ax.set_title(f"{name}: {'soft (E along the edge)' if pol == 'H' else 'hard (H along the edge)'}, "
                     f"k rho = {entry['k_rho']:.0f}")
        ax.set_xlabel("observer angle phi from the 0-face [deg]")
        ax.set_ylim(-30, 8)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("|u| / incident at the edge [dB]")
    axes[0].legend(fontsize=8, loc="lower left")
    return png(fig)


def gain_figure(case_result: dict) -> str:
    """Total path gain per receiver of one case: Sionna, wavepaths' matched paths, all of wavepaths' paths."""
    plt = _pyplot()
    pols = list(case_result["polarizations"])
    fig, axes = plt.subplots(1, len(pols), figsize=(6.5 * len(pols), 3.6), squeeze=False)
    for ax, pol in zip(axes[0], pols):
        g = case_result["polarizations"][pol]["total_gain_db"]
        x = np.arange(case_result["num_rx"])
        # dtype=float: a receiver no path reaches is -inf dB in memory, null (NaN here) in the JSON
        ax.plot(x, np.asarray(g["sionna"], dtype=float)[0], "o--", color="tab:red", label="Sionna RT", ms=4)
        ax.plot(x, np.asarray(g["wavepaths_matched_compat"], dtype=float)[0], ".-", color="tab:orange",
                label="wavepaths, matched paths, compat")
        ax.plot(x, np.asarray(g["wavepaths_all_textbook"], dtype=float)[0], "-", color="tab:blue",
                label="wavepaths, all paths, UTD")
        ax.set_xlabel("receiver")
        ax.set_ylabel("total path gain [dB]")
        ax.set_title(f"{case_result['name']} ({pol})")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    return png(fig)


def report_figures(summary: dict) -> dict:
    """Every figure of the report, keyed as :func:`wavepaths.validation.report.write_html` expects,
    from a summary as read from ``validation.json``."""
    from .coverage_compare import coverage_figure

    figures = {"gain_" + c["name"]: gain_figure(c) for c in summary["cases"]}
    for name, entry in summary.get("lines", {}).items():
        figures["line_" + name] = line_figure(name, entry)
    if summary.get("coverage"):
        figures["coverage"] = coverage_figure(summary["coverage"])
    return figures
