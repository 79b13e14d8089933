"""``wavepaths coverage``: a coverage map from the command line (a thin layer over
:func:`wavepaths.coverage.coverage`), written as a PNG and an ``.npz``."""

from __future__ import annotations

import argparse
import os

import numpy as np

from ..errors import DependencyError, WavepathsError

QUANTITIES = ("path_gain_db", "received_power_dbm", "field_strength_dbuv_m", "los_gain_db", "reflection_gain_db",
              "diffraction_gain_db")


def add_parser(sub) -> argparse.ArgumentParser:
    """Register the ``coverage`` subcommand on the ``wavepaths`` parser's subparsers."""
    from ..cli import _add_field_flags, _add_trace_flags, add_scene_arguments

    p = sub.add_parser(
        "coverage",
        help="coverage map (path gain, received power, field strength) over a grid of receivers",
        description="Trace every cell of a horizontal grid (or the faces of a measurement mesh) and write "
                    "DIR/coverage.png and DIR/coverage.npz.",
    )
    add_scene_arguments(p)
    p.add_argument("--tx", nargs=3, type=float, action="append", required=True, metavar=("X", "Y", "Z"),
                   help="transmitter position [m]; repeat for several (the map shows the best server)")
    p.add_argument("--height", type=float, help="height z of the grid [m] (planar grid)")
    p.add_argument("--cell", type=float, help="cell size [m] (planar grid)")
    p.add_argument("--size", nargs=2, type=float, metavar=("SX", "SY"),
                   help="grid extent in x and y [m] (default: the scene's footprint)")
    p.add_argument("--center", nargs=2, type=float, metavar=("X", "Y"),
                   help="grid centre [m] (default: the centre of the scene's footprint)")
    p.add_argument("--mesh", metavar="FILE", help="measurement mesh: its faces are the cells (instead of a grid)")
    p.add_argument("--out", default=".", metavar="DIR", help="output folder (default: the current one)")
    par = p.add_mutually_exclusive_group()
    par.add_argument("--workers", type=int,
                     help="local processes; 1: this process (default: this process for a small map, "
                          "else one per core)")
    par.add_argument("--dask", metavar="ADDRESS", help="run the tiles on the Dask scheduler at ADDRESS")
    p.add_argument("--threads", type=int, default=None,
                   help="tiles traced at once on threads when they run in this process (default: one per core)")
    p.add_argument("--tile-size", type=int, default=None,
                   help="cells traced together (default: from the scene's image counts, 16 to 1024)")
    p.add_argument("--incoherent", action="store_true", help="add path powers instead of complex amplitudes")
    p.add_argument("--keep-inside", action="store_true",
                   help="trace cells inside solid objects too (rooms covered from inside)")
    p.add_argument("--quantity", choices=QUANTITIES, default="path_gain_db", help="what the PNG shows")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    _add_trace_flags(p)
    p.add_argument("--tolerance-db", type=float, default=None,
                   help="drop diffracted contributions, weakest first, while they change no cell's power-sum "
                        "total by more than this many dB (bound in TraceOptions.tolerance_db; UTD model)")
    _add_field_flags(p)
    p.set_defaults(func=run)
    return p


def _grid(args, scene):
    from ..search.trace import check_positions
    from .grid import MeshGrid, PlanarGrid

    if args.mesh:
        if args.height is not None or args.cell is not None or args.size or args.center:
            raise WavepathsError("--mesh replaces the planar grid: leave out --height, --cell, --size and --center")
        if not os.path.exists(args.mesh):
            raise WavepathsError(f"{args.mesh}: no such measurement mesh")
        grid = MeshGrid.from_file(args.mesh, up_axis=getattr(args, "up_axis", "auto"))  # turned as the scene is
        check_positions(f"--mesh {args.mesh}: cell centres", grid.cell_centers(), allow_empty=True)
        return grid
    missing = [f for f, v in (("--height", args.height), ("--cell", args.cell)) if v is None]
    if missing:
        raise WavepathsError(f"a planar grid needs {' and '.join(missing)} (or give --mesh FILE)")
    lo, hi = scene.bounds
    center = np.array(args.center if args.center else 0.5 * (lo[:2] + hi[:2]), dtype=float)
    size = np.array(args.size if args.size else hi[:2] - lo[:2], dtype=float)
    check_grid_reach(args.height, center, size)
    if np.isfinite(args.cell) and np.isfinite(size).all() and args.cell > 0 and args.cell > np.abs(size).max():
        raise WavepathsError(f"--cell {args.cell:g} m is larger than the area ({' x '.join(f'{v:g}' for v in size)} m"
                             f"{', --size' if args.size else ', the scene footprint'}): a map of one cell that "
                             "overhangs it; give a smaller --cell")
    return PlanarGrid(center=center, size=size, cell_size=args.cell, height=args.height)


