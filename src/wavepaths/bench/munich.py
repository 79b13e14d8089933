"""The scale target (optional, ``wavepaths bench --munich``): Sionna RT's ``munich`` scene.

Target (issue #7): a coverage map of the whole scene at 2 m cells, 1.5 m above the
ground, with reflections to order 2 and diffraction with reflections before and after
it (``diffraction_reflections=2``: R-D, D-R, R-D-R, R-R-D, D-R-R), in under 10 minutes and
8 GB here. The transmitter stands where Sionna's tutorials put it, (8.5, 21, 27) m.

The map runs in a child process with a time limit and an 8 GiB address-space limit. The
child writes its progress (cells done, stage) to a small JSON file as it goes, so that a
run that does not finish still tells how far it got and at what rate; the report gives
the extrapolated time. Before it, another child builds the transmitter context and traces
one tile (:func:`munich_sample`): the report then has the context's counts, time and memory
and the tile rate even when the full map is hopeless, and the full map is skipped when that
sample puts it beyond its time limit.
"""

from __future__ import annotations

import json
import os
import time

from .isolated import run_isolated

MUNICH_TX = (8.5, 21.0, 27.0)
TARGET_S = 600.0
LAUNCHED_OPTIONS = {"max_reflections": 2, "diffraction": True, "diffraction_reflections": 2,
                    "diffraction_candidates": "launched", "reflection_candidates": "launched"}
"""The target's settings with launched candidates (:mod:`wavepaths.search.launch`)."""
TARGET_BYTES = 8 << 30
CHECK_BYTES = 16 << 30
"""Address-space limit of :func:`munich_check`, which is no part of the target: its exhaustive
search holds the transmitter's order-2 (chain, edge) sources (46.7 M in the fifteenth session; twenty-fourth session:
7.1 GB peak resident, process and threads; under an 8 GiB address-space limit it ran out)."""


def _write(path: str, data: dict) -> None:
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(data, f)
    os.replace(tmp, path)


def munich_map(progress_file: str, cell_size: float = 2.0, options: dict | None = None, workers: int | None = None) -> dict:
    """Build the munich coverage map (runs in a child process); return timings and figures.

    ``workers``: local processes, by default one per core, started at once (the map is far
    too large for ``coverage()``'s automatic choice to keep it in this process)."""
    import numpy as np

    from ..coverage import CoverageOptions, PlanarGrid, coverage
    from ..coverage.solver import default_workers
    from ..scene import load_scene
    from ..search import TraceOptions
    from .scenes import sionna_scene_xml

    opts = TraceOptions(**(options or {"max_reflections": 2, "diffraction": True, "diffraction_reflections": 2}))
    state = {"stage": "load", "t0": time.time()}
    _write(progress_file, state)
    t = time.perf_counter()
    scene = load_scene(sionna_scene_xml("munich"))
    load_s = time.perf_counter() - t
    info = scene.summary()
    grid = PlanarGrid.footprint(scene, cell_size, 1.5)
    state.update(stage="dihedra", load_s=load_s, triangles=info["triangles"], polygons=info["polygons"],
                 diffracting_dihedra=info["diffracting_dihedra"], cells=grid.num_cells, shape=list(grid.shape))
    _write(progress_file, state)
    t_map = time.perf_counter()
    last = [0.0]

    def progress(done: int) -> None:
        now = time.perf_counter()
        if now - last[0] > 2.0:
            last[0] = now
            state.update(stage="tiles", cells_done=int(done), map_elapsed_s=now - t_map)
            _write(progress_file, state)

    state["stage"] = "context"
    _write(progress_file, state)
    m = coverage(scene, np.array([MUNICH_TX]), grid, opts, settings=CoverageOptions(workers=workers or default_workers()),
                 progress=progress)
    map_s = time.perf_counter() - t_map
    state.update(stage="done", map_s=map_s, cells_done=int(m.metadata["cells_traced"]))
    _write(progress_file, state)
    return {"load_s": load_s, "map_s": map_s, "total_s": load_s + map_s, "cells": grid.num_cells,
            "cells_traced": int(m.metadata["cells_traced"]), "shape": list(grid.shape), "timings": m.timings,
            "scene": info, "options": {k: getattr(opts, k) for k in ("max_reflections", "diffraction",
                                                                      "diffraction_reflections",
                                                                      "diffraction_candidates",
                                                                      "reflection_candidates")},
            "stats": {k: int(v) for k, v in m.stats.items()},
            "reached_fraction": float(np.isfinite(m.path_gain_db())[~m.inside].mean())}


