"""How complete the launched candidates are (:mod:`wavepaths.search.launch`), against the
exhaustive search, and what they cost.

For a scene, one transmitter and ``cells`` random street-level receivers (1.5 m, outside
the buildings, seeded): the exhaustive search's diffracted paths (R2+D2: D, R-D, D-R,
R-R-D, R-D-R, D-R-R), then, for each fan density, the candidate sequences that the Keller
fans carry to each receiver. Reported per fan density: the time of the edge samples and of
the fans, the candidates per receiver, and which of the exhaustive paths' sequences are
among them, counted per (reflections before, after) and weighted by the paths' power
(UTD fields at 3.5 GHz), beside the exhaustive search's own candidate count. The E-D-R
sequences (``0R-D-0R``) count as found: the launched tiles enumerate them
(:mod:`wavepaths.search.launched`), the fans no longer carry them.
"""

from __future__ import annotations

import time

import numpy as np


def _diffracted_keys(paths, power: np.ndarray) -> list[tuple]:
    from ..search.paths import InteractionType

    out = []
    for i in range(len(paths.rx_index)):
        kinds = paths.interactions[i]
        at = np.nonzero(kinds == InteractionType.DIFFRACTION)[0]
        if len(at) == 0:
            continue
        depth = int(paths.depth[i])
        prim = paths.primitive[i].tolist()
        a = int(at[0])
        out.append(((int(paths.rx_index[i]), tuple(prim[: a + 1]), tuple(prim[a + 1 : depth])),
                    (a, depth - a - 1), float(power[i])))
    return out


def launch_completeness(scene_name: str, tx, cells: int = 32, fans=(64, 256, 1024), seed: int = 7,
                        progress=print) -> dict:
    """Benchmark the launched candidates on ``scene_name`` (see module docstring)."""
    from ..coverage import PlanarGrid
    from ..scene.solids import inside_solid_objects, solid_objects
    from ..fields import FieldConfig, compute_fields
    from ..scene import load_scene
    from ..search import TraceOptions
    from ..search.context import build_tx_context
    from ..search.launch import LaunchOptions, candidate_sequences, edge_samples
    from ..search.paths import assemble
    from ..search.tile import trace_tile
    from .scenes import sionna_scene_xml

    t = time.perf_counter()
    scene = load_scene(sionna_scene_xml(scene_name))
    grid = PlanarGrid.footprint(scene, 2.0, 1.5)
    flat = grid.cell_centers().reshape(-1, 3)
    active = np.nonzero(~inside_solid_objects(scene, flat, solid_objects(scene)))[0]
    rx = flat[np.sort(np.random.default_rng(seed).choice(active, min(cells, len(active)), replace=False))]
    tx = np.asarray(tx, dtype=np.float64).reshape(1, 3)
    progress(f"launch: {scene_name} loaded ({time.perf_counter() - t:.1f} s), context")
    t = time.perf_counter()
    ctx = build_tx_context(scene, tx, TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=2))
    context_s = time.perf_counter() - t
    progress(f"launch: context {context_s:.1f} s, exhaustive search of {len(rx)} receivers")
    t = time.perf_counter()
    batches, stats = [], {}
    for lo in range(0, len(rx), 8):
        b, st = trace_tile(scene, ctx, rx[lo : lo + 8], lo)
        batches += b
        for k, v in st.items():
            stats[k] = stats.get(k, 0) + int(v)
    exhaustive_s = time.perf_counter() - t
    paths = assemble(tx, rx, batches, stats)
    power = np.abs(compute_fields(scene, paths, FieldConfig(3.5e9)).a) ** 2
    ref = _diffracted_keys(paths, power)
    total_power = sum(p for _, _, p in ref)
    # what the exhaustive search joined per receiver (its candidates before the casts)
    joined = sum(v for k, v in stats.items() if k.startswith("diffraction_") and k.endswith("_candidates"))
    out = {"scene": scene_name, "tx": tx[0].tolist(), "receivers": len(rx), "seed": seed, "context_s": context_s,
           "exhaustive_s": exhaustive_s, "exhaustive_s_per_receiver": exhaustive_s / len(rx),
           "diffracted_paths": len(ref), "exhaustive_candidates_per_receiver": joined / len(rx), "fans": []}
    for fan in fans:
        opts = LaunchOptions(fan=fan)
        t = time.perf_counter()
        samples = edge_samples(scene, ctx, opts)
        samples_s = time.perf_counter() - t
        t = time.perf_counter()
        found = candidate_sequences(scene, ctx, rx, opts, samples)
        fans_s = time.perf_counter() - t
        keys = found.keys()
        per: dict[str, list] = {}
        got_power = 0.0
        missed = []
        for key, ab, p in ref:
            # E-D-R (0R-D-0R) sequences are enumerated by the launched tiles, not sampled
            hit = ab == (0, 0) or key in keys
            x = per.setdefault(f"{ab[0]}R-D-{ab[1]}R", [0, 0])
            x[0] += 1
            x[1] += hit
            got_power += p * hit
            if not hit:
                missed.append({"receiver": key[0], "before_and_edge": list(key[1]), "after": list(key[2]),
                               "gain_db": 10 * np.log10(max(p, 1e-300))})
        row = {"fan": fan, "samples": len(samples), "samples_per_order": np.bincount(samples.order).tolist(),
               "samples_s": samples_s, "fans_s": fans_s, "candidates_per_receiver": len(found) / len(rx),
               "found": len(ref) - len(missed), "found_fraction": (len(ref) - len(missed)) / max(len(ref), 1),
               "power_fraction": got_power / total_power if total_power > 0 else 1.0,
               "per_order": {k: {"paths": v[0], "found": v[1]} for k, v in sorted(per.items())},
               "missed": missed}
        out["fans"].append(row)
        progress(f"launch: fan {fan}: {row['found']}/{len(ref)} sequences, power {row['power_fraction']:.4f}, "
                 f"{row['candidates_per_receiver']:.0f} candidates per receiver, samples {samples_s:.1f} s, "
                 f"fans {fans_s:.1f} s")
    return out
