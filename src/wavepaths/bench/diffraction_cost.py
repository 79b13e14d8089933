"""Benchmark 5: the cost of diffraction, the same coverage map with diffraction off and on.

The seed (§4) rendered its image 46 times slower with diffraction than without (270
polygons, 378 dihedra). Here: a coverage map of ``simple_street_canyon`` (2 m cells at
1.5 m height, 88 x 60 cells, the cells inside buildings masked), with reflections and
without diffraction, then the same reflections plus diffraction:

* ``R2 / R2+D1`` (the headline, ``diffraction_cost_ratio``): reflections to order 2,
  then diffraction with one reflection before or after it (R-D, D-R) added, the
  default options of :func:`wavepaths.coverage.coverage`;
* ``R2 / R2+D0``: the seed's own case ("one diffraction between two fixed points", §4):
  the diffracted paths E-D-R only, no reflection before or after the edge;
* ``R2 / R2+D2``: diffraction with up to two reflections (also R-D-R, R-R-D, D-R-R);
* ``R3 / R3+D2``: Sionna's depth 3 (benchmark 2's path types);
* ``R2 / R2+D1 tol 0.1 dB``: the headline pair with ``tolerance_db=0.1`` (diffracted
  contributions that cannot change a cell's power-sum total by more than 0.1 dB dropped
  before their casts and fields).

The two maps of a pair are timed in alternation, ``repeats`` times each (the headline pair
:data:`HEADLINE_ROUNDS` times), and the ratio of medians is reported. One process
(``workers=1``), its tiles on the threads the machine's cores give
(``CoverageOptions.threads``' default, as :func:`wavepaths.coverage.coverage` runs a map
this small by default); the headline pair again on one thread beside it
(``diffraction_cost_ratio_one_thread``: the tiles on the calling thread and numba's
kernels on one thread too; before the twenty-fifth session the calling thread's field
kernels still used numba's two): diffraction's work releases the GIL and gains
from the second core, the map without diffraction hardly does. Beside it, what a path
costs: the map without diffraction per path it finds (``us_per_path_off``), the time
diffraction adds per diffracted path (``us_per_diffracted_path``), and how many more paths
the map with diffraction holds (``paths_ratio``): the time ratio is about the paths ratio
times the ratio of those per-path costs. And where the headline pair's time goes (``stages``): both
maps once more under cProfile, on one thread (the profiler sees only its own thread),
split into the stages of :data:`STAGES` (the profiler inflates Python calls: read the
shares).
"""

from __future__ import annotations


import numpy as np

from ..search import kernels
from .scenes import STREET_CANYON_TX
from .timing import interleaved

SEED_RATIO = 46.0
HEADLINE_ROUNDS = 9
"""Rounds of the headline pair and of the seed's case (on the default threads and on one
thread): their R2 map takes about 0.03 s, where a busy host moves a median of three by
20-30 % (the seed's case came out at 2.45x in three rounds whose R2 map ran 0.030 s against
0.024 s in the headline pair's nine)."""
PAIRS = [
    ("R2", {"max_reflections": 2, "diffraction": False}, "R2+D1",
     {"max_reflections": 2, "diffraction": True, "diffraction_reflections": 1}),
    ("R2", {"max_reflections": 2, "diffraction": False}, "R2+D0",
     {"max_reflections": 2, "diffraction": True, "diffraction_reflections": 0}),
    ("R2", {"max_reflections": 2, "diffraction": False}, "R2+D2",
     {"max_reflections": 2, "diffraction": True, "diffraction_reflections": 2}),
    ("R3", {"max_reflections": 3, "diffraction": False}, "R3+D2",
     {"max_reflections": 3, "diffraction": True, "diffraction_reflections": 2}),
    ("R2", {"max_reflections": 2, "diffraction": False}, "R2+D1 tol 0.1 dB",
     {"max_reflections": 2, "diffraction": True, "diffraction_reflections": 1, "tolerance_db": 0.1}),
]


