"""Mesh files that store their coordinates in float32, far from the origin.

Binary PLY files (and ASCII ones whose ``x`` is declared ``float``), binary STL and glTF/GLB
store vertex positions as float32, which rounds a coordinate ``c`` to within
``|c| 2^-24`` (half its spacing). Near the origin that is about 3e-8 of a scene's size,
which the weld tolerance (1e-6 of the diagonal, :class:`~wavepaths.scene.tolerances.SceneTolerances`)
covers. In projected coordinates (UTM: ``y`` about 5.3e6 m) the same rounding is 0.3 m:
vertices that should coincide no longer weld, one wall becomes several polygons and edges
appear where there are none (a review's 6 x 6 city at UTM coordinates: 289 polygons
became 615, 427 diffracting dihedra 1,259, path gains moved by up to 10 dB), silently.
:func:`warn_float32_coordinates` says so when the rounding reaches a tenth of the weld
tolerance. The remedy is the file's, not the loader's: the precision is gone.
"""

from __future__ import annotations

import os
import warnings

import numpy as np

from .model import WavepathsWarning, external_stacklevel

FLOAT32_ROUNDING = 2.0**-24
"""Relative rounding of a float32 value (half its spacing)."""
WARN_FRACTION = 0.1
"""The rounding, as a fraction of the weld tolerance, from which the loader warns."""


def stores_float32(path: str) -> bool:
    """Whether the mesh file ``path`` stores its vertex positions as float32.

    A PLY file whose vertex ``x`` is a ``float`` (``float32``) property, a binary STL file
    (its size is 84 + 50 bytes per triangle), a glTF or GLB file (positions are float32 by
    the specification). OBJ, OFF and ASCII STL files are text, read in full precision.
    """
    ext = os.path.splitext(path)[1].lower()
    if ext in (".gltf", ".glb"):
        return True
    try:
        if ext == ".ply":
            from .ply_off_reader import _ply_header

            with open(path, "rb") as fh:
                head = fh.read(1 << 16)
            _, elements, _ = _ply_header(path, head)
            vertex = next((e for e in elements if e.name == "vertex"), None)
            x = next((p for p in vertex.properties if p.name == "x"), None) if vertex else None
            return x is not None and x.dtype == "f4"
        if ext == ".stl":
            size = os.path.getsize(path)
            with open(path, "rb") as fh:
                head = fh.read(84)
            return len(head) == 84 and size == 84 + 50 * int(np.frombuffer(head[80:84], "<u4")[0])
    except Exception:  # an unreadable header: the reader itself reports it
        return False
    return False


def float32_reach(path: str, local_vertices: np.ndarray) -> float:
    """The largest coordinate magnitude [file units] of ``local_vertices`` as file ``path``
    stores them, if it stores them as float32 (:func:`stores_float32`); else 0."""
    if len(local_vertices) == 0 or not stores_float32(path):
        return 0.0
    return float(np.abs(local_vertices).max())


def warn_float32_coordinates(source: str, reaches: list[tuple[str, float]], weld_m: float) -> None:
    """Warn when float32 rounding in the files of ``reaches`` (``(file, largest coordinate
    magnitude)``, as :func:`float32_reach` gives) reaches :data:`WARN_FRACTION` of the weld
    tolerance ``weld_m`` [m] of scene ``source``.

    The message names the worst file, its rounding and what to do: write the mesh around a
    local origin (a Mitsuba XML ``to_world`` translate places it, applied by wavepaths in
    float64) or in double precision.
    """
    if not reaches:
        return
    path, reach = max(reaches, key=lambda r: r[1])
    rounding = reach * FLOAT32_ROUNDING
    if not rounding >= WARN_FRACTION * weld_m:
        return
    more = f" (and {len(reaches) - 1} more file(s))" if len(reaches) > 1 else ""
    warnings.warn(
        f"{source}: {os.path.basename(path)}{more} stores its vertices as float32, with coordinates up to "
        f"{reach:.6g} from the origin: rounded to within {rounding:.2g} m, {rounding / weld_m:.2g} times the "
        f"scene's weld tolerance ({weld_m:.2g} m). Vertices that should coincide may not weld, walls split into "
        "several polygons and false edges diffract. Write the mesh around a local origin (placed by a Mitsuba "
        "XML to_world translate, which wavepaths applies in float64) or in double precision",
        WavepathsWarning, stacklevel=external_stacklevel())
