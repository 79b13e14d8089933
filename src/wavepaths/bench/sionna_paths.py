"""Benchmark 2: path queries, wavepaths against Sionna RT on the same CPU, in one run.

The same scene file, the same transmitter and 100 receivers, the same path types:

* Sionna RT: ``PathSolver`` with ``max_depth=3``, line of sight, specular reflections,
  ``diffraction=True`` with ``edge_diffraction=True`` (wavepaths diffracts on free edges
  too: the rim of the street canyon's ground), the lit region on, refraction and
  diffuse reflection off, ``samples_per_src = max_num_paths_per_src = 10^6`` (its
  defaults). Its diffraction is first order and combines with reflections before and
  after it up to ``max_depth`` interactions: D, R-D, D-R, R-R-D, R-D-R, D-R-R.
* wavepaths: ``TraceOptions(max_reflections=3, diffraction=True,
  diffraction_reflections=2)``, the same sequences, plus the field of every path
  (:func:`wavepaths.fields.compute_fields`, ``compat="sionna"`` so that coefficients
  compare like for like), since Sionna's timed call computes its ``a`` too.

Timing: Sionna's figure is ``run_sionna_paths(...).elapsed_s``, the second of two solver
calls in one process (the first, untimed, compiles its kernels). wavepaths is warmed up
the same way (its first query builds the scene's dihedra and BVH, reported as
``cold_s``), then timed ``repeats`` times per round. Rounds alternate the two engines and
the ratio of medians is reported. Scene loading is excluded for both.

Agreement: paths are matched by interaction sequence and vertices
(:func:`wavepaths.validation.compare.compare_paths`, 2 cm); the report gives how many
of Sionna's paths wavepaths also finds, how many each finds alone, and the delay and
|a| differences of the matched ones. A Sionna path without a match is explained as in
the validation report: a topology rule (it diffracts on an edge with three or more
faces and leaves its topological volume, seed §3.1, which wavepaths rejects on
purpose), an edge that is not a wedge, a Sionna duplicate, a reflection off the
diffracting wedge's own face (a grazing ray without field), or a failure of wavepaths.
"""

from __future__ import annotations

import time
from collections import Counter

import numpy as np

from .isolated import run_isolated
from .scenes import BenchScene

FREQUENCY_HZ = 3.5e9
SIONNA_REFERENCE_S = 20.0  # issue #7: "Sionna RT took about 20 s for 100 receivers on simple_street_canyon"


def trace_options(max_depth: int = 3) -> dict:
    """wavepaths' options for Sionna's ``max_depth`` (all of Sionna's sequences)."""
    return {"max_reflections": max_depth, "diffraction": True, "diffraction_reflections": max(max_depth - 1, 0),
            "lit_region": True}


def kinds_count(interactions: np.ndarray, depth: np.ndarray) -> dict:
    """Number of paths per interaction sequence ("LOS", "R", "R-D", ...)."""
    from ..validation.compare import kinds_string

    return dict(sorted(Counter(kinds_string(interactions[i], depth[i]) for i in range(len(depth))).items()))


def wavepaths_query(xml: str, tx, rx, options: dict, repeats: int = 3, frequency_hz: float = FREQUENCY_HZ,
                    keep_paths: bool = True) -> dict:
    """Load ``xml``, then time ``repeats`` path queries (trace + fields) after a cold one.

    Module-level so that :func:`~wavepaths.bench.isolated.run_isolated` can run it in a
    child process with a time limit.
    """
    from ..fields import FieldConfig, compute_fields
    from ..scene import load_scene
    from ..search import TraceOptions, trace

    t0 = time.perf_counter()
    scene = load_scene(xml)
    load_s = time.perf_counter() - t0
    opts = TraceOptions(**options)
    cfg = FieldConfig(frequency_hz, "utd", "sionna")
    tx = np.asarray(tx, float)
    rx = np.asarray(rx, float)

    def query():
        t = time.perf_counter()
        paths = trace(scene, tx, rx, opts)
        t_trace = time.perf_counter() - t
        fields = compute_fields(scene, paths, cfg)
        return paths, fields, t_trace, time.perf_counter() - t

    paths, fields, _, cold_s = query()
    times, trace_times = [], []
    for _ in range(repeats):
        paths, fields, t_trace, t_all = query()
        times.append(t_all)
        trace_times.append(t_trace)
    out = {"load_s": load_s, "cold_s": cold_s, "times_s": times, "trace_times_s": trace_times,
           "num_paths": len(paths), "kinds": kinds_count(paths.interactions, paths.depth),
           "scene": scene.summary(), "stats": {k: int(v) for k, v in paths.stats.items()}}
    if keep_paths:
        out["paths"] = paths
        out["a"] = fields.a
    return out


