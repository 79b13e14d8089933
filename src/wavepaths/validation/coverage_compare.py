"""Coverage maps of both engines on the same scene, transmitter and grid.

Sionna RT's ``RadioMapSolver`` gives a cell-averaged, power-summed path gain estimated by
shooting rays (Monte Carlo); wavepaths evaluates every path exactly at each cell centre,
here power-summed too (``CoverageOptions(coherent=False)``). Statistics are taken over cells
where both maps are above a noise floor and outside objects.

The two maps differ for four reasons, which :func:`compare_coverage` separates (its
``decomposition``), each measured in the same run:

1. Sionna's sampling noise: the std of two of its maps with different seeds, over sqrt(2).
   Without diffraction its rays leave on a fixed lattice and the seed changes nothing; with
   it, cells lit mostly by diffraction get a few diffracted samples each.
2. Cell averaging: Sionna averages the power over the cell, a part inside a building counting
   as zero; wavepaths samples the centre. wavepaths averaged over ``SUBSAMPLES`` x
   ``SUBSAMPLES`` points of each cell, inside points as zero, removes it.
3. The path set: Sionna's radio map diffracts only from the transmitter to an edge to the
   cell (no reflection before or after), while wavepaths' map has R-D and D-R paths too.
4. The diffraction coefficient: Sionna's combination, which the boundary lines judge
   against the exact solutions (:mod:`wavepaths.validation.known`).

With the last two matched (``compat="sionna"``, ``diffraction_reflections=0``), wavepaths
averaged over each cell must agree with Sionna at ``REFERENCE_FACTOR`` times the samples
within :data:`LIKE_FOR_LIKE_TOLERANCES`: the like-for-like verdict of the coverage maps.
"""

from __future__ import annotations

import time

import numpy as np

from ..coverage import CoverageOptions, PlanarGrid, coverage
from ..fields import FieldConfig
from ..fields.result import power_db
from ..scene import load_scene
from ..search import TraceOptions

NOISE_FLOOR_DB = -160.0
SUBSAMPLES = 8  # wavepaths points per cell side for the cell-averaged maps
REFERENCE_FACTOR = 10  # Sionna's samples for the low-noise reference, times samples_per_tx
# like for like (same paths, Sionna's coefficient, cell-averaged, against Sionna at 10x samples):
# measured std 0.56 dB (4 m cells) and 0.73 dB (2 m), median within 0.1 dB (thirtieth session)
LIKE_FOR_LIKE_TOLERANCES = {"std_db": 1.5, "abs_median_db": 0.5}



def _field_gain(cm) -> np.ndarray:
    """(ny, nx) the power of the field at each cell over both polarisations (``sum |e|^2``,
    :meth:`~wavepaths.coverage.CoverageMap.field_gain_per_tx`), normalised like the path gain:
    Sionna's radio map takes the squared norm of the whole field, "an ideal isotropic receiver",
    where wavepaths' path gain would be the co-polarised power of the V receive antenna."""
    return cm.field_gain_per_tx(coherent=False)[0]


def _cell_average(gain: np.ndarray, inside: np.ndarray, k: int) -> np.ndarray:
    """(ny, nx) linear gain averaged over each cell's k x k sub-cells of ``gain`` (ny k, nx k), a
    sub-cell inside an object counting as zero (as Sionna divides by the whole cell's area); NaN
    where every sub-cell is inside."""
    ny, nx = gain.shape[0] // k, gain.shape[1] // k
    g = np.where(inside, 0.0, np.nan_to_num(gain, nan=0.0)).reshape(ny, k, nx, k).mean(axis=(1, 3))
    return np.where(inside.reshape(ny, k, nx, k).all(axis=(1, 3)), np.nan, g)


def _stats(a_db: np.ndarray, b_db: np.ndarray, mask: np.ndarray) -> dict:
    """std and median of ``a_db - b_db`` over ``mask`` and the cells where both are above the floor."""
    m = mask & np.isfinite(a_db) & np.isfinite(b_db) & (a_db > NOISE_FLOOR_DB) & (b_db > NOISE_FLOOR_DB)
    d = a_db[m] - b_db[m]
    return {"std_db": float(d.std()) if len(d) else None, "median_db": float(np.median(d)) if len(d) else None,
            "cells": int(m.sum())}


