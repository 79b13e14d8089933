"""Benchmark 3: run time against error, for coverage maps and path queries, both engines.

The knobs that trade speed for accuracy:

* wavepaths: the reflection order, whether diffraction is traced and with how many
  reflections, diffraction in the incident shadow only (``lit_region=False``), the
  pruning tolerance ``prune_db`` (reflected paths that a stated bound puts that far below
  free space are dropped; :class:`~wavepaths.search.TraceOptions`), for maps the tolerance
  ``tolerance_db`` (diffracted contributions that cannot change a cell's power-sum total by
  more than that), and, for maps, how many
  receivers per cell (``s x s`` sub-cells averaged, since Sionna's map is a cell
  average). wavepaths computes in float64 only (Embree casts in float32 with float64
  re-casts near boundaries), so a float32 knob does not exist.
* Sionna RT: ``samples_per_tx`` (maps) and ``samples_per_src`` (paths), the number of
  rays it shoots; it computes in float32 only.

The quantity compared is the one Sionna's radio map gives: the incoherent (power-sum)
path gain, cell-averaged for maps, per receiver for path queries, in dB, with Sionna's
coefficient model on the wavepaths side (``FieldConfig(compat="sionna")``) so that both
converge to the same numbers where they find the same paths.

Error: the mean absolute difference in dB over the cells (receivers) that the reference
reaches and whose centre lies outside buildings, both maps floored at the reference's 1st
percentile, so that a cell a fast setting does not reach at all counts as a large error
rather than being left out. The fraction of reference cells not reached and the median
error are reported beside it.

References ("converged"):

* common reference: wavepaths with every path of Sionna's depth (reflections to order 3,
  diffraction with up to 2 reflections), ``s x s`` sub-cells (3 x 3 in the full run);
  both curves are measured against it, and ``verdict`` asks whether every Sionna point is
  beaten by a wavepaths point both faster and closer to it. The reference is one of
  wavepaths' own settings (error 0 by construction), which favours wavepaths wherever the
  two engines' converged answers differ (``reference_vs_sionna_limit``);
* Sionna's own limit: its map (paths) at the largest sample count run; Sionna's curve
  against it is reported too (its self-convergence), since part of its distance to the
  common reference is a model difference (``docs/validation``: D-R coefficients that
  depend on ``max_depth``; paths its sampling never finds), not sampling noise.
  ``verdict_self_convergence`` asks the same question with each engine against its own
  limit, a comparison that favours neither engine's model.

Timing: wavepaths' time is the wall time of :func:`wavepaths.coverage.coverage` (scene
loaded before; one warm-up map first) or of trace + fields; Sionna's is its timed call
after a warm-up call in the same process.
"""

from __future__ import annotations

import time

import numpy as np

from ..fields.result import power_db
from .scenes import STREET_CANYON_TX, street_canyon_receivers

FREQUENCY_HZ = 3.5e9

# (label, max_reflections, diffraction, diffraction_reflections[, other TraceOptions fields])
# "shadow": diffracted paths only where the incident field is shadowed (lit_region=False), the
# cheapest way to light the cells reflections leave dark; UTD's total field is then not
# continuous across the shadow boundaries, which the error shows. "prune x dB": reflected
# paths a stated bound puts x dB below free space are dropped (prune_db). "tol x dB":
# diffracted contributions are dropped, weakest first, while no cell's power-sum total changes
# by more than x dB (tolerance_db).
WAVEPATHS_SETTINGS = [
    ("R1", 1, False, 0),
    ("R2", 2, False, 0),
    ("R3", 3, False, 0),
    ("R3 prune 20 dB", 3, False, 0, {"prune_db": 20.0}),
    ("R0+D shadow", 0, True, 0, {"lit_region": False}),
    ("R0+D", 0, True, 0),
    ("R1+D", 1, True, 0),
    ("R2+D", 2, True, 0),
    ("R2+D1", 2, True, 1),
    ("R3+D1", 3, True, 1),
    ("R2+D1 tol 0.1 dB", 2, True, 1, {"tolerance_db": 0.1}),
    ("R3+D2 tol 0.1 dB", 3, True, 2, {"tolerance_db": 0.1}),
    ("R3+D2 prune 10 dB", 3, True, 2, {"prune_db": 10.0}),
    ("R3+D2 prune 20 dB", 3, True, 2, {"prune_db": 20.0}),
    ("R3+D2", 3, True, 2),
]
QUICK_SETTINGS = ("R1", "R2", "R0+D shadow", "R0+D", "R1+D", "R2+D", "R2+D1", "R3+D1", "R3+D2 prune 20 dB")


MAP_ONLY_OPTIONS = frozenset({"tolerance_db"})
"""Options only coverage maps have (they need the fields of the other paths)."""