def check_grid_reach(height: float, center: np.ndarray, size: np.ndarray) -> None:
    """Refuse a planar grid that reaches beyond the coordinates the search accepts.

    ``paths`` refuses a receiver beyond :data:`~wavepaths.search.trace.MAX_COORDINATE`
    metres (:func:`~wavepaths.search.trace.check_positions`); a grid's cells are receivers
    too, and met no such check.

    Parameters
    ----------
    height : float
        ``--height`` [m].
    center : (2,) array_like
        ``--center`` [m] (or the scene's footprint centre).
    size : (2,) array_like
        ``--size`` [m] (or the scene's footprint).

    Raises
    ------
    WavepathsError
        A finite ``--height``, ``--center`` or grid edge beyond the limit (non-finite values
        are left to :class:`~wavepaths.coverage.grid.PlanarGrid`, which names them).
    """
    from ..search.trace import MAX_COORDINATE

    why = "(float64 cannot resolve wavelengths there)"
    c = np.asarray(center, dtype=float)
    half = 0.5 * np.abs(np.asarray(size, dtype=float))
    for flag, values in (("--height", np.array([height], dtype=float)), ("--center", c)):
        if np.isfinite(values).all() and (np.abs(values) > MAX_COORDINATE).any():
            shown = " ".join(f"{v:g}" for v in values)
            raise WavepathsError(f"{flag} {shown} is beyond {MAX_COORDINATE:g} m {why}")
    reach = np.abs(c) + half
    if np.isfinite(reach).all() and (reach > MAX_COORDINATE).any():
        raise WavepathsError(f"--size {' '.join(f'{v:g}' for v in 2 * half)} around --center "
                             f"{' '.join(f'{v:g}' for v in c)} reaches beyond {MAX_COORDINATE:g} m {why}")


def _client(address: str):
    try:
        from distributed import Client
    except ImportError:
        raise DependencyError("--dask needs `distributed`: pip install 'wavepaths[dask]'") from None
    try:
        return Client(address, timeout=30)
    except (OSError, TimeoutError) as exc:
        raise WavepathsError(f"cannot reach the Dask scheduler at {address} ({exc})") from None
    except (ValueError, TypeError) as exc:  # not an address distributed can parse
        raise WavepathsError(f"--dask {address!r} is not a Dask scheduler address such as "
                             f"tcp://HOST:8786 ({exc})") from None


def run(args) -> int:
    from ..cli import _field_config, _scene, _trace_options, json_text, plural
    from .plot import save_png
    from .solver import CoverageOptions, coverage

    fields = _field_config(args)  # checked before any work
    scene = _scene(args)
    grid = _grid(args, scene)
    settings = CoverageOptions(tile_size=args.tile_size, coherent=not args.incoherent, workers=args.workers,
                               threads=args.threads, mask_inside=not args.keep_inside)
    # (--tolerance-db on a coherent map is warned about by coverage() itself)
    tx = np.array(args.tx, dtype=float).reshape(-1, 3)
    client = _client(args.dask) if args.dask else None
    try:
        cmap = coverage(scene, tx, grid, _trace_options(args), fields=fields, settings=settings,
                        client=client, progress=not args.quiet)
    finally:
        if client is not None:
            client.close()
    os.makedirs(args.out, exist_ok=True)
    # an earlier run's map in the same folder is replaced: said, not silent
    replaced = [p for p in (os.path.join(args.out, name) for name in ("coverage.npz", "coverage.png"))
                if os.path.exists(p)]
    npz = cmap.save(os.path.join(args.out, "coverage.npz"))
    png = save_png(cmap, os.path.join(args.out, "coverage.png"), args.quantity, scene=scene,
                   title=f"{os.path.basename(str(scene.source))}: {args.quantity}")
    values = cmap.quantity(args.quantity)
    finite = values[np.isfinite(values)]
    summary = {
        "scene": scene.source,
        "shape": list(cmap.shape),
        "cells": cmap.num_cells,
        "cells_inside_objects": int(cmap.inside.sum()),
        "cells_without_paths": int(cmap.without_paths().sum()),
        "cells_without_quantity": int((np.isneginf(values) & ~cmap.inside).sum()),
        "elapsed_s": cmap.elapsed_s,
        "cells_per_second": cmap.cells_per_second,
        "ran_on": cmap.metadata["workers"],
        "quantity": args.quantity,
        "min": float(finite.min()) if finite.size else None,
        "max": float(finite.max()) if finite.size else None,
        "png": png,
        "npz": npz,
        "replaced": replaced,  # the files of an earlier run that these replaced
        # the settings behind the numbers, as the .npz's metadata and ``paths --json`` name them
        "tx_power_dbm": cmap.metadata["field_config"]["tx_power_dbm"],
        "trace_options": cmap.metadata["trace_options"],
        "field_config": cmap.metadata["field_config"],
        "coverage_options": cmap.metadata["coverage_options"],
        # where and at what frequency: named as ``paths --json`` names them ("tx", "frequency_hz")
        # and as the .npz's metadata names the grid; "coherent" says how min / max add the paths
        "frequency_hz": cmap.frequency_hz,
        "tx": np.asarray(cmap.tx_positions, dtype=float).tolist(),
        "grid": cmap.grid.describe(),
        "coherent": bool(cmap.coherent),
    }
    if args.json:
        print(json_text(summary))
        return 0
    print(f"coverage of {scene.source}: {plural(cmap.num_cells, 'cell')} ({' x '.join(map(str, cmap.shape))}), "
          f"{summary['cells_inside_objects']} inside objects, {summary['cells_without_paths']} without paths")
    if summary["cells_without_quantity"] != summary["cells_without_paths"]:
        print(f"{args.quantity}: -inf dB on {plural(summary['cells_without_quantity'], 'cell')} (no path of its kind)")
    print(f"{cmap.elapsed_s:.2f} s ({cmap.cells_per_second:.0f} cells/s, {summary['ran_on']})")
    if finite.size:
        print(f"{args.quantity}: {summary['min']:.1f} .. {summary['max']:.1f}")
    print(f"wrote {png} and {npz}" + (f" (replacing the earlier {' and '.join(map(os.path.basename, replaced))})"
                                        if replaced else ""))
    return 0
