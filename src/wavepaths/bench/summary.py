"""What ``bench.json`` holds beside the results: the machine, the headline and the targets.

The job of this module is the summary of a benchmark run, from the results alone:

* :func:`machine_info`: CPU, cores, memory, OS and the versions of everything timed
  (wavepaths, numpy, scipy, embreex, Sionna RT, Mitsuba, Dr.Jit);
* :func:`headline`: the top-level figures of ``bench.json`` (``point_search_ns``,
  ``point_search_speedup``, ``sionna_paths_time_ratio``, ``diffraction_cost_ratio``, ...,
  ``tradeoff_points``) and the targets of issue #7, met, missed or not run;
* ``_json_default``: how numpy values are written to JSON.
"""

from __future__ import annotations

import os

import numpy as np

__all__ = ["headline", "machine_info"]


def machine_info() -> dict:
    """CPU, cores, memory, OS and the versions of everything that is timed."""
    from .._machine import host_versions

    out = host_versions()
    out["openblas_coretype"] = os.environ.get("OPENBLAS_CORETYPE")
    try:
        from importlib.metadata import version

        out["embreex"] = version("embreex")
    except Exception:  # pragma: no cover
        pass
    try:
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
        "point_search_speedup_compiled": ps.get("point_search_speedup_compiled"),
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
