"""Cells and transmitters lying exactly on faces, in a coverage map.

A cell centre on a solid's surface is masked like the cells inside it (the ray-parity inside
test answers either way on a surface); one on another face is traced, and both are counted
in a warning (:func:`cells_on_faces`, :func:`warn_cells_on_faces`). A path whose first leg
leaves a transmitter on a solid's face into that solid is dropped (:func:`outside_solids`).
docs/coverage.md, docs/stress.md (S16-S18).
"""

from __future__ import annotations

import warnings
from collections import Counter

import numpy as np

from ..scene.model import Scene, WavepathsWarning
from ..search.context import TxContext
from ..search.on_faces import points_on_faces
from ..search.paths import Paths


def cells_on_faces(scene: Scene, flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(faces, on_solid)`` of cell centres ``flat``: a polygon each lies exactly on (-1: none,
    :func:`~wavepaths.search.on_faces.points_on_faces`) and whether it lies on a face of a
    solid object. Skipped (none on a face) beyond the on-face test's budget of point x polygon tests."""
    from ..scene.closed import solid_objects_mask
    from ..search.on_faces import points_on_surfaces

    faces = points_on_faces(scene, flat)
    on_solid = np.zeros(len(flat), bool)
    if (faces >= 0).any():
        rows = np.nonzero(faces >= 0)[0]
        on_solid[rows] = points_on_surfaces(scene, flat[rows])[:, solid_objects_mask(scene)].any(axis=1)
    return faces, on_solid


def warn_cells_on_faces(scene: Scene, flat: np.ndarray, active: np.ndarray, face: np.ndarray,
                         masked: int = 0) -> None:
    """Warn when cell centres lie exactly on a face (a grid whose centres fall on walls: the
    street canyon's footprint grid at 2 m put whole columns on them). Those on a solid's
    surface (``masked`` of them) are masked like the cells inside it; the others (a ground, a
    screen) are traced, with fields that are the limit from neither side of the face."""
    on = np.nonzero(face >= 0)[0]  # face: points_on_faces of the active cells
    if len(on) or masked:
        first = (f" (first traced: cell {int(active[on[0]])} at {flat[active[on[0]]].tolist()}, object "
                 f"{scene.object_names[scene.polygon_object[face[on[0]]]]})") if len(on) else ""
        warnings.warn(
            f"{len(on) + masked} cell centres lie exactly on a face: {masked} on the surface of a solid object, "
            f"masked like the cells inside it; {len(on)} traced{first}, taking part in no reflection or "
            "diffraction on that face, their fields the limit from neither side; offset the grid by a fraction "
            "of a cell or change its height (PlanarGrid's `center` and `height`, --center and --height)",
            WavepathsWarning, stacklevel=3,
        )


def outside_solids(scene: Scene, ctx: TxContext, paths: Paths, stats: Counter) -> Paths:
    """``paths`` without those whose first leg enters a solid from a transmitter lying on its
    surface (:func:`wavepaths.search.on_faces.legs_into_solids`; the cells on a solid's
    surface are masked). The transmitters' faces are found once per context."""
    from ..search.on_faces import legs_into_solids, solid_surface_cones

    cones = ctx.derived.get("tx_solid_cones")
    if cones is None:
        cones = ctx.derived["tx_solid_cones"] = solid_surface_cones(scene, ctx.tx)
    if not cones:
        return paths
    inward = legs_into_solids(paths, cones, {})
    stats["paths_dropped_into_solid"] = int(inward.sum())  # of the tile's last assembly (all its paths)
    return paths.select(~inward) if inward.any() else paths