class _InProcess:
    """wavepaths queries on one loaded scene, for interleaving with Sionna in one process."""

    def __init__(self, bench: BenchScene, options: dict):
        self.first = wavepaths_query(bench.xml, bench.tx, bench.rx, options, repeats=0)
        from ..fields import FieldConfig
        from ..scene import load_scene
        from ..search import TraceOptions

        self.scene = load_scene(bench.xml)
        self.opts = TraceOptions(**options)
        self.cfg = FieldConfig(FREQUENCY_HZ, "utd", "sionna")
        self.bench = bench
        self.run()  # warm this scene object's lazy structures

    def run(self) -> float:
        from ..fields import compute_fields
        from ..search import trace

        t = time.perf_counter()
        paths = trace(self.scene, self.bench.tx, self.bench.rx, self.opts)
        compute_fields(self.scene, paths, self.cfg)
        return time.perf_counter() - t


def _sionna(bench: BenchScene, max_depth: int, samples: int):
    from ..validation.sionna_runner import run_sionna_paths

    return run_sionna_paths(bench.xml, bench.tx, bench.rx, frequency_hz=FREQUENCY_HZ, max_depth=max_depth,
                            diffraction=True, edge_diffraction=True, diffraction_lit_region=True,
                            samples_per_src=samples, max_num_paths_per_src=1_000_000)


def _agreement(xml: str, paths, a, sn, sn_depth2=None) -> dict:
    """Path-by-path comparison; each Sionna-only path gets the validation report's reason.
    ``sn_depth2``: Sionna's paths at ``max_depth=2``, to check the D-R pairs that differ
    (:func:`_large_gain_differences`)."""
    from ..scene import load_scene
    from ..validation.compare import compare_paths
    from ..validation.disagreements import SIONNA_ONLY_FAILURE, _explain_sionna_only

    from ..topology.sectors import sector_table

    scene = load_scene(xml)
    sectors = sector_table(scene.dihedra)
    comp = compare_paths(paths, a, sn, explain=lambda side, i: _explain_sionna_only(scene, sn, i, sectors)
                         if side == "sionna" else "")
    s = comp.summary()
    depth2 = None
    if sn_depth2 is not None:
        # the same wavepaths paths against Sionna at depth 2: its D-R coefficients there
        comp2 = compare_paths(paths, a, sn_depth2, explain=lambda side, i: "")
        depth2 = {m.wp_index: m.gain_diff_db for m in comp2.matches if m.kinds == "D-R"}
    amplitude = _large_gain_differences(scene, paths, a, sn, comp, depth2=depth2)
    failures = sum(1 for x in comp.only_sionna if x["reason"] == SIONNA_ONLY_FAILURE)
    only_sn = Counter(x["kinds"] for x in comp.only_sionna)
    only_wp = Counter(x["kinds"] for x in comp.only_wavepaths)
    return {
        "matched": s["matched"],
        "sionna_paths": int(sn.num_paths),
        "sionna_paths_found_by_wavepaths": s["matched"],
        "sionna_paths_found_fraction": s["matched"] / sn.num_paths if sn.num_paths else 1.0,
        "only_wavepaths": s["only_wavepaths"],
        "only_sionna": s["only_sionna"],
        "only_sionna_not_found_by_wavepaths": failures,
        "only_sionna_reasons": s["only_sionna_reasons"],
        "only_sionna_by_kind": dict(sorted(only_sn.items())),
        "only_wavepaths_by_kind": dict(sorted(only_wp.items())),
        "only_sionna_examples": comp.only_sionna[:10],
        "delay_rel_error": s["delay_rel_error"],
        "gain_diff_db": s["gain_diff_db"],
        "vertex_error_m": s["vertex_error_m"],
        "by_kind": s["by_kind"],
        "large_gain_differences": amplitude,
    }


GAIN_BANDS_DB = (6.0, 20.0)