def munich_sample(progress_file: str, cell_size: float = 2.0, options: dict | None = None, cells: int = 256,
                  workers: int | None = None) -> dict:
    """The transmitter context and one tile of the munich map (runs in a child process).

    Builds the context (image tree, beam trees, diffraction sources: its time, its counts and
    the process's memory peak), traces ``cells`` consecutive cells from the middle of the grid
    (one coverage tile, which also builds what all tiles share, ``ctx.derived``), then the
    next ``cells`` cells, and extrapolates the whole map: ``context_s + tile_s +
    second_tile_s * (active cells - cells) / cells / workers``. Tells whether the full map
    can fit its time limit before running it.
    """
    import numpy as np

    from ..coverage import PlanarGrid
    from ..scene.solids import inside_solid_objects, solid_objects
    from ..coverage.solver import default_workers
    from ..scene import load_scene
    from ..search import TraceOptions
    from ..search.context import build_tx_context
    from ..search.tile import trace_tile
    from .isolated import peak_rss_bytes
    from .scenes import sionna_scene_xml

    opts = TraceOptions(**(options or {"max_reflections": 2, "diffraction": True, "diffraction_reflections": 2}))
    state: dict = {"stage": "load", "t0": time.time()}
    _write(progress_file, state)
    t = time.perf_counter()
    scene = load_scene(sionna_scene_xml("munich"))
    load_s = time.perf_counter() - t
    grid = PlanarGrid.footprint(scene, cell_size, 1.5)
    flat = grid.cell_centers().reshape(-1, 3)
    t = time.perf_counter()
    active = np.nonzero(~inside_solid_objects(scene, flat, solid_objects(scene)))[0]
    inside_s = time.perf_counter() - t
    state.update(stage="context", load_s=load_s, inside_s=inside_s, cells=grid.num_cells, active_cells=len(active))
    _write(progress_file, state)
    t = time.perf_counter()
    ctx = build_tx_context(scene, np.array([MUNICH_TX]), opts)
    context_s = time.perf_counter() - t
    context_rss = peak_rss_bytes()
    state.update(stage="tile", context_s=context_s, context_peak_rss_bytes=context_rss,
                 context_stats={k: int(v) for k, v in ctx.stats.items()})
    _write(progress_file, state)
    mid = len(active) // 2
    rx = flat[active[mid : mid + cells]]
    t = time.perf_counter()
    batches, stats = trace_tile(scene, ctx, rx)
    tile_s = time.perf_counter() - t
    # the first tile also builds what every tile shares (the sources' frames, the beam trees:
    # ctx.derived); the next cells give the rate of every other tile
    rx2 = flat[active[mid + cells : mid + 2 * cells]]
    state.update(stage="second tile", tile_s=tile_s)
    _write(progress_file, state)
    t = time.perf_counter()
    batches2, _ = trace_tile(scene, ctx, rx2) if len(rx2) else ([], None)
    tile2_s = time.perf_counter() - t
    n_workers = default_workers() if workers is None else workers
    rest = max(len(active) - len(rx), 0)
    tiles_s = tile_s + (tile2_s / max(len(rx2), 1) if len(rx2) else tile_s / len(rx)) * rest / max(n_workers, 1)
    out = {"load_s": load_s, "inside_s": inside_s, "context_s": context_s, "context_peak_rss_bytes": context_rss,
           "context_stats": {k: int(v) for k, v in ctx.stats.items()}, "sample_cells": len(rx), "tile_s": tile_s,
           "tile_stats": {k: int(v) for k, v in stats.items()}, "paths": int(sum(len(b.tx_index) for b in batches)),
           "second_tile_cells": int(len(rx2)), "second_tile_s": tile2_s,
           "second_tile_paths": int(sum(len(b.tx_index) for b in batches2)),
           "active_cells": int(len(active)), "workers": n_workers,
           "extrapolated_map_s": load_s + inside_s + context_s + tiles_s, "peak_rss_bytes": peak_rss_bytes()}
    state.update(stage="done", **{k: out[k] for k in ("tile_s", "extrapolated_map_s")})
    _write(progress_file, state)
    return out


