"""wavepaths: exact, complete radio propagation paths and their fields in polygonal scenes.

The package reads like its data flow::

    scene file -> Scene -> Dihedra -> TxContext -> paths per receiver tile -> Paths -> fields

Importing it has no side effects: no global state, no Sionna, no Mitsuba variant.
"""

from .errors import WavepathsError
from .scene import Scene, SceneTolerances, build_scene, load_scene, write_mitsuba_xml
from .search import InteractionType, Paths, TraceOptions, build_tx_context, trace

__version__ = "0.1.0"

__all__ = [
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
