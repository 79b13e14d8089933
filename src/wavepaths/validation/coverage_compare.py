"""Coverage maps of both engines on the same scene, transmitter and grid.

Sionna RT's ``RadioMapSolver`` gives a cell-averaged, power-summed path gain estimated by
shooting rays (Monte Carlo); wavepaths evaluates every path exactly at each cell centre,
here power-summed too (``CoverageOptions(coherent=False)``) so that the two measure the
same quantity up to cell averaging and sampling noise. Statistics are taken over cells
where both maps are above a noise floor and outside objects.
"""

from __future__ import annotations

import time

import numpy as np

from ..coverage import CoverageOptions, PlanarGrid, coverage
from ..fields import FieldConfig
from ..scene import load_scene
from ..search import TraceOptions

NOISE_FLOOR_DB = -160.0


def compare_coverage(scene_xml: str, tx, center, size, cell: float, max_depth: int, frequency_hz: float = 3.5e9,
                     samples_per_tx: int = 1_000_000) -> dict:
    """Run both engines with and without diffraction; return maps, differences and timings."""
    from .sionna_runner import run_sionna_radio_map

    scene = load_scene(scene_xml)
    tx = np.asarray(tx, dtype=float).reshape(1, 3)
    out = {"scene": scene_xml, "tx": tx[0].tolist(), "center": list(center), "size": list(size), "cell_m": cell,
           "max_depth": max_depth, "noise_floor_db": NOISE_FLOOR_DB, "frequency_hz": frequency_hz,
           "samples_per_tx": samples_per_tx, "antennas": "isotropic, V, both ends (Sionna's defaults)",
           "field_model": "wavepaths: UTD (textbook), power sum at the cell centres; Sionna: RadioMapSolver, "
                          "cell-averaged power", "runs": {}}
    for diffraction in (False, True):
        sn = run_sionna_radio_map(scene_xml, tx[0], center, size, (cell, cell), (0.0, 0.0, 0.0), frequency_hz,
                                  max_depth, diffraction, samples_per_tx)
        ny, nx = sn.path_gain_db.shape
        grid = PlanarGrid(center=np.asarray(center, float), size=(nx * cell, ny * cell), cell_size=cell)
        opts = TraceOptions(max_reflections=max_depth, diffraction=diffraction,
                            diffraction_reflections=max(max_depth - 1, 0))
        t0 = time.perf_counter()
        cm = coverage(scene, tx, grid, opts, fields=FieldConfig(frequency_hz),
                      settings=CoverageOptions(coherent=False, workers=1))
        wp_time = time.perf_counter() - t0
        wp_db = cm.path_gain_db()
        if wp_db.shape != sn.path_gain_db.shape:
            raise ValueError(f"grid shapes differ: wavepaths {wp_db.shape}, Sionna {sn.path_gain_db.shape}")
        centres_ok = np.allclose(cm.cell_centers[..., :2], sn.cell_centers[..., :2], atol=1e-3 * cell)
        both = np.isfinite(wp_db) & np.isfinite(sn.path_gain_db) & (wp_db > NOISE_FLOOR_DB) & (sn.path_gain_db > NOISE_FLOOR_DB)
        diff = np.full(wp_db.shape, np.nan)
        diff[both] = wp_db[both] - sn.path_gain_db[both]
        d = diff[both]
        out["runs"]["diffraction" if diffraction else "no_diffraction"] = {
            "wavepaths_db": wp_db, "sionna_db": sn.path_gain_db, "difference_db": diff,
            "cell_centres_agree": bool(centres_ok),
            "cells_compared": int(both.sum()), "cells": int(wp_db.size),
            "cells_only_wavepaths": int((np.isfinite(wp_db) & (wp_db > NOISE_FLOOR_DB) & ~(sn.path_gain_db > NOISE_FLOOR_DB)).sum()),
            "mean_db": float(d.mean()) if len(d) else None, "median_db": float(np.median(d)) if len(d) else None,
            "std_db": float(d.std()) if len(d) else None,
            "p95_abs_db": float(np.percentile(np.abs(d), 95)) if len(d) else None,
            "wavepaths_time_s": wp_time, "sionna_time_s": sn.elapsed_s, "sionna_warmup_s": sn.warmup_s,
        }
    return out


def coverage_figure(result: dict) -> str:
    """Base64 PNG: wavepaths, Sionna and their difference, with and without diffraction.

    ``result`` is :func:`compare_coverage`'s, or the report's ``coverage`` entry read back from
    ``validation.json`` (maps as nested lists, ``null`` for non-finite cells).
    """
    import base64
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = result["runs"]
    fig, axes = plt.subplots(len(runs), 3, figsize=(15, 3.6 * len(runs)), squeeze=False)
    cx, cy = result["center"][:2]
    ext = None
    for row, (name, r) in zip(axes, runs.items()):
        # a non-finite cell (-inf: no path; NaN: not compared) is blank either way
        maps = {key: np.asarray(r[key], dtype=float) for key in ("wavepaths_db", "sionna_db", "difference_db")}
        ny, nx = maps["wavepaths_db"].shape
        c = result["cell_m"]
        ext = [cx - nx * c / 2, cx + nx * c / 2, cy - ny * c / 2, cy + ny * c / 2]
        vmin = np.nanpercentile(np.where(np.isfinite(maps["sionna_db"]), maps["sionna_db"], np.nan), 2)
        vmax = np.nanmax(np.where(np.isfinite(maps["sionna_db"]), maps["sionna_db"], np.nan))
        for ax, key, title in ((row[0], "wavepaths_db", "wavepaths (exact paths, power sum)"),
                               (row[1], "sionna_db", "Sionna RT RadioMapSolver")):
            im = ax.imshow(np.where(np.isfinite(maps[key]), maps[key], np.nan), origin="lower", extent=ext,
                           vmin=vmin, vmax=vmax, cmap="viridis")
            ax.plot(*result["tx"][:2], "r*", ms=12)
            ax.set_title(f"{title}, {name.replace('_', ' ')}", fontsize=9)
            fig.colorbar(im, ax=ax, label="path gain [dB]")
        im = row[2].imshow(maps["difference_db"], origin="lower", extent=ext, vmin=-6, vmax=6, cmap="RdBu_r")
        row[2].set_title(f"wavepaths - Sionna [dB]: median {r['median_db']:.2f}, std {r['std_db']:.2f}", fontsize=9)
        fig.colorbar(im, ax=row[2], label="dB")
    for ax in axes.ravel():
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()
