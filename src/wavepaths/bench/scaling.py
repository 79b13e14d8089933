"""Benchmark 4: time and peak memory against receivers, triangles, dihedra and reflection order.

Each point runs in its own child process (:mod:`wavepaths.bench.isolated`), with a time
limit and an address-space limit, so that a point that explodes ends cleanly and its
memory peak is its own. In the child: the scene is loaded, one query warms the scene's
lazy structures (dihedra, BVH) and is reported as ``cold_s``; a second query is timed
(``time_s``), and a third runs under ``tracemalloc`` for the peak of numpy's buffers
(``peak_numpy_bytes``; Embree's BVH is not counted there, the child's resident peak is
given beside it). The path-search counters (``Paths.stats``) come with every point, so
the dominant term can be read off: candidates per stage.

Sweeps:

* receivers: ``simple_street_canyon``, 10 to 3,000 receivers, the default options
  (reflections to order 2, diffraction with one reflection);
* reflection order: the same scene, 100 receivers, ``max_reflections`` 0 to 5 without
  diffraction, then diffraction with 0, 1, 2 reflections on top of order 3;
* triangles and dihedra: squares of growing size cut from Sionna's ``etoile``
  (:func:`wavepaths.bench.scenes.crop_objects`), 100 receivers, first order
  (reflections and diffraction without reflections), and the default options where
  they finish in time;
* occlusion: nanoseconds per segment of the Embree caster, with its compiled set-up and
  confirmation and with the numpy reference, interleaved in one process
  (:func:`occlusion_rates`).
"""

from __future__ import annotations

import os
import time

import numpy as np

from .isolated import run_isolated
from .scenes import STREET_CANYON_TX, street_canyon_receivers


def scaling_point(xml: str, tx, rx, options: dict, measure_memory: bool = True, second_run_max_s: float = 60.0) -> dict:
    """One point of a sweep (runs in a child process)."""
    from ..scene import load_scene
    from ..search import TraceOptions, trace
    from .timing import peak_python_memory

    t0 = time.perf_counter()
    scene = load_scene(xml)
    load_s = time.perf_counter() - t0
    opts = TraceOptions(**options)
    tx = np.asarray(tx, float)
    rx = np.asarray(rx, float)
    t0 = time.perf_counter()
    paths = trace(scene, tx, rx, opts)
    cold_s = time.perf_counter() - t0
    time_s = cold_s
    if cold_s < second_run_max_s:
        t0 = time.perf_counter()
        paths = trace(scene, tx, rx, opts)
        time_s = time.perf_counter() - t0
    peak = None
    if measure_memory and time_s < second_run_max_s:
        _, peak = peak_python_memory(lambda: trace(scene, tx, rx, opts))
    info = scene.summary()
    return {"load_s": load_s, "cold_s": cold_s, "time_s": time_s, "peak_numpy_bytes": peak,
            "num_paths": len(paths), "triangles": info["triangles"], "polygons": info["polygons"],
            "dihedra": info["dihedra"], "diffracting_dihedra": info["diffracting_dihedra"],
            "num_rx": int(len(rx)), "options": options,
            "stats": {k: int(v) for k, v in paths.stats.items()}}


def occlusion_rates(xml: str, n: int = 200_000, rounds: int = 3) -> dict:
    """ns per segment of :meth:`EmbreeRayCaster.occluded`: Embree's half-rays with the numpy
    and the compiled set-up, and the float64 tree (``bvh=True``, the default on scenes of at
    most :data:`~wavepaths.raycast.bvh.BVH_MAX_TRIANGLES` triangles), in one process.

    The segments are the search's kind: from a random point on a random face of the scene
    to a random point of its box at 1.5 m height (a leg to a receiver). The casters are
    timed in alternation, ``rounds`` times, on the same segments. The two Embree forms'
    verdicts are compared (``same_verdicts``), and the tree's and Embree's with the float64
    rule against every triangle (``tree_matches_rule``, ``embree_misses_of_rule``).
    """
    from ..raycast.embree import EmbreeRayCaster, _compiled
    from ..scene import load_scene
    from .timing import interleaved

    scene = load_scene(xml)
    rng = np.random.default_rng(0)
    tri = scene.vertices[scene.triangles[rng.integers(0, len(scene.triangles), n)]]
    a = np.einsum("ki,kij->kj", rng.dirichlet([1, 1, 1], n), tri)
    lo, hi = scene.bounds
    b = np.column_stack([rng.uniform(lo[0], hi[0], n), rng.uniform(lo[1], hi[1], n), np.full(n, 1.5)])
    casters = {"numpy": EmbreeRayCaster(scene, compiled=False)}
    if _compiled() is not None:
        casters["compiled"] = EmbreeRayCaster(scene, compiled=True, bvh=False)
        casters["float64 tree"] = EmbreeRayCaster(scene, bvh=True)
    verdicts = {k: c.occluded(a, b) for k, c in casters.items()}  # warm-up (and the kernels' compilation)
    times = interleaved({k: (lambda c=c: c.occluded(a, b)) for k, c in casters.items()}, rounds)
    out = {"segments": n, "blocked_fraction": float(verdicts["numpy"].mean()),
           "ns_per_segment": {k: t.median_s / n * 1e9 for k, t in times.items()}}
    if "compiled" in casters:
        from ..raycast import canonical

        out["speedup"] = times["numpy"].median_s / times["compiled"].median_s
        out["same_verdicts"] = bool((verdicts["numpy"] == verdicts["compiled"]).all())
        out["tree_speedup_over_compiled"] = times["compiled"].median_s / times["float64 tree"].median_s
        A, B, _ = canonical(a - scene.center, b - scene.center)
        rule = casters["numpy"]._exact.blocked(A, B)
        out["tree_matches_rule"] = bool((verdicts["float64 tree"] == rule).all())
        out["embree_misses_of_rule"] = int((verdicts["compiled"] != rule).sum())
    return out