def _large_gain_differences(scene, paths, a, sn, comp, max_depth: int = 3, depth2: dict | None = None) -> dict:
    """Matched pairs whose |a| differ by more than 6 dB, counted by reason and band (6-20 dB, > 20 dB).

    The reasons are the validation report's known disagreements (``validation/known.py``),
    each checked against exact solutions in the tests: ``sionna-dr-depends-on-max-depth``
    (a D-R at depth 3), ``multi-object edge`` and ``non-manifold edge`` (Sionna's wedge is two
    of the faces wavepaths' dihedron has), ``sionna-free-edge-collapses-to-flat``; anything
    else is ``unexplained`` (with up to 10 examples).

    ``depth2`` (wavepaths path index -> gain difference [dB] of its D-R against Sionna run at
    ``max_depth=2``) checks the D-R label path by path: a D-R pair is
    ``sionna-dr-depends-on-max-depth`` where Sionna's depth-2 coefficient of that same path is
    within 6 dB of wavepaths', ``unexplained`` where it is not, and
    ``sionna-dr-depends-on-max-depth-not-checked`` where Sionna's depth-2 run did not find the
    path (its ray sampling) or no depth-2 run was made.
    """
    from ..validation.disagreements import (_matched_wedge_difference, _multi_object_dihedra, _non_manifold_dihedra,
                                            _sionna_collapsed_free_edge)

    multi, non_manifold = _multi_object_dihedra(scene), _non_manifold_dihedra(scene)
    counts: dict = {}
    examples = []
    for mm in comp.matches:
        diff = mm.gain_diff_db
        if not np.isfinite(diff) or abs(diff) <= GAIN_BANDS_DB[0]:
            continue
        reason = "unexplained"
        if mm.kinds == "D-R" and max_depth >= 3:
            d2 = None if depth2 is None else depth2.get(mm.wp_index)
            if d2 is not None and np.isfinite(d2) and abs(d2) <= GAIN_BANDS_DB[0]:
                reason = "sionna-dr-depends-on-max-depth"
            elif d2 is None or not np.isfinite(d2):
                reason = "sionna-dr-depends-on-max-depth-not-checked"
        if reason != "sionna-dr-depends-on-max-depth" and "D" in mm.kinds:
            # Sionna's wedge differs from the dihedron (a D-R too, when depth 2 does not explain it)
            wedge = _matched_wedge_difference(paths, mm.wp_index, multi, non_manifold)
            if wedge is not None:
                reason = wedge
            elif mm.kinds != "D-R" and _sionna_collapsed_free_edge(scene, paths, mm, sn, a):
                reason = "sionna-free-edge-collapses-to-flat"
        band = "> 20 dB" if abs(diff) > GAIN_BANDS_DB[1] else "6-20 dB"
        counts.setdefault(reason, {"6-20 dB": 0, "> 20 dB": 0})[band] += 1
        if reason == "unexplained" and len(examples) < 10:
            examples.append({"kinds": mm.kinds, "rx": int(mm.rx), "gain_diff_db": float(diff),
                             "wavepaths_index": int(mm.wp_index)})
    return {"by_reason": counts, "unexplained_examples": examples}