# ---- where the time goes -----------------------------------------------------------------
# (label, [(module path suffix, function) added], [(suffix, function) subtracted]): cumulative
# times from cProfile; the stages are disjoint parts of coverage()
STAGES = [
    ("context (per transmitter)", [("search/context.py", "build_tx_context")], []),
    ("line of sight and reflections", [("search/tile.py", "los_tile"), ("search/tile.py", "reflection_tile")], []),
    ("receivers' image trees (diffraction after a reflection)", [("search/tile.py", "_diffraction_part")],
     [("search/diffraction.py", "diffraction_tile")]),
    ("diffraction: receiver side (receiver image x edge tests)", [("search/end_sides.py", "_receiver_side")], []),
    ("diffraction: join, closed-form points, back-traces", [("search/diffraction.py", "diffraction_tile")],
     [("search/end_sides.py", "_receiver_side"), ("search/diffraction.py", "finish_diffraction")]),
    ("diffraction: occlusion of the legs", [("search/diffraction.py", "finish_diffraction")], []),
    ("path assembly", [("search/paths.py", "assemble")], []),
    ("fields (all paths)", [("coverage/solver.py", "_fields_sums")], []),
]


def stage_times(fn) -> dict:
    """Seconds per stage of ``fn()`` (a coverage map) under cProfile: :data:`STAGES`, the
    rest (``"other"``) and ``"total"``. Read the shares: the profiler inflates Python calls.
    Meant for maps without ``tolerance_db``, whose diffracted legs are cast after the search
    (outside ``diffraction_tile``): there the join stage would come out short."""
    import cProfile
    import pstats

    pr = cProfile.Profile()
    pr.enable()
    fn()
    pr.disable()
    cum: dict = {}
    for (path, _, name), (_, _, _, ct, _) in pstats.Stats(pr).stats.items():
        key = (path.replace("\\", "/"), name)
        cum[key] = cum.get(key, 0.0) + ct

    def total(pairs):
        return sum(v for (path, name), v in cum.items() for suffix, want in pairs
                   if name == want and path.endswith(suffix))

    out = {label: max(total(plus) - total(minus), 0.0) for label, plus, minus in STAGES}
    out["total"] = total([("coverage/solver.py", "coverage")])
    out["other"] = max(out["total"] - sum(out[label] for label, _, _ in STAGES), 0.0)
    return out


def diffracted_work(scene, rx: np.ndarray, options) -> tuple:
    """The headline map's diffracted paths, found by :func:`wavepaths.search.trace` for the map's
    traced cells ``rx`` (the same search), and their legs.

    Returns ``(paths, a, b)``: the diffracted paths (:class:`~wavepaths.search.paths.Paths`)
    and the ends (L, 3) [m] of every leg of every one of them, each leg once.
    """
    from ..coverage.solver import path_mechanism
    from ..search import trace

    found = trace(scene, STREET_CANYON_TX, rx, options)
    paths = found.select(path_mechanism(found) == 2)
    a, b = [], []
    for depth in np.unique(paths.depth):
        v = paths.vertices[paths.depth == depth][:, : depth + 2]
        a.append(v[:, :-1].reshape(-1, 3))
        b.append(v[:, 1:].reshape(-1, 3))
    return paths, np.concatenate(a) if a else np.zeros((0, 3)), np.concatenate(b) if b else np.zeros((0, 3))