def _point(xml, tx, rx, options, timeout_s, memory_limit) -> dict:
    r = run_isolated("wavepaths.bench.scaling", "scaling_point",
                     {"xml": xml, "tx": np.asarray(tx), "rx": np.asarray(rx), "options": options},
                     timeout_s=timeout_s, memory_limit_bytes=memory_limit)
    if r["ok"]:
        out = dict(r["result"])
        out["max_rss_bytes"] = r["max_rss_bytes"]
    else:
        out = {"error": r.get("error"), "timed_out": r.get("timed_out", False), "options": options,
               "num_rx": int(len(rx))}
    return out


def dominant_terms(stats: dict, top: int = 5) -> list[tuple[str, int]]:
    """The largest candidate counters of a run (what the time goes into)."""
    keys = [(k, v) for k, v in stats.items() if k.endswith("_candidates") or k.endswith("_receiver_pairs")
            or k == "rays_cast"]
    return sorted(keys, key=lambda kv: -kv[1])[:top]


def log_slope(x, y) -> float | None:
    """Least-squares slope of log y against log x (the empirical exponent)."""
    pairs = [(a, b) for a, b in zip(x, y) if a is not None and b is not None]
    if len(pairs) < 2:
        return None
    x = np.array([a for a, _ in pairs], float)
    y = np.array([b for _, b in pairs], float)
    ok = (x > 0) & (y > 0) & np.isfinite(y)
    if ok.sum() < 2:
        return None
    return float(np.polyfit(np.log(x[ok]), np.log(y[ok]), 1)[0])


def fixed_plus_linear(x, y) -> dict | None:
    """Least-squares ``y = a + b x`` over the finite points, with the local exponent between
    the two largest ``x`` (``log(y2 / y1) / log(x2 / x1)``): one power law fitted over a
    fixed per-query cost reads low, so the report gives both (``docs/benchmarks/bench.json``:
    n^0.48 over 10-3,000 receivers, where this fit gives 9.8 ms plus 53 us per receiver and
    the local exponent is 0.92).

    Returns ``{"fixed_s", "per_item_s", "local_exponent"}`` (None with fewer than 2 points)."""
    x = np.asarray([np.nan if v is None else v for v in x], dtype=float)
    y = np.asarray([np.nan if v is None else v for v in y], dtype=float)
    ok = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
    if ok.sum() < 2:
        return None
    x, y = x[ok], y[ok]
    b, a = np.polyfit(x, y, 1)
    i, j = np.argsort(x)[-2:]
    return {"fixed_s": float(a), "per_item_s": float(b),
            "local_exponent": float(np.log(y[j] / y[i]) / np.log(x[j] / x[i])) if x[j] > x[i] else None}