def run_scene(bench: BenchScene, rounds: int = 3, repeats: int = 3, max_depth: int = 3,
              samples_per_src: int = 1_000_000, wavepaths_timeout_s: float | None = None) -> dict:
    """Benchmark 2 on one scene.

    With ``wavepaths_timeout_s`` the wavepaths queries run once in a child process with
    that time limit (a large scene may not finish); otherwise the engines alternate in
    this process for ``rounds`` rounds.
    """
    options = trace_options(max_depth)
    out: dict = {"scene": bench.name, "scene_file": bench.xml, "note": bench.note, "tx": bench.tx.tolist(),
                 "num_rx": int(len(bench.rx)), "max_depth": max_depth, "samples_per_src": samples_per_src,
                 "trace_options": options,
                 "sionna_options": {"max_depth": max_depth, "los": True, "specular_reflection": True,
                                    "diffraction": True, "edge_diffraction": True, "diffraction_lit_region": True,
                                    "refraction": False, "diffuse_reflection": False,
                                    "samples_per_src": samples_per_src, "max_num_paths_per_src": 1_000_000}}
    sionna_times, sionna_warmups, wp_times = [], [], []
    sn = None
    if wavepaths_timeout_s is None:
        wp = _InProcess(bench, options)
        first = wp.first
        for _ in range(rounds):
            wp_times += [wp.run() for _ in range(repeats)]
            sn = _sionna(bench, max_depth, samples_per_src)
            sionna_times.append(sn.elapsed_s)
            sionna_warmups.append(sn.warmup_s)
        wp_times += [wp.run() for _ in range(repeats)]
        paths_res = wavepaths_query(bench.xml, bench.tx, bench.rx, options, repeats=0)
        first_cold = first["cold_s"]
    else:
        child = run_isolated("wavepaths.bench.sionna_paths", "wavepaths_query",
                             {"xml": bench.xml, "tx": bench.tx, "rx": bench.rx, "options": options,
                              "repeats": 1}, timeout_s=wavepaths_timeout_s)
        out["wavepaths_child"] = {k: v for k, v in child.items() if k != "result"}
        if not child["ok"]:
            paths_res = None
        else:
            paths_res = child["result"]
            wp_times = list(paths_res["times_s"])
            first_cold = paths_res["cold_s"]
        for _ in range(max(1, rounds)):
            sn = _sionna(bench, max_depth, samples_per_src)
            sionna_times.append(sn.elapsed_s)
            sionna_warmups.append(sn.warmup_s)

    out["sionna"] = {"times_s": sionna_times, "median_s": float(np.median(sionna_times)),
                     "warmup_s": sionna_warmups, "num_paths": int(sn.num_paths), "excluded": int(sn.excluded),
                     "kinds": kinds_count(sn.interactions, sn.num_interactions), "version": sn.sionna_version}
    if paths_res is None:
        out["wavepaths"] = {"finished": False, "error": out["wavepaths_child"].get("error"),
                            "timeout_s": wavepaths_timeout_s}
        out["time_ratio"] = None
        out["time_ratio_upper_bound"] = float(np.median(sionna_times)) / wavepaths_timeout_s
        return out
    out["wavepaths"] = {"finished": True, "times_s": wp_times, "median_s": float(np.median(wp_times)),
                        "cold_s": first_cold, "load_s": paths_res["load_s"],
                        "trace_share": float(np.median(paths_res["trace_times_s"]) / np.median(paths_res["times_s"]))
                        if paths_res["times_s"] else None,
                        "num_paths": paths_res["num_paths"], "kinds": paths_res["kinds"],
                        "scene": paths_res["scene"], "stats": paths_res["stats"]}
    out["time_ratio"] = out["sionna"]["median_s"] / out["wavepaths"]["median_s"]
    # Sionna once more at depth 2 (not timed): the D-R coefficients it gives there check, path
    # by path, the D-R pairs that differ at depth 3
    sn2 = _sionna(bench, 2, samples_per_src) if max_depth >= 3 else None
    out["agreement"] = _agreement(bench.xml, paths_res["paths"], paths_res["a"], sn, sn2)
    return out


def run_sionna_paths_bench(out_dir: str, quick: bool = False, rounds: int = 3, repeats: int = 3,
                           large_timeout_s: float = 600.0, progress=print) -> dict:
    """Benchmark 2: ``simple_street_canyon`` and the larger ``etoile_crop``.

    ``quick``: the street canyon only, one round.
    """
    from ..validation.sionna_env import sionna_version
    from .scenes import etoile_crop, street_canyon

    if sionna_version() is None:
        return {"skipped": "Sionna RT is not installed (pip install 'wavepaths[sionna]')"}
    scenes = {}
    progress("benchmark 2: simple_street_canyon")
    scenes["simple_street_canyon"] = run_scene(street_canyon(), rounds=1 if quick else rounds, repeats=repeats)
    if not quick:
        progress("benchmark 2: etoile_crop (wavepaths in a child process, "
                 f"limit {large_timeout_s:g} s)")
        scenes["etoile_crop"] = run_scene(etoile_crop(out_dir), rounds=1, repeats=1,
                                          wavepaths_timeout_s=large_timeout_s)
    head = scenes["simple_street_canyon"]
    return {
        "scenes": scenes,
        "sionna_paths_time_ratio": head["time_ratio"],
        "sionna_reference_s": SIONNA_REFERENCE_S,
        "target_time_ratio_min": 20.0,
        "method": "ratio of medians; rounds alternate the engines in one process; Sionna's time is its second "
                  "PathSolver call (after JIT warm-up); scene loading excluded for both",
    }