def munich_check(progress_file: str, cells: int = 32, seed: int = 7, cell_size: float = 2.0,
                 options: dict | None = None) -> dict:
    """How much the launched candidates miss on munich (runs in a child process).

    ``cells`` random active cells of the map's grid (``seed``) are traced twice from one
    transmitter context with the target's settings: the exhaustive search, then launched
    candidates (:data:`LAUNCHED_OPTIONS`, the fans traced for these cells only). Both sets
    of paths get their fields (3.5 GHz, the map's defaults), and the report compares them:
    the paths the launched search misses (by type), any it finds that the exhaustive one
    does not (there should be none: the tests are the same), the share of the power
    missed, and each cell's total power difference [dB].
    """
    import dataclasses

    import numpy as np

    from ..coverage import PlanarGrid
    from ..scene.solids import inside_solid_objects, solid_objects
    from ..fields import FieldConfig, compute_fields
    from ..scene import load_scene
    from ..search import TraceOptions, trace
    from ..search.context import build_tx_context
    from .scenes import sionna_scene_xml

    base = {k: v for k, v in (options or LAUNCHED_OPTIONS).items() if not k.endswith("_candidates")}
    ex_opts = TraceOptions(**base)
    la_opts = TraceOptions(**(options or LAUNCHED_OPTIONS))
    state: dict = {"stage": "load", "t0": time.time()}
    _write(progress_file, state)
    scene = load_scene(sionna_scene_xml("munich"))
    grid = PlanarGrid.footprint(scene, cell_size, 1.5)
    flat = grid.cell_centers().reshape(-1, 3)
    active = np.nonzero(~inside_solid_objects(scene, flat, solid_objects(scene)))[0]
    pick = np.sort(np.random.default_rng(seed).choice(active, min(cells, len(active)), replace=False))
    rx = flat[pick]
    tx = np.array([MUNICH_TX])
    state.update(stage="context")
    _write(progress_file, state)
    t = time.perf_counter()
    ctx = build_tx_context(scene, tx, ex_opts)
    context_s = time.perf_counter() - t
    state.update(stage="exhaustive", context_s=context_s)
    _write(progress_file, state)
    t = time.perf_counter()
    ex = trace(scene, tx, rx, ex_opts, context=ctx)
    ex_s = time.perf_counter() - t
    state.update(stage="launched", exhaustive_s=ex_s)
    _write(progress_file, state)
    lctx = dataclasses.replace(ctx, options=la_opts, derived={})
    t = time.perf_counter()
    la = trace(scene, tx, rx, la_opts, context=lctx)
    la_s = time.perf_counter() - t
    cfg = FieldConfig(3.5e9)

    def keyed(p):
        power = np.abs(compute_fields(scene, p, cfg).a) ** 2
        keys = [(int(p.rx_index[i]), tuple(int(v) for v in p.interactions[i]), tuple(int(v) for v in p.primitive[i]))
                for i in range(len(p.rx_index))]
        total = np.bincount(p.rx_index, power, len(rx))
        return dict(zip(keys, power.tolist())), total

    ke, te = keyed(ex)
    kl, tl = keyed(la)
    missed = set(ke) - set(kl)
    kinds: dict[str, int] = {}
    names = {1: "R", 2: "D"}
    for k in missed:
        label = "-".join(names.get(v, "?") for v in k[1] if v != 0) or "LoS"
        kinds[label] = kinds.get(label, 0) + 1
    reached = te > 0
    err = np.abs(10 * np.log10(np.maximum(tl[reached], 1e-300) / te[reached]))
    out = {"cells": int(len(rx)), "seed": seed, "cell_rows": pick.tolist(), "context_s": context_s,
           "exhaustive_s": ex_s, "launched_s": la_s, "paths_exhaustive": len(ke), "paths_launched": len(kl),
           "missed": len(missed), "extra": len(set(kl) - set(ke)), "missed_by_type": kinds,
           "missed_power_fraction": float(sum(ke[k] for k in missed) / max(sum(ke.values()), 1e-300)),
           "cells_reached": int(reached.sum()),
           "max_cell_error_db": float(err.max()) if len(err) else 0.0,
           "median_cell_error_db": float(np.median(err)) if len(err) else 0.0,
           "launched_candidates": int(la.stats.get("launched_candidates", 0))}
    state.update(stage="done")
    _write(progress_file, state)
    return out


