"""Path search: line of sight, image-method reflections, first-order diffraction."""

from .context import TxContext, build_tx_context
from .options import TraceOptions
from .paths import InteractionType, Paths
from .trace import trace

__all__ = ["InteractionType", "Paths", "TraceOptions", "TxContext", "build_tx_context", "trace"]