def cost_floor(scene, grid, cfg, off: dict, on: dict, rounds: int, threads: int, off_threads_s: float,
               on_threads_s: float) -> dict:
    """What the headline map with diffraction cannot do without, timed on one thread against the
    map without diffraction: the fields of its diffracted paths and one occlusion query per leg
    of each (every leg is clear, so each costs its two half-rays). A search that found those
    paths at no cost beyond them would give the map with diffraction a cost ratio of

        floor = (t_off + t_fields + t_casts) / t_off        (one thread),

    and, with that work spread ideally over the machine's ``threads`` while the map without
    diffraction takes ``off_threads_s`` there, ``(t_off + (t_fields + t_casts) / threads) /
    t_off``. Beside it, the time the search of diffracted paths may take to meet a ratio of 3
    on those threads (``search_budget_s``) and the time it takes now (``search_s``: the
    measured ``on_threads_s`` minus the floor's share).
    """
    from ..coverage import CoverageOptions, coverage
    from ..fields import compute_fields
    from ..search import TraceOptions

    one = CoverageOptions(workers=1, threads=1)
    saved = kernels.threads()
    kernels.set_threads(1)
    try:
        m = coverage(scene, STREET_CANYON_TX, grid, TraceOptions(**on), fields=cfg, settings=one)
        rx = grid.cell_centers().reshape(-1, 3)[np.isfinite(m.a_total[0].ravel())]
        paths, a, b = diffracted_work(scene, rx, TraceOptions(**on))
        # (the map's cells, the map's search: the same diffracted paths, every leg clear)
        blocked = int(scene.raycaster.occluded(a, b).sum())
        compute_fields(scene, paths, cfg)
        times = interleaved({
            "off": lambda: coverage(scene, STREET_CANYON_TX, grid, TraceOptions(**off), fields=cfg, settings=one),
            "fields": lambda: compute_fields(scene, paths, cfg),
            "casts": lambda: scene.raycaster.occluded(a, b),
        }, rounds)
    finally:
        kernels.set_threads(saved)
    t_off, t_fields, t_casts = (times[k].median_s for k in ("off", "fields", "casts"))
    spread = (t_fields + t_casts) / threads
    return {"diffracted_paths": len(paths), "map_diffracted_paths": int(np.nansum(m.num_paths[2])),
            "legs": len(a), "legs_blocked": blocked,
            "off_s": times["off"].as_dict(), "fields_s": times["fields"].as_dict(), "casts_s": times["casts"].as_dict(),
            "ns_per_path_fields": 1e9 * t_fields / max(len(paths), 1),
            "ns_per_leg_cast": 1e9 * t_casts / max(len(a), 1),
            "floor_one_thread": (t_off + t_fields + t_casts) / t_off,
            "threads": threads, "floor_threads_ideal": (off_threads_s + spread) / off_threads_s,
            "search_budget_s": max(3.0 * off_threads_s - off_threads_s - spread, 0.0),
            "search_s": on_threads_s - off_threads_s - spread}