def compare_coverage(scene_xml: str, tx, center, size, cell: float, max_depth: int, frequency_hz: float = 3.5e9,
                     samples_per_tx: int = 1_000_000) -> dict:
    """Run both engines with and without diffraction; return maps, differences, timings and the
    decomposition of their difference (module docstring).

    Returns
    -------
    dict
        The settings, and ``runs``: ``"no_diffraction"`` / ``"diffraction"`` -> the maps
        (``wavepaths_db``, ``sionna_db``, ``difference_db``; (ny, nx) dB), the statistics of the
        difference over the compared cells, the timings, ``decomposition`` (``sionna_seed_noise_db``,
        ``rows``: the difference's ``std_db``, ``median_db`` and ``cells`` for each pair of maps
        named by ``wavepaths`` and ``sionna``) and ``like_for_like`` (``std_db``, ``median_db``,
        ``cells``, ``tolerances``, ``passed``).
    """
    from .sionna_runner import run_sionna_radio_map

    scene = load_scene(scene_xml)
    tx = np.asarray(tx, dtype=float).reshape(1, 3)
    out = {"scene": scene_xml, "tx": tx[0].tolist(), "center": list(center), "size": list(size), "cell_m": cell,
           "max_depth": max_depth, "noise_floor_db": NOISE_FLOOR_DB, "frequency_hz": frequency_hz,
           "samples_per_tx": samples_per_tx,
           "antennas": "transmitter isotropic, V (Sionna's default); no receive antenna (the whole field)",
           "field_model": "wavepaths: UTD (textbook), power sum at the cell centres, the field's power over both "
                          "polarisations; Sionna: RadioMapSolver, cell-averaged power of the whole field (an ideal "
                          "isotropic receiver)", "subsamples": SUBSAMPLES, "reference_factor": REFERENCE_FACTOR,
           "runs": {}}
    for diffraction in (False, True):
        def sionna(samples: int, seed: int = 1):
            return run_sionna_radio_map(scene_xml, tx[0], center, size, (cell, cell), (0.0, 0.0, 0.0), frequency_hz,
                                        max_depth, diffraction, samples, seed=seed)

        sn = sionna(samples_per_tx)
        ny, nx = sn.path_gain_db.shape
        grid = PlanarGrid(center=np.asarray(center, float), size=(nx * cell, ny * cell), cell_size=cell)
        opts = TraceOptions(max_reflections=max_depth, diffraction=diffraction,
                            diffraction_reflections=max(max_depth - 1, 0))
        t0 = time.perf_counter()
        cm = coverage(scene, tx, grid, opts, fields=FieldConfig(frequency_hz),
                      settings=CoverageOptions(coherent=False, workers=1))
        wp_time = time.perf_counter() - t0
        wp_db = power_db(_field_gain(cm))
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
            "cells_sionna_inside_objects": int((np.isfinite(sn.path_gain_db) & (sn.path_gain_db > NOISE_FLOOR_DB)
                                                & cm.inside).sum()),
        }
        out["runs"]["diffraction" if diffraction else "no_diffraction"].update(
            _decomposition(scene, tx, grid, opts, frequency_hz, sionna, samples_per_tx, wp_db, sn.path_gain_db, both))
    return out