def path_query_settings() -> list[tuple]:
    """The entries of :data:`WAVEPATHS_SETTINGS` a path query can run (no map-only option)."""
    return [x for x in WAVEPATHS_SETTINGS if not (len(x) > 4 and MAP_ONLY_OPTIONS & set(x[4]))]


def trace_options(setting: tuple):
    """The :class:`~wavepaths.search.TraceOptions` of one entry of :data:`WAVEPATHS_SETTINGS`."""
    from ..search import TraceOptions

    _, mr, diff, dr, *other = setting
    return TraceOptions(max_reflections=mr, diffraction=diff, diffraction_reflections=dr, **(other[0] if other else {}))


def map_error(value_db: np.ndarray, reference_db: np.ndarray, valid: np.ndarray) -> dict:
    """Error of a path-gain map (or receiver vector) against a reference [dB].

    Parameters
    ----------
    value_db, reference_db : same shape, float64 [dB]; ``-inf`` where nothing arrives.
    valid : bool mask of the cells to compare (outside buildings).
    """
    ref_ok = valid & np.isfinite(reference_db)
    if not ref_ok.any():
        return {"mean_abs_db": None, "median_abs_db": None, "missed_fraction": None, "cells": 0}
    ref = reference_db[ref_ok]
    val = value_db[ref_ok]
    floor = float(np.percentile(ref, 1))
    val_c = np.where(np.isfinite(val), np.maximum(val, floor), floor)
    ref_c = np.maximum(ref, floor)
    d = np.abs(val_c - ref_c)
    reached = np.isfinite(val)
    return {"mean_abs_db": float(d.mean()), "median_abs_db": float(np.median(d)),
            "p90_abs_db": float(np.percentile(d, 90)),
            "median_abs_db_reached": float(np.median(np.abs(val[reached] - ref[reached]))) if reached.any() else None,
            "missed_fraction": float(1.0 - reached.mean()), "cells": int(ref_ok.sum()), "floor_db": floor}


def _block_mean(power: np.ndarray, s: int) -> np.ndarray:
    """(ny, nx) mean of (ny*s, nx*s) over s x s blocks, NaN (inside buildings) left out."""
    ny, nx = power.shape[0] // s, power.shape[1] // s
    blocks = power.reshape(ny, s, nx, s)
    with np.errstate(invalid="ignore"):
        return np.nanmean(blocks, axis=(1, 3)) if np.isnan(blocks).any() else blocks.mean(axis=(1, 3))


def wavepaths_map(scene, grid_spec: dict, setting: tuple, sub: int = 1, workers: int = 1) -> tuple[np.ndarray, float]:
    """(cell-averaged incoherent path gain (ny, nx) linear, wall time [s]) of one wavepaths map."""
    import warnings

    from ..coverage import CoverageOptions, PlanarGrid, coverage
    from ..fields import FieldConfig

    grid = PlanarGrid(center=grid_spec["center"][:2], height=grid_spec["center"][2], size=grid_spec["size"],
                      cell_size=grid_spec["cell_size"] / sub)
    opts = trace_options(setting)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # nanmean of all-NaN blocks (cells inside buildings)
        m = coverage(scene, STREET_CANYON_TX, grid, opts, fields=FieldConfig(FREQUENCY_HZ, "utd", "sionna"),
                     settings=CoverageOptions(workers=workers, coherent=False))
        elapsed = time.perf_counter() - t0
        power = m.path_gain(coherent=False)
        return _block_mean(power, sub), elapsed



