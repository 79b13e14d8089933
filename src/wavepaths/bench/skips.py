"""Benchmark 6: what each skip saves ("skip what a scene doesn't need", issue #7).

Every conservative culling test of the path search can be switched off
(:attr:`wavepaths.search.TraceOptions.disable_culling`, names in
:data:`wavepaths.search.options.CULLING_TESTS`). Here benchmark 2's path query
(``simple_street_canyon``, 100 receivers, reflections to order 3, diffraction with up to
two reflections, fields included) runs with every test on, with each one off in turn,
and with all of them off, the runs alternating round by round. For each test: the
median time with it off, the time it saves (off minus on), what it counted as culled
in ``Paths.stats`` with it on, and whether the paths found are exactly the same (they
must be: the tests are conservative; a difference is reported, not hidden).

The skips that are not switches (flat and concave edges are never dihedra; no dihedra
are built without diffraction; absorbers and hidden contact faces never reflect;
one-sided closed objects; per-transmitter sector pruning; the half-space and bounding
sphere tests of the image tree) are reported by their counters only.
"""

from __future__ import annotations

import re

import numpy as np

from .timing import interleaved

FREQUENCY_HZ = 3.5e9


def _path_set(p) -> set:
    """(tx, rx, interactions, primitives) of every path."""
    keys = np.concatenate([p.tx_index[:, None], p.rx_index[:, None], p.interactions.astype(np.int64), p.primitive], axis=1)
    return {tuple(r) for r in keys.tolist()}




def run_skips(quick: bool = False, rounds: int = 5, progress=print) -> dict:
    """Benchmark 6."""
    from ..fields import FieldConfig, compute_fields
    from ..scene import load_scene
    from ..search import TraceOptions, trace
    from ..search.options import CULLING_COUNTERS, CULLING_TESTS
    from .scenes import street_canyon

    bench = street_canyon(30 if quick else 100)
    scene = load_scene(bench.xml)
    base = TraceOptions(max_reflections=3, diffraction=True, diffraction_reflections=2)
    cfg = FieldConfig(FREQUENCY_HZ, "utd", "sionna")
    settings = {"all on": base, **{f"{n} off": base.with_(disable_culling={n}) for n in CULLING_TESTS},
                "all off": base.with_(disable_culling=set(CULLING_TESTS))}
    found = {}

    def runner(label, opts):
        def run():
            p = trace(scene, bench.tx, bench.rx, opts)
            compute_fields(scene, p, cfg)
            found[label] = p
        return run

    for label, opts in settings.items():  # warm-up, and the paths of each setting
        runner(label, opts)()
    progress(f"benchmark 6: {len(settings)} settings x {1 if quick else rounds} rounds")
    times = interleaved({k: runner(k, o) for k, o in settings.items()}, 1 if quick else rounds)
    on = times["all on"].median_s
    ref = _path_set(found["all on"])
    stats = found["all on"].stats
    rows = []
    for label in settings:
        name = label[: -len(" off")] if label.endswith(" off") else None
        culled = (sum(v for k, v in stats.items() if re.fullmatch(CULLING_COUNTERS[name], k)) if name in CULLING_COUNTERS else None)
        rows.append({"setting": label, "test": name, "description": CULLING_TESTS.get(name, ""),
                     "time_s": times[label].as_dict(), "saved_s": times[label].median_s - on,
                     "saved_fraction": (times[label].median_s - on) / times[label].median_s,
                     "culled_with_it_on": culled, "num_paths": len(found[label]),
                     "same_paths": _path_set(found[label]) == ref})
    counters = {k: int(v) for k, v in stats.items()
                if any(s in k for s in ("culled", "rejected", "kept", "considered", "images_order"))}
    return {"scene": bench.name, "num_rx": len(bench.rx), "options": base.to_dict(), "rows": rows,
            "all_same_paths": all(r["same_paths"] for r in rows), "counters_all_on": counters}
