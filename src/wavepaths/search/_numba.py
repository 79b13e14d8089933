"""The numba kernels behind :mod:`wavepaths.search.kernels`, gathered from their modules.

Imported only when numba is installed. Each kernel is the compiled twin of a numpy
reference named in its comment; the public wrappers, with the documented shapes and units,
are in :mod:`wavepaths.search.kernels`. The kernels live in one module per job; this one
re-exports them, so that callers reach them as ``_numba.<kernel>`` (looked up at call
time):

* :mod:`wavepaths.search._numba_end_sides`: the receiver side's pair tests
  (:func:`receiver_pairs`, :func:`receiver_pairs_serial`, with ``_receiver_rows`` and
  ``ROWS``, which :mod:`wavepaths.search._numba_reach` shares) and the end sides' frame and
  sector lookup (:func:`end_sides`);
* :mod:`wavepaths.search._numba_beams`: the beams through the chains' mirrors
  (:func:`chain_side_planes`), the reflection candidates (:func:`reflection_pairs`,
  :func:`reflection_pairs_flat`) and the chains meeting the edges (:func:`chains_edges`);
* :mod:`wavepaths.search._numba_images`: the image trees' exact tests (:func:`admissible`)
  and the back-traces of the image method (:func:`backtrace`);
* :mod:`wavepaths.search._numba_diffraction`: the join with the closed-form point
  (:func:`joined_candidates`), the Keller-cone culling (:func:`keller_cone_keep`) and the
  diffracted candidates' vertices (:func:`diffraction_vertices`);
* :mod:`wavepaths.search._numba_chains`: the degenerate chains (:func:`degenerate_chains`);
* :mod:`wavepaths.search._numba_order`: the ordering of paths (:func:`key_length_order`,
  with ``_counting_sort``, which :mod:`wavepaths.search._numba_tolerance` shares).

The other compiled loops are imported from their own modules: ``_numba_reach``,
``_numba_windows``, ``_numba_mirrors``, ``_numba_tolerance``, ``_numba_launch``.
"""

from ._numba_beams import chain_side_planes, chains_edges, reflection_pairs, reflection_pairs_flat
from ._numba_chains import degenerate_chains
from ._numba_diffraction import diffraction_vertices, joined_candidates, keller_cone_keep
from ._numba_end_sides import ROWS, _receiver_rows, end_sides, receiver_pairs, receiver_pairs_serial
from ._numba_images import admissible, backtrace
from ._numba_order import _counting_sort, key_length_order

__all__ = [
    "ROWS", "_counting_sort", "_receiver_rows", "admissible", "backtrace", "chain_side_planes", "chains_edges",
    "degenerate_chains", "diffraction_vertices", "end_sides", "joined_candidates", "keller_cone_keep",
    "key_length_order", "receiver_pairs", "receiver_pairs_serial", "reflection_pairs", "reflection_pairs_flat",
]
