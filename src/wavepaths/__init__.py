"""wavepaths: exact, complete radio propagation paths and their fields in polygonal scenes.

The package reads like its data flow::

    scene file -> Scene -> Dihedra -> TxContext -> paths per receiver tile -> Paths -> fields

Importing it has no side effects: no global state, no Sionna, no Mitsuba variant.
"""

from .errors import WavepathsError
from .scene import Scene, SceneTolerances, build_scene, load_scene, write_mitsuba_xml
from .search import InteractionType, Paths, TraceOptions, build_tx_context, trace
from .fields import FieldConfig, FieldResult, compute_fields
from .coverage import CoverageMap, CoverageOptions, MeshGrid, PlanarGrid, load_coverage
from .coverage import coverage as coverage  # the function; the subpackage stays importable as wavepaths.coverage.<module>

__version__ = "0.1.0"

__all__ = [
    "CoverageMap",
    "CoverageOptions",
    "FieldConfig",
    "FieldResult",
    "MeshGrid",
    "PlanarGrid",
    "compute_fields",
    "coverage",
    "load_coverage",
    "InteractionType",
    "Paths",
    "Scene",
    "SceneTolerances",
    "TraceOptions",
    "WavepathsError",
    "build_scene",
    "build_tx_context",
    "load_scene",
    "trace",
    "write_mitsuba_xml",
    "__version__",
]