def run_munich(out_dir: str, timeout_s: float = 1800.0, memory_limit: int = TARGET_BYTES, cell_size: float = 2.0,
               options: dict | None = None, probe: bool = True, probe_timeout_s: float = 900.0,
               progress=print, sample_first: bool = True, sample_timeout_s: float = 900.0,
               sample_cells: int = 16, launched: bool = True, check_cells: int = 32) -> dict:
    """Run the munich map once in a child process; report how far it got.

    With ``launched`` (and the target's settings), first the whole map with launched
    candidates (:data:`LAUNCHED_OPTIONS`, :func:`munich_map` on the default workers, within
    ``timeout_s``), reported under ``"launched"`` with its own ``meets_target`` (time, and the
    peak of the summed resident memory of the map's process and its workers); then, with
    ``check_cells``, what the launched candidates miss there (:func:`munich_check`, under
    ``"launched_check"``).

    With ``sample_first``, a child first builds the transmitter context and traces two strips
    of ``sample_cells`` cells (:func:`munich_sample`, limited to ``sample_timeout_s``; at R2+D2
    in the fourteenth session: the context in about 300 s, then 4-5 s per cell, plus about
    30 s in the first strip for what every tile shares); the full map runs only when the
    extrapolated time fits ``timeout_s``, so a hopeless setting costs minutes, not the full
    limit, and still reports its context (images per order, time, memory) and tile rate.
    When the target settings fail, ``probe`` runs the same map at first order (R1+D0)
    with ``probe_timeout_s``, to measure the rate at which the scene's cells go.
    """
    from ..validation.sionna_env import sionna_version

    if sionna_version() is None:
        return {"skipped": "Sionna RT is not installed (its munich scene ships with it)"}
    os.makedirs(out_dir, exist_ok=True)
    pfile = os.path.join(out_dir, "munich_progress.json")
    launched_out = None
    if launched and options is None:
        # the target's settings with launched candidates: the whole map, then a check of what
        # the launch misses against the exhaustive search on random cells
        progress(f"munich: the map with launched candidates (limit {timeout_s:g} s)")
        lfile = os.path.join(out_dir, "munich_launched_progress.json")
        rl = run_isolated("wavepaths.bench.munich", "munich_map",
                          {"progress_file": lfile, "cell_size": cell_size, "options": LAUNCHED_OPTIONS},
                          timeout_s=timeout_s, memory_limit_bytes=memory_limit)
        launched_out = dict(rl["result"]) if rl["ok"] else {"error": rl.get("error"),
                                                            "timed_out": rl.get("timed_out", False)}
        launched_out.update(wall_s=rl["wall_s"], options=LAUNCHED_OPTIONS, finished=bool(rl["ok"]),
                            max_rss_bytes=rl.get("max_rss_bytes"), max_group_rss_bytes=rl.get("max_group_rss_bytes"))
        launched_out["meets_target"] = bool(rl["ok"] and launched_out["total_s"] <= TARGET_S
                                            and (rl.get("max_group_rss_bytes") or 0) <= TARGET_BYTES)
        if check_cells:
            progress(f"munich: launched against exhaustive on {check_cells} random cells (limit {sample_timeout_s:g} s)")
            cfile = os.path.join(out_dir, "munich_check_progress.json")
            rc = run_isolated("wavepaths.bench.munich", "munich_check",
                              {"progress_file": cfile, "cells": check_cells, "cell_size": cell_size},
                              timeout_s=sample_timeout_s, memory_limit_bytes=max(memory_limit, CHECK_BYTES))
            launched_out["check"] = dict(rc["result"]) if rc["ok"] else {"error": rc.get("error"),
                                                                         "timed_out": rc.get("timed_out", False)}
    sample = None
    if sample_first:
        progress(f"munich: context and one tile first (limit {sample_timeout_s:g} s)")
        sfile = os.path.join(out_dir, "munich_sample_progress.json")
        rs = run_isolated("wavepaths.bench.munich", "munich_sample",
                          {"progress_file": sfile, "cell_size": cell_size, "options": options,
                           "cells": sample_cells},
                          timeout_s=sample_timeout_s, memory_limit_bytes=memory_limit)
        sample = dict(rs["result"]) if rs["ok"] else {"error": rs.get("error"), "timed_out": rs.get("timed_out", False)}
        sample["wall_s"] = rs["wall_s"]
        if os.path.exists(sfile):
            with open(sfile) as f:
                sample["last_progress"] = json.load(f)
        est = sample.get("extrapolated_map_s")
        if est is None or est > timeout_s:
            why = (f"the sample extrapolates the map to {est:.0f} s, beyond the {timeout_s:g} s limit" if est
                   else "the sample did not finish")
            progress(f"munich: full map not run: {why}")
            out = {"options": options or "target (R2+D2)", "target_s": TARGET_S, "target_bytes": TARGET_BYTES,
                   "timeout_s": timeout_s, "memory_limit_bytes": memory_limit, "tx": list(MUNICH_TX),
                   "cell_size_m": cell_size, "finished": False, "meets_target": False, "full_map_skipped": why,
                   "sample": sample, "launched": launched_out}
            if probe and options is None:
                progress("munich: probing first order (R1+D0) to see where the scene stands")
                out["probe"] = run_munich(out_dir, timeout_s=probe_timeout_s, memory_limit=memory_limit,
                                          cell_size=cell_size, probe=False, progress=progress, launched=False,
                                          options={"max_reflections": 1, "diffraction": True,
                                                   "diffraction_reflections": 0},
                                          sample_timeout_s=min(sample_timeout_s, probe_timeout_s))
            return out
    progress(f"munich: coverage map at {cell_size:g} m cells (limit {timeout_s:g} s, {memory_limit / 2**30:g} GiB)")
    r = run_isolated("wavepaths.bench.munich", "munich_map",
                     {"progress_file": pfile, "cell_size": cell_size, "options": options},
                     timeout_s=timeout_s, memory_limit_bytes=memory_limit)
    state = {}
    if os.path.exists(pfile):
        with open(pfile) as f:
            state = json.load(f)
    out = {"options": options or "target (R2+D2)", "target_s": TARGET_S, "target_bytes": TARGET_BYTES, "timeout_s": timeout_s,
           "memory_limit_bytes": memory_limit, "tx": list(MUNICH_TX), "cell_size_m": cell_size,
           "finished": bool(r["ok"]), "wall_s": r["wall_s"], "last_progress": state}
    if sample is not None:
        out["sample"] = sample
    if launched_out is not None:
        out["launched"] = launched_out
    if r["ok"]:
        out.update(r["result"])
        out["max_rss_bytes"] = r["max_rss_bytes"]
        out["max_group_rss_bytes"] = r.get("max_group_rss_bytes")
        peak = max(r["max_rss_bytes"], r.get("max_group_rss_bytes") or 0)  # the workers count too
        out["meets_target"] = out["total_s"] <= TARGET_S and peak <= TARGET_BYTES
    else:
        out["error"] = r.get("error")
        out["timed_out"] = r.get("timed_out", False)
        out["meets_target"] = False
        done, el = state.get("cells_done"), state.get("map_elapsed_s")
        if done and el:
            rate = done / el
            out["cells_per_s"] = rate
            out["extrapolated_map_s"] = state.get("cells", 0) / rate
        if probe and options is None:
            progress("munich: the target settings failed; probing first order (R1+D0) to see where the scene stands")
            out["probe"] = run_munich(out_dir, timeout_s=probe_timeout_s, memory_limit=memory_limit,
                                      cell_size=cell_size, probe=False, progress=progress, launched=False,
                                      options={"max_reflections": 1, "diffraction": True, "diffraction_reflections": 0})
    return out
