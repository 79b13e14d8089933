"""Benchmark 5: the cost of diffraction, the same coverage map with diffraction off and on.

The seed (§4) rendered its image 46 times slower with diffraction than without (270
polygons, 378 dihedra). Here: a coverage map of ``simple_street_canyon`` (2 m cells at
1.5 m height, 88 x 60 cells, the cells inside buildings masked), with reflections and
without diffraction, then the same reflections plus diffraction:

* ``R2 / R2+D1`` (the headline, ``diffraction_cost_ratio``): reflections to order 2,
  then diffraction with one reflection before or after it (R-D, D-R) added, the
  default options of :func:`wavepaths.coverage.coverage`;
* ``R2 / R2+D2``: diffraction with up to two reflections (also R-D-R, R-R-D, D-R-R);
* ``R3 / R3+D2``: Sionna's depth 3 (benchmark 2's path types).

The two maps of a pair are timed in alternation, ``repeats`` times each, and the ratio of
medians is reported. One process (``workers=1``).
"""

from __future__ import annotations

import time

import numpy as np

from .scenes import STREET_CANYON_TX
from .timing import interleaved

SEED_RATIO = 46.0
PAIRS = [
    ("R2", {"max_reflections": 2, "diffraction": False}, "R2+D1",
     {"max_reflections": 2, "diffraction": True, "diffraction_reflections": 1}),
    ("R2", {"max_reflections": 2, "diffraction": False}, "R2+D2",
     {"max_reflections": 2, "diffraction": True, "diffraction_reflections": 2}),
    ("R3", {"max_reflections": 3, "diffraction": False}, "R3+D2",
     {"max_reflections": 3, "diffraction": True, "diffraction_reflections": 2}),
]


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
    settings = CoverageOptions(workers=1)
    pairs = PAIRS[:1] if quick else PAIRS
    rounds = 1 if quick else repeats
    results = []
    last = {}

    def runner(opts):
        def run():
            last["map"] = coverage(scene, STREET_CANYON_TX, grid, TraceOptions(**opts), fields=cfg, settings=settings)
        return run

    runner(PAIRS[0][1])()  # warm-up
    for off_name, off, on_name, on in pairs:
        progress(f"benchmark 5: {off_name} against {on_name}, {grid.shape[0]} x {grid.shape[1]} cells")
        times = interleaved({"off": runner(off), "on": runner(on)}, rounds if on_name != "R3+D2" else 1)
        m = last["map"]
        results.append({"off": off_name, "on": on_name, "off_options": off, "on_options": on,
                        "off_s": times["off"].as_dict(), "on_s": times["on"].as_dict(),
                        "ratio": times["on"].median_s / times["off"].median_s,
                        "cells_traced": int(m.metadata["cells_traced"]),
                        "diffracted_paths": int(np.nansum(m.num_paths[2])),
                        "all_paths": int(np.nansum(m.num_paths))})
    return {"scene": "simple_street_canyon", "grid_shape": list(grid.shape), "cell_size_m": cell,
            "pairs": results, "diffraction_cost_ratio": results[0]["ratio"], "headline_pair": "R2 / R2+D1",
            "seed_ratio": SEED_RATIO, "target_ratio_max": 3.0}