def run_scaling(out_dir: str, quick: bool = False, timeout_s: float = 300.0, memory_limit: int = 8 << 30,
                progress=print) -> dict:
    """Benchmark 4."""
    from .scenes import sionna_scene_xml

    default = {"max_reflections": 2, "diffraction": True, "diffraction_reflections": 1}
    xml = sionna_scene_xml("simple_street_canyon")
    out: dict = {"memory_limit_bytes": memory_limit, "timeout_s": timeout_s}

    counts = [10, 100, 1000] if quick else [10, 30, 100, 300, 1000, 3000]
    progress("benchmark 4: receivers")
    rows = []
    for n in counts:
        rows.append(_point(xml, STREET_CANYON_TX, street_canyon_receivers(n), default, timeout_s, memory_limit))
    out["receivers"] = {"scene": "simple_street_canyon", "options": default, "points": rows,
                        "time_exponent": log_slope([r["num_rx"] for r in rows], [r.get("time_s") for r in rows]),
                        "time_fixed_plus_linear": fixed_plus_linear([r["num_rx"] for r in rows],
                                                                    [r.get("time_s") for r in rows])}

    progress("benchmark 4: reflection order")
    rx = street_canyon_receivers(100)
    rows = []
    for k in range(0, 4 if quick else 6):
        rows.append(_point(xml, STREET_CANYON_TX, rx, {"max_reflections": k, "diffraction": False},
                           timeout_s, memory_limit))
    for b in range(0, 2 if quick else 3):
        rows.append(_point(xml, STREET_CANYON_TX, rx, {"max_reflections": 3, "diffraction": True,
                                                        "diffraction_reflections": b}, timeout_s, memory_limit))
    out["order"] = {"scene": "simple_street_canyon", "num_rx": 100, "points": rows}

    progress("benchmark 4: occlusion, compiled against numpy")
    r = run_isolated("wavepaths.bench.scaling", "occlusion_rates", {"xml": xml, "n": 50_000 if quick else 200_000},
                     timeout_s=timeout_s, memory_limit_bytes=memory_limit)
    out["occlusion"] = dict(r["result"]) if r["ok"] else {"error": r.get("error")}

    progress("benchmark 4: triangles and dihedra (etoile crops)")
    from ..scene import load_scene, write_mitsuba_xml
    from .scenes import crop_objects, outdoor_points

    full = load_scene(sionna_scene_xml("etoile"))
    halves = [100.0, 150.0] if quick else [100.0, 125.0, 150.0, 200.0, 250.0, 300.0, 450.0]
    first_order = {"max_reflections": 1, "diffraction": True, "diffraction_reflections": 0}
    rows_first, rows_default = [], []
    give_up_default = False
    for half in halves:
        crop = crop_objects(full, (0.0, 0.0), half)
        path = os.path.join(out_dir, "scenes", f"etoile_{int(2 * half)}m", f"etoile_{int(2 * half)}m.xml")
        if not os.path.exists(path):
            write_mitsuba_xml(crop, path)
        rng = np.random.default_rng(0)
        pts = np.column_stack([rng.uniform(-half, half, 800), rng.uniform(-half, half, 800), np.full(800, 1.5)])
        rxs = pts[outdoor_points(crop, pts)][:100]
        tx = np.array([[3.0, 1.0, 25.0]])
        info = crop.summary()
        size = {"square_m": 2 * half, "triangles": info["triangles"], "polygons": info["polygons"],
                "diffracting_dihedra": info["diffracting_dihedra"]}
        progress(f"  {2 * half:g} m square: {crop.num_triangles} triangles")
        r = _point(path, tx, rxs, first_order, timeout_s, memory_limit)
        rows_first.append({**size, **r})
        if not give_up_default and not quick:
            r = _point(path, tx, rxs, default, timeout_s, memory_limit)
            rows_default.append({**size, **r})
            give_up_default = "error" in r
    tri = [r.get("triangles") for r in rows_first]
    out["triangles"] = {
        "scene": "etoile crops", "first_order": {"options": first_order, "points": rows_first,
                                                 "time_exponent_triangles": log_slope(tri, [r.get("time_s") for r in rows_first]),
                                                 "time_exponent_dihedra": log_slope([r.get("diffracting_dihedra") for r in rows_first],
                                                                                    [r.get("time_s") for r in rows_first])},
        "default": {"options": default, "points": rows_default,
                    "time_exponent_triangles": log_slope([r.get("triangles") for r in rows_default],
                                                         [r.get("time_s") for r in rows_default])},
    }
    out["analysis"] = _analysis(out)
    return out


def _analysis(out: dict) -> str:
    """What the sweeps say, in words: exponents, growth per order, the dominant counters."""
    parts = []
    e = out["receivers"]["time_exponent"]
    if e is not None:
        fit = out["receivers"].get("time_fixed_plus_linear")
        if fit and fit["local_exponent"] is not None:
            parts.append(f"Receivers: one power law fits n^{e:.2f}, but the time is a fixed cost plus a linear part "
                         f"({1e3 * fit['fixed_s']:.1f} ms + {1e6 * fit['per_item_s']:.1f} us per receiver); between "
                         f"the two largest counts it grows as n^{fit['local_exponent']:.2f}.")
        else:
            parts.append(f"Receivers: time grows as n^{e:.2f} (fixed per-query costs at small n, linear beyond).")
    refl = [r for r in out["order"]["points"] if not r.get("options", {}).get("diffraction") and "time_s" in r]
    if len(refl) >= 3:
        growth = [b["time_s"] / a["time_s"] for a, b in zip(refl[1:], refl[2:])]
        parts.append(f"Reflection order: each order multiplies the time by {', '.join(f'{g:.1f}' for g in growth)} "
                     "(the order-k candidates, receivers x images of order k, grow about 7x per order here).")
    t = out["triangles"]
    e1 = t["first_order"]["time_exponent_triangles"]
    e2 = t["default"]["time_exponent_triangles"]
    if e1 is not None:
        parts.append(f"Triangles, first order: time ~ T^{e1:.2f}.")
    if e2 is not None:
        parts.append(f"Triangles, R2+D1: time ~ T^{e2:.2f}; the largest counters are the diffraction receiver pairs "
                     "(receiver images x dihedra, both growing with T) and the candidates of the join with the "
                     "transmitter's images, so diffraction with reflections dominates: its pair counts grow as T^2 per "
                     "receiver, the culling tests keep the time's growth near the fitted exponent.")
    failed = [r for r in t["default"]["points"] if "error" in r]
    if failed:
        r = failed[0]
        parts.append(f"R2+D1 stopped at {r.get('triangles')} triangles: {r['error']}.")
    return " ".join(parts)