def _decomposition(scene, tx, grid, opts, frequency_hz, sionna, samples, wp_db, sn_db, compared) -> dict:
    """The four reasons of the module docstring, measured: the ``decomposition`` and
    ``like_for_like`` entries of a run (:func:`compare_coverage`)."""
    fine = PlanarGrid(center=grid.center, size=grid.size, cell_size=grid.cell_size / SUBSAMPLES)
    settings = CoverageOptions(coherent=False, workers=1)

    def averaged(options, field_config):
        m = coverage(scene, tx, fine, options, fields=field_config, settings=settings)
        if m.inside.shape != (SUBSAMPLES * len(compared), SUBSAMPLES * compared.shape[1]):
            raise ValueError(f"the sub-sampled grid {m.inside.shape} does not tile the cells {compared.shape}")
        return power_db(_cell_average(_field_gain(m), m.inside, SUBSAMPLES))

    n_ref = f"{REFERENCE_FACTOR * samples:,} samples"
    centre, cell_avg = "at the cell centres, textbook UTD", f"averaged over {SUBSAMPLES} x {SUBSAMPLES} points per cell"
    second = power_db(sionna(samples, seed=2).path_gain)
    reference = power_db(sionna(REFERENCE_FACTOR * samples).path_gain)
    t0 = time.perf_counter()
    textbook = averaged(opts, FieldConfig(frequency_hz))
    compat = FieldConfig(frequency_hz, "utd", "sionna")
    if opts.diffraction:
        first_order = TraceOptions(max_reflections=opts.max_reflections, diffraction=True, diffraction_reflections=0)
        like = averaged(first_order, compat)
        # each of the two model differences alone
        alone = [(f"{cell_avg}, compat='sionna', with reflections before and after a diffraction", averaged(opts, compat)),
                 (f"{cell_avg}, textbook UTD, no reflection before or after a diffraction",
                  averaged(first_order, FieldConfig(frequency_hz)))]
    else:
        like, alone = textbook, []  # no diffracted path: the coefficient and the path set are the same
    elapsed = time.perf_counter() - t0
    noise = _stats(sn_db, second, compared)
    matched = f"{cell_avg}, compat='sionna', no reflection before or after a diffraction (Sionna's radio map's paths)"
    rows = [("wavepaths " + centre, f"Sionna, {samples:,} samples", wp_db, sn_db),
            ("wavepaths " + centre, f"Sionna, {n_ref}", wp_db, reference),
            ("wavepaths " + cell_avg + ", textbook UTD", f"Sionna, {n_ref}", textbook, reference),
            *[("wavepaths " + w, f"Sionna, {n_ref}", a, reference) for w, a in alone],
            ("wavepaths " + matched, f"Sionna, {samples:,} samples", like, sn_db),
            ("wavepaths " + matched, f"Sionna, {n_ref}", like, reference)]
    like_stats = _stats(like, reference, compared)
    shown = compared & np.isfinite(like) & np.isfinite(reference) & (like > NOISE_FLOOR_DB) & (reference > NOISE_FLOOR_DB)
    like_difference = np.full(like.shape, np.nan)
    like_difference[shown] = like[shown] - reference[shown]
    tol = LIKE_FOR_LIKE_TOLERANCES
    passed = (like_stats["std_db"] is not None and like_stats["std_db"] <= tol["std_db"]
              and abs(like_stats["median_db"]) <= tol["abs_median_db"])
    return {"decomposition": {
                "sionna_seed_noise_db": None if noise["std_db"] is None else noise["std_db"] / np.sqrt(2),
                "rows": [{"wavepaths": w, "sionna": sname, **_stats(a, b, compared)} for w, sname, a, b in rows],
                "wavepaths_cell_averaged_time_s": elapsed},
            "like_for_like": {**like_stats, "tolerances": dict(tol), "passed": bool(passed),
                              "difference_db": like_difference}}


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
    like = any("difference_db" in r.get("like_for_like", {}) for r in runs.values())
    fig, axes = plt.subplots(len(runs), 3 + like, figsize=(15 + 5 * like, 3.6 * len(runs)), squeeze=False)
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
        if like:
            ll = r["like_for_like"]
            im = row[3].imshow(np.asarray(ll["difference_db"], dtype=float), origin="lower", extent=ext, vmin=-6,
                               vmax=6, cmap="RdBu_r")
            row[3].set_title(f"like for like - Sionna x{result.get('reference_factor', 10)} samples: median "
                             f"{ll['median_db']:.2f}, std {ll['std_db']:.2f}", fontsize=9)
            fig.colorbar(im, ax=row[3], label="dB")
    for ax in axes.ravel():
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()