def run_diffraction_cost(quick: bool = False, repeats: int = 3, progress=print) -> dict:
    """Benchmark 5."""
    from ..coverage import CoverageOptions, PlanarGrid, coverage
    from ..fields import FieldConfig
    from ..scene import load_scene
    from ..search import TraceOptions
    from .scenes import sionna_scene_xml

    scene = load_scene(sionna_scene_xml("simple_street_canyon"))
    cell = 4.0 if quick else 2.0
    grid = PlanarGrid(center=[0.0, 0.0], height=1.5, size=[176.0, 120.0], cell_size=cell)
    cfg = FieldConfig(3.5e9)
    threads = kernels.threads()
    pairs = [p + (threads,) for p in (PAIRS[:1] if quick else PAIRS)]
    if threads > 1:
        pairs.insert(1, PAIRS[0] + (1,))
        if not quick:
            pairs.insert(3, PAIRS[1] + (1,))  # the seed's case on one thread too
    rounds = 1 if quick else repeats
    results = []
    last = {}

    def runner(opts, key="map", n_threads=None):
        # (the power sum: the total tolerance_db bounds; the coherent sum costs the same)
        settings = CoverageOptions(workers=1, threads=n_threads, coherent=False)

        def run():
            # one thread means one: tiles on the calling thread (threads=1) and, as the calling
            # thread's compiled kernels would use numba's threads, those set to 1 for the call
            saved = kernels.threads()
            if n_threads == 1:
                kernels.set_threads(1)
            try:
                last[key] = coverage(scene, STREET_CANYON_TX, grid, TraceOptions(**opts), fields=cfg, settings=settings)
            finally:
                kernels.set_threads(saved)
        return run

    runner(PAIRS[0][1])()  # warm-up, both maps of the headline pair
    runner(PAIRS[0][3])()
    for off_name, off, on_name, on, n_threads in pairs:
        progress(f"benchmark 5: {off_name} against {on_name}, {grid.shape[0]} x {grid.shape[1]} cells, "
                 f"{n_threads} thread(s)")
        n_rounds = 1 if on_name == "R3+D2" else rounds
        if on_name in (PAIRS[0][2], PAIRS[1][2]) and not quick:
            n_rounds = max(n_rounds, HEADLINE_ROUNDS)
        times = interleaved({"off": runner(off, "off", n_threads), "on": runner(on, "map", n_threads)}, n_rounds)
        m = last["map"]
        all_paths = int(np.nansum(m.num_paths))
        diffracted = int(np.nansum(m.num_paths[2]))
        off_paths = int(np.nansum(last["off"].num_paths))
        # diffraction adds paths and removes none: the same line-of-sight and reflected paths per cell
        same_go = bool(np.array_equal(np.nan_to_num(m.num_paths[:2]), np.nan_to_num(last["off"].num_paths[:2])))
        t_off, t_on = times["off"].median_s, times["on"].median_s
        results.append({"off": off_name, "on": on_name, "off_options": off, "on_options": on, "threads": n_threads,
                        "off_s": times["off"].as_dict(), "on_s": times["on"].as_dict(),
                        "ratio": t_on / t_off,
                        "cells_traced": int(m.metadata["cells_traced"]),
                        "diffracted_paths": diffracted, "all_paths": all_paths,
                        # what a path costs: the map without diffraction per path it finds, and
                        # the time diffraction adds per diffracted path it finds
                        "us_per_path_off": 1e6 * t_off / max(off_paths, 1),
                        "us_per_diffracted_path": 1e6 * (t_on - t_off) / max(diffracted, 1),
                        "paths_ratio": all_paths / max(off_paths, 1), "same_geometrical_optics_paths": same_go})
    # what no search can save: the fields and the casts of the diffracted paths it must find
    progress("benchmark 5: the floor of the headline pair (fields and casts of the diffracted paths, one thread)")
    head = results[0]
    floor = cost_floor(scene, grid, cfg, PAIRS[0][1], PAIRS[0][3], 1 if quick else HEADLINE_ROUNDS, threads,
                       head["off_s"]["median_s"], head["on_s"]["median_s"])
    # where the headline pair's time goes: the same two maps under cProfile, stage by stage
    off_st, on_st = stage_times(runner(PAIRS[0][1], "off", 1)), stage_times(runner(PAIRS[0][3], "map", 1))
    added = {k: on_st[k] - off_st[k] for k in on_st}
    stages = [{"stage": k, "off_s": off_st[k], "on_s": on_st[k], "added_s": added[k],
               "share_of_added": added[k] / added["total"] if added["total"] > 0 else None}
              for k in [label for label, _, _ in STAGES] + ["other", "total"]]
    return {"scene": "simple_street_canyon", "grid_shape": list(grid.shape), "cell_size_m": cell,
            "threads": threads, "pairs": results, "stages": stages, "floor": floor,
            "diffraction_cost_ratio": results[0]["ratio"],
            "headline_pair": "R2 / R2+D1",
            "diffraction_cost_ratio_one_thread": next((r["ratio"] for r in results if r["on"] == "R2+D1"
                                                       and r["threads"] == 1), None),
            # the seed's own case (one diffraction between two fixed points), beside the headline
            "seed_case_ratio": next((r["ratio"] for r in results if r["on"] == "R2+D0" and r["threads"] == threads),
                                    None),
            "seed_case_ratio_one_thread": next((r["ratio"] for r in results if r["on"] == "R2+D0"
                                                and r["threads"] == 1), None),
            "seed_ratio": SEED_RATIO, "target_ratio_max": 3.0}