def run_map_tradeoff(quick: bool = False, workers: int = 1, progress=print) -> dict:
    """The coverage-map half of benchmark 3, on ``simple_street_canyon``."""
    from ..scene import load_scene
    from ..validation.sionna_env import sionna_version
    from .scenes import sionna_scene_xml

    xml = sionna_scene_xml("simple_street_canyon")
    scene = load_scene(xml)
    cell = 8.0 if quick else 4.0
    spec = {"center": np.array([0.0, 0.0, 1.5]), "size": np.array([176.0, 120.0]), "cell_size": cell}
    ref_sub = 2 if quick else 3
    settings = WAVEPATHS_SETTINGS if not quick else [x for x in WAVEPATHS_SETTINGS if x[0] in QUICK_SETTINGS]
    progress(f"benchmark 3 (maps): wavepaths reference, {ref_sub}x{ref_sub} sub-cells of {cell:g} m cells")
    centre_map, _ = wavepaths_map(scene, spec, settings[0], 1, workers)  # warm-up
    ref_lin, ref_time = wavepaths_map(scene, spec, WAVEPATHS_SETTINGS[-1], ref_sub, workers)
    ref_db = power_db(ref_lin)
    # compare the cells whose centre lies outdoors (NaN: inside a building), the cells a
    # map of cell-centre receivers defines; a cell cut by a wall is averaged over its
    # outdoor sub-cells in the reference
    valid = ~np.isnan(centre_map)
    wp_points = []
    for setting in settings:
        for sub in ((1,) if setting != WAVEPATHS_SETTINGS[-1] else ((1, 2) if not quick else (1,))):
            lin, el = wavepaths_map(scene, spec, setting, sub, workers)
            err = map_error(power_db(lin), ref_db, valid)
            wp_points.append({"label": f"{setting[0]}" + (f" {sub}x{sub}" if sub > 1 else ""), "time_s": el,
                              "error": err})
            progress(f"  wavepaths {wp_points[-1]['label']}: {el:.2f} s, {err['mean_abs_db']:.2f} dB")
    out = {"scene": "simple_street_canyon", "tx": STREET_CANYON_TX.tolist(),
           "grid": {"center": spec["center"].tolist(), "size": spec["size"].tolist(), "cell_size_m": cell,
                    "shape": list(ref_lin.shape)},
           "reference": {"engine": "wavepaths", "setting": WAVEPATHS_SETTINGS[-1][0], "sub_cells": ref_sub,
                         "time_s": ref_time},
           "wavepaths_workers": workers, "wavepaths": wp_points}
    if sionna_version() is None:
        out["sionna"] = {"skipped": "Sionna RT is not installed"}
        return out
    from ..validation.sionna_runner import run_sionna_radio_map

    samples = [10**4, 10**5, 10**6] if quick else [10**4, 10**5, 10**6, 10**7]
    limit = 10**7 if quick else 10**8
    sn_maps = []
    for n in samples + [limit]:
        progress(f"  Sionna radio map, {n:.0e} samples")
        rm = run_sionna_radio_map(xml, STREET_CANYON_TX[0], center=spec["center"], size=spec["size"],
                                  cell_size=[cell, cell], orientation=[0, 0, 0], frequency_hz=FREQUENCY_HZ,
                                  max_depth=3, diffraction=True, edge_diffraction=True, samples_per_tx=n,
                                  warmup=n != limit)
        if rm.path_gain.shape != ref_lin.shape:
            raise RuntimeError(f"Sionna's map has shape {rm.path_gain.shape}, wavepaths' {ref_lin.shape}")
        sn_maps.append((n, rm))
    sn_limit_db = sn_maps[-1][1].path_gain_db
    sn_points = []
    for n, rm in sn_maps:
        sn_points.append({"label": f"{n:.0e} samples", "samples_per_tx": n, "time_s": rm.elapsed_s,
                          "warmup_s": rm.warmup_s, "timed_after_warmup": n != limit,
                          "error": map_error(rm.path_gain_db, ref_db, valid),
                          "error_vs_own_limit": map_error(rm.path_gain_db, sn_limit_db, valid) if n != limit else None})
    centre_offset = float(np.abs(sn_maps[-1][1].cell_centers[..., :2]
                                 - _grid_centres(spec, ref_lin.shape)[..., :2]).max())
    out["sionna"] = {"points": sn_points, "limit_samples": limit, "cell_centre_mismatch_m": centre_offset,
                     # how far apart the two engines' converged answers are: model differences, not sampling
                     "reference_vs_sionna_limit": map_error(ref_db, sn_limit_db, valid)}
    out["verdict"] = _dominates(wp_points, sn_points)
    out["verdict_self_convergence"] = _dominates(wp_points, sn_points, "error_vs_own_limit")
    return out


def _grid_centres(spec: dict, shape) -> np.ndarray:
    from ..coverage import PlanarGrid

    g = PlanarGrid(center=spec["center"][:2], height=spec["center"][2], size=spec["size"],
                   cell_size=spec["cell_size"])
    return g.cell_centers()


def _dominates(wp_points: list[dict], sn_points: list[dict], key: str = "error") -> dict:
    """Is every Sionna point beaten by some wavepaths point (faster and at most as wrong)?

    Also: the lowest wavepaths error reached within each Sionna point's time. ``key`` is the
    Sionna points' error: ``"error"`` (against the common reference, wavepaths' converged
    answer) or ``"error_vs_own_limit"`` (each engine against its own limit: wavepaths' points
    are measured against its own converged answer already); points without it are left out.
    """
    rows = []
    for s in sn_points:
        if not s.get(key):
            continue
        se = s[key]["mean_abs_db"]
        best = [w["error"]["mean_abs_db"] for w in wp_points if w["time_s"] <= s["time_s"]]
        best_err = min(best) if best else None
        rows.append({"sionna": s["label"], "sionna_time_s": s["time_s"], "sionna_error_db": se,
                     "best_wavepaths_error_db_within_that_time": best_err,
                     "wavepaths_better": best_err is not None and se is not None and best_err <= se})
    return {"every_sionna_point_beaten": all(r["wavepaths_better"] for r in rows), "rows": rows}


