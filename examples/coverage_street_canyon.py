"""Coverage map of the built-in street canyon, split by mechanism.

    python examples/coverage_street_canyon.py --out out/examples            # 2 m cells, ~10 s
    python examples/coverage_street_canyon.py --out out/examples --cell 0.5 # finer
    python examples/coverage_street_canyon.py --dask tcp://scheduler:8786   # on a Dask cluster

Writes ``street_canyon_coverage.png`` (path gain, received power, field strength),
``street_canyon_mechanisms.png`` (line of sight, reflections, diffraction, each as a power
sum) and ``street_canyon_coverage.npz``. Traces line of sight, reflections up to order 2
and first-order diffraction with one reflection before or after it.
"""

from __future__ import annotations

import argparse
import os

import numpy as np
from matplotlib.figure import Figure

from wavepaths import TraceOptions, load_scene
from wavepaths.coverage import CoverageOptions, PlanarGrid, coverage
from wavepaths.coverage.plot import color_range, plot_coverage
from wavepaths.fields import FieldConfig


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/examples", help="output folder")
    parser.add_argument("--cell", type=float, default=2.0, help="cell size [m] (default 2)")
    parser.add_argument("--workers", type=int, default=None, help="local processes (default: one per core)")
    parser.add_argument("--dask", metavar="ADDRESS", help="Dask scheduler address")
    args = parser.parse_args()

    scene = load_scene("street_canyon")
    tx = [-60.0, 0.0, 10.0]
    # the scene's footprint, shifted by a quarter cell so that no cell centre lies exactly
    # on a building wall (a receiver on a wall is on the boundary of "inside")
    lo, hi = scene.bounds
    grid = PlanarGrid(center=0.5 * (lo[:2] + hi[:2]) + 0.25 * args.cell, size=hi[:2] - lo[:2],
                      cell_size=args.cell, height=1.5)
    options = TraceOptions(max_reflections=2, diffraction=True, diffraction_reflections=1)
    fields = FieldConfig(frequency_hz=3.5e9, tx_power_dbm=30.0)
    client = None
    if args.dask:
        from distributed import Client

        client = Client(args.dask)
    try:
        cmap = coverage(scene, tx, grid, options, fields=fields, settings=CoverageOptions(workers=args.workers),
                        client=client, progress=True)
    finally:
        if client is not None:
            client.close()
    os.makedirs(args.out, exist_ok=True)
    npz = cmap.save(os.path.join(args.out, "street_canyon_coverage.npz"))

    fig = Figure(figsize=(9, 10), layout="constrained")
    for ax, q in zip(fig.subplots(3, 1), ("path_gain_db", "received_power_dbm", "field_strength_dbuv_m"), strict=True):
        plot_coverage(cmap, q, ax=ax, scene=scene)
    fig.savefig(os.path.join(args.out, "street_canyon_coverage.png"), dpi=120)

    # the mechanisms on one colour scale
    lo, hi = color_range(cmap.path_gain_db(coherent=False))
    fig = Figure(figsize=(9, 10), layout="constrained")
    for ax, q in zip(fig.subplots(3, 1), ("los_gain_db", "reflection_gain_db", "diffraction_gain_db"), strict=True):
        plot_coverage(cmap, q, ax=ax, scene=scene, vmin=lo, vmax=hi)
    fig.savefig(os.path.join(args.out, "street_canyon_mechanisms.png"), dpi=120)

    gain = cmap.path_gain_db()
    outside = ~cmap.inside
    print(f"{cmap.num_cells} cells ({cmap.shape[0]} x {cmap.shape[1]}, {args.cell} m), "
          f"{int(cmap.inside.sum())} inside buildings; {cmap.elapsed_s:.1f} s, "
          f"{cmap.cells_per_second:.0f} cells/s ({cmap.metadata['workers']})")
    reached = outside & np.isfinite(gain)
    print(f"path gain {np.nanmin(gain[reached]):.1f} .. {np.nanmax(gain[reached]):.1f} dB; "
          f"{int((outside & np.isneginf(gain)).sum())} cells reached by no path of these orders")
    for m in ("los", "reflection", "diffraction"):
        share = (cmap.mechanism_gain(m)[reached] / cmap.path_gain(coherent=False)[reached])
        print(f"  {m:<12} carries {100 * np.mean(share):5.1f} % of the power on average")
    print(f"wrote {args.out}/street_canyon_coverage.png, street_canyon_mechanisms.png and {npz}")


if __name__ == "__main__":
    main()
