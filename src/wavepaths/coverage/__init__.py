"""Coverage maps: path gain, received power and field strength over a grid of receivers.

Built on the path engine: the transmitter-side work is done once
(:func:`~wavepaths.search.build_tx_context`), the cells are traced in vectorised tiles
(:func:`~wavepaths.search.tile.trace_tile`), and the tiles run in this process, in a local
process pool or on a Dask cluster (:mod:`wavepaths.coverage.parallel`). A cell's value is
exactly :func:`wavepaths.trace` + :func:`wavepaths.fields.compute_fields` at its centre.
See ``docs/coverage.md``.
"""

from .grid import MeshGrid, PlanarGrid
from ..scene.solids import inside_solid_objects, solid_objects
from .result import MECHANISMS, CoverageMap, field_strength_dbuv_m
from .solver import CoverageOptions, coverage, solve_tile

load_coverage = CoverageMap.load

__all__ = [
    "MECHANISMS",
    "CoverageMap",
    "CoverageOptions",
    "MeshGrid",
    "PlanarGrid",
    "coverage",
    "field_strength_dbuv_m",
    "inside_solid_objects",
    "load_coverage",
    "solid_objects",
    "solve_tile",
]