def _gain_per_rx(rx_index: np.ndarray, a: np.ndarray, n: int) -> np.ndarray:
    return np.bincount(rx_index, np.abs(a) ** 2, n)


def run_path_tradeoff(quick: bool = False, n_rx: int = 100, progress=print) -> dict:
    """The path-query half of benchmark 3 (street canyon, 100 receivers)."""
    from ..fields import FieldConfig, compute_fields
    from ..scene import load_scene
    from ..search import trace
    from ..validation.sionna_env import sionna_version
    from .scenes import sionna_scene_xml

    xml = sionna_scene_xml("simple_street_canyon")
    scene = load_scene(xml)
    rx = street_canyon_receivers(n_rx)
    cfg = FieldConfig(FREQUENCY_HZ, "utd", "sionna")
    valid = np.ones(n_rx, bool)

    def query(setting):
        opts = trace_options(setting)
        t0 = time.perf_counter()
        p = trace(scene, STREET_CANYON_TX, rx, opts)
        f = compute_fields(scene, p, cfg)
        return p, f, time.perf_counter() - t0

    query(WAVEPATHS_SETTINGS[0])  # warm-up
    ref_p, ref_f, _ = query(WAVEPATHS_SETTINGS[-1])
    ref_db = power_db(_gain_per_rx(ref_p.rx_index, ref_f.a, n_rx))
    wp_points = []
    for setting in path_query_settings():
        times = []
        for _ in range(1 if quick else 3):
            p, f, el = query(setting)
            times.append(el)
        err = map_error(power_db(_gain_per_rx(p.rx_index, f.a, n_rx)), ref_db, valid)
        err["paths_found_fraction"] = len(p) / len(ref_p)
        wp_points.append({"label": setting[0], "time_s": float(np.median(times)), "num_paths": len(p), "error": err})
    out = {"scene": "simple_street_canyon", "num_rx": n_rx, "reference": {"engine": "wavepaths",
           "setting": WAVEPATHS_SETTINGS[-1][0], "num_paths": len(ref_p)}, "wavepaths": wp_points}
    if sionna_version() is None:
        out["sionna"] = {"skipped": "Sionna RT is not installed"}
        return out
    from ..validation.sionna_runner import run_sionna_paths

    samples = [10**4, 10**5, 10**6] if quick else [10**4, 10**5, 10**6, 10**7]
    sn_points = []
    runs = []
    for n in samples:
        progress(f"  Sionna paths, {n:.0e} samples per source")
        sn = run_sionna_paths(xml, STREET_CANYON_TX, rx, frequency_hz=FREQUENCY_HZ, max_depth=3, diffraction=True,
                              edge_diffraction=True, samples_per_src=n, warmup=n < 10**7)
        runs.append((n, sn))
    own = power_db(_gain_per_rx(runs[-1][1].rx_index, runs[-1][1].a, n_rx))
    for n, sn in runs:
        g = power_db(_gain_per_rx(sn.rx_index, sn.a, n_rx))
        err = map_error(g, ref_db, valid)
        err["paths_found_fraction"] = sn.num_paths / len(ref_p)
        sn_points.append({"label": f"{n:.0e} samples", "samples_per_src": n, "time_s": sn.elapsed_s,
                          "timed_after_warmup": n < 10**7, "num_paths": sn.num_paths, "error": err,
                          "error_vs_own_limit": map_error(g, own, valid) if n != samples[-1] else None})
    out["sionna"] = {"points": sn_points, "reference_vs_sionna_limit": map_error(ref_db, own, valid)}
    out["verdict"] = _dominates(wp_points, sn_points)
    out["verdict_self_convergence"] = _dominates(wp_points, sn_points, "error_vs_own_limit")
    return out


def run_tradeoff(quick: bool = False, workers: int = 1, progress=print) -> dict:
    """Benchmark 3: maps and path queries."""
    progress("benchmark 3: path queries")
    paths = run_path_tradeoff(quick, progress=progress)
    progress("benchmark 3: coverage maps")
    maps = run_map_tradeoff(quick, workers, progress=progress)
    return {"maps": maps, "paths": paths,
            "error_metric": "mean |dB difference| of the incoherent path gain over the cells (receivers) that the "
                            "reference reaches and whose centre is outside buildings, both floored at the "
                            "reference's 1st percentile (a cell not reached counts as reference minus floor)"}
