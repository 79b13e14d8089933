"""Coverage behind a knife-edge hill, against ITU-R P.526's single knife edge.

    python examples/coverage_knife_edge.py --out out/examples       # 5 m cells, a few seconds

A ridge 50 m high with a sharp crest (its two flanks meet at 22 degrees) runs along y;
there is no ground, so that the field behind the crest is the crest's diffraction
alone and can be read against the Fresnel-Kirchhoff knife edge (ITU-R P.526 section 4.1,
:mod:`wavepaths.exact.knife_edge`). The map is the vertical plane y = 0.3 m through the
transmitter (u = x, v = z); the second panel follows one row of it behind the hill,
20 m above the foot of the ridge, against ``free space - J(nu)``.
Writes ``knife_edge_coverage.png`` and ``knife_edge_coverage.npz``.
"""

from __future__ import annotations

import argparse
import os

import numpy as np
from matplotlib.figure import Figure

from wavepaths import TraceOptions
from wavepaths.coverage import CoverageOptions, PlanarGrid, coverage
from wavepaths.coverage.plot import plot_coverage
from wavepaths.em.materials import itu_material
from wavepaths.exact.knife_edge import fresnel_nu, knife_edge_loss_db
from wavepaths.fields import FieldConfig
from wavepaths.scene import build_scene

CREST_Z = 50.0
HALF_BASE = 10.0
LENGTH = 2000.0  # along y: far longer than the map, so the ridge's ends do not matter


def ridge_scene():
    """Two flanks of ground material meeting at the crest (x = 0, z = 50)."""
    h = LENGTH / 2
    v = np.array([[-HALF_BASE, -h, 0], [-HALF_BASE, h, 0], [0, h, CREST_Z], [0, -h, CREST_Z],
                  [HALF_BASE, -h, 0], [HALF_BASE, h, 0]], float)
    t = np.array([[0, 3, 2], [0, 2, 1], [4, 5, 2], [4, 2, 3]])
    return build_scene(v, t, np.zeros(4, int), np.zeros(4, int), ["ridge"],
                       [itu_material("medium_dry_ground")], source="knife_edge_ridge")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/examples", help="output folder")
    parser.add_argument("--cell", type=float, default=5.0, help="cell size [m] (default 5)")
    parser.add_argument("--frequency", type=float, default=1.8e9, help="carrier frequency [Hz] (default 1.8e9)")
    parser.add_argument("--workers", type=int, default=None)
    args = parser.parse_args()

    scene = ridge_scene()
    tx = np.array([-400.0, 0.0, 30.0])
    grid = PlanarGrid(center=[100.0, 0.3, 60.0], size=[1000.0, 120.0], cell_size=args.cell,
                      orientation=[0, 0, np.pi / 2])
    fields = FieldConfig(frequency_hz=args.frequency)
    cmap = coverage(scene, tx, grid, TraceOptions(max_reflections=1, diffraction=True, diffraction_reflections=0),
                    fields=fields, settings=CoverageOptions(workers=args.workers), progress=True)
    os.makedirs(args.out, exist_ok=True)
    npz = cmap.save(os.path.join(args.out, "knife_edge_coverage.npz"))

    # one row behind the hill against free space minus the knife-edge loss J(nu)
    centres = cmap.cell_centers
    row = int(np.argmin(np.abs(centres[:, 0, 2] - 20.0)))
    rx = centres[row]
    behind = rx[:, 0] > 2 * HALF_BASE
    rx = rx[behind]
    got = cmap.path_gain_db()[row][behind]
    lam = fields.wavelength
    d1 = np.hypot(-tx[0], CREST_Z - tx[2])  # transmitter to crest, in the x-z plane
    d2 = np.hypot(rx[:, 0], CREST_Z - rx[:, 2])
    d = np.linalg.norm(rx - tx, axis=1)
    # height of the crest above the straight transmitter-receiver line
    line_z = tx[2] + (rx[:, 2] - tx[2]) * (0 - tx[0]) / (rx[:, 0] - tx[0])
    nu = fresnel_nu(CREST_Z - line_z, d1, d2, lam)
    free_space = 20 * np.log10(lam / (4 * np.pi * d))
    itu = free_space - knife_edge_loss_db(nu)

    fig = Figure(figsize=(10, 8), layout="constrained")
    ax_map, ax_cut = fig.subplots(2, 1, height_ratios=[1.4, 1])
    plot_coverage(cmap, ax=ax_map, scene=scene, dynamic_range_db=70, aspect="auto",
                  title=f"knife-edge hill, {args.frequency / 1e6:g} MHz: path gain [dB]")
    ax_map.axhline(rx[0, 2], color="w", lw=0.8, ls="--")
    ax_cut.plot(rx[:, 0], got, "o-", ms=3, label="wavepaths (UTD, ground flanks)")
    ax_cut.plot(rx[:, 0], itu, "-", label="free space - J(nu), ITU-R P.526")
    ax_cut.plot(rx[:, 0], free_space, ":", color="0.5", label="free space")
    ax_cut.set_xlabel("x [m]")
    ax_cut.set_ylabel("path gain [dB]")
    ax_cut.set_title(f"behind the hill at z = {rx[0, 2]:.1f} m")
    ax_cut.legend()
    png = os.path.join(args.out, "knife_edge_coverage.png")
    fig.savefig(png, dpi=120)
    diff = got - itu
    print(f"{cmap.num_cells} cells in {cmap.elapsed_s:.1f} s; behind the hill at z = {rx[0, 2]:.1f} m, "
          f"wavepaths - ITU knife edge: median {np.median(diff):+.2f} dB, "
          f"range {diff.min():+.2f} .. {diff.max():+.2f} dB")
    print(f"wrote {png} and {npz}")


if __name__ == "__main__":
    main()
