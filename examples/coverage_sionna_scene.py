"""Coverage map of a Sionna RT built-in scene, read from the installed sionna-rt package.

    python examples/coverage_sionna_scene.py --out out/examples                      # simple_street_canyon
    python examples/coverage_sionna_scene.py --out out/examples --scene etoile --cell 5 --tx 0 60 30

The scene's Mitsuba XML is found in the sionna-rt package folder
(``sionna/rt/scenes/<name>/<name>.xml``) through ``importlib.util.find_spec`` without
importing Sionna (no Dr.Jit, no LLVM needed). Without sionna-rt the script says so and
exits 0. Writes ``<name>_coverage.png`` and ``<name>_coverage.npz``.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys

from wavepaths import TraceOptions, load_scene
from wavepaths.coverage import CoverageOptions, PlanarGrid, coverage
from wavepaths.coverage.plot import save_png
from wavepaths.fields import FieldConfig


def sionna_scene_path(name: str) -> str | None:
    """The XML file of Sionna RT's built-in scene ``name``, or None when sionna-rt is absent."""
    spec = importlib.util.find_spec("sionna")
    if spec is None or not spec.submodule_search_locations:
        return None
    for root in spec.submodule_search_locations:
        path = os.path.join(root, "rt", "scenes", name, f"{name}.xml")
        if os.path.exists(path):
            return path
    return None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/examples", help="output folder")
    parser.add_argument("--scene", default="simple_street_canyon", help="Sionna RT scene name")
    parser.add_argument("--cell", type=float, default=2.0, help="cell size [m] (default 2)")
    parser.add_argument("--height", type=float, default=1.5, help="grid height [m] (default 1.5)")
    parser.add_argument("--tx", nargs=3, type=float, default=[-33.0, 11.0, 32.0], metavar=("X", "Y", "Z"))
    parser.add_argument("--workers", type=int, default=None)
    args = parser.parse_args()

    path = sionna_scene_path(args.scene)
    if path is None:
        print(f"skipped: Sionna RT's scene {args.scene!r} is not installed (pip install 'wavepaths[sionna]')")
        return 0
    scene = load_scene(path)
    lo, hi = scene.bounds
    # the footprint, shifted by a quarter cell so that no cell centre lies on a wall
    grid = PlanarGrid(center=0.5 * (lo[:2] + hi[:2]) + 0.25 * args.cell, size=hi[:2] - lo[:2],
                      cell_size=args.cell, height=args.height)
    cmap = coverage(scene, args.tx, grid, TraceOptions(max_reflections=2, diffraction=True),
                    fields=FieldConfig(frequency_hz=3.5e9), settings=CoverageOptions(workers=args.workers),
                    progress=True)
    os.makedirs(args.out, exist_ok=True)
    npz = cmap.save(os.path.join(args.out, f"{args.scene}_coverage.npz"))
    png = save_png(cmap, os.path.join(args.out, f"{args.scene}_coverage.png"), scene=scene,
                   title=f"Sionna RT scene {args.scene}: path gain [dB]")
    print(f"{args.scene}: {scene.num_triangles} triangles; {cmap.num_cells} cells, "
          f"{int(cmap.inside.sum())} inside buildings; {cmap.elapsed_s:.1f} s ({cmap.cells_per_second:.0f} cells/s)")
    print(f"wrote {png} and {npz}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
