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


def cells_on_faces(scene: Scene, flat: np.ndarray, solids=None) -> tuple[np.ndarray, np.ndarray]:
    """``(faces, on_solid)`` of cell centres ``flat``: a polygon each lies exactly on (-1: none,
    :func:`~wavepaths.search.on_faces.points_on_faces`) and whether it lies on a solid's
    surface. Skipped (none on a face) beyond the on-face test's budget of point x polygon tests.

    On a solid's surface: on a face of a closed object (:func:`~wavepaths.scene.closed.solid_objects_mask`),
    or where the face bounds a solid of the inside mask's own rule
    (:func:`~wavepaths.scene.solids.inside_solid_objects` with ``solids``, by default
    :func:`~wavepaths.scene.solids.solid_objects`, which spans objects): the points a few
    plane tolerances off the face on one side, tilted four ways along it (so that a cell on a
    building's corner reaches into it), meet a solid, and those on the other side do not. The
    second rule does not depend on how a file groups faces into objects or orients them (a
    review: cells on walls were masked when each building was its own object and traced when
    the same walls came in one object).
    """
    from ..scene.closed import solid_objects_mask
    from ..search.on_faces import points_on_surfaces
    from ..scene.solids import inside_solid_objects, solid_objects

    faces = points_on_faces(scene, flat)
    on_solid = np.zeros(len(flat), bool)
    if not (faces >= 0).any():
        return faces, on_solid
    rows = np.nonzero(faces >= 0)[0]
    on_solid[rows] = points_on_surfaces(scene, flat[rows])[:, solid_objects_mask(scene)].any(axis=1)
    n = scene.polygon_normal[faces[rows]]
    t1 = np.cross(n, np.where(np.abs(n[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]]))
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    h = 4 * scene.length_tolerance(scene.tolerances.plane_distance)
    tilts = [a * t1 + b * t2 for a, b in ((0.5, 0.5), (0.5, -0.5), (-0.5, 0.5), (-0.5, -0.5))]
    pts = np.concatenate([flat[rows] + h * (side * n + tilt) for side in (1.0, -1.0) for tilt in tilts])
    inside = inside_solid_objects(scene, pts, solid_objects(scene) if solids is None else solids)
    inside = inside.reshape(2, len(tilts), len(rows)).any(axis=1)
    on_solid[rows] |= inside[0] != inside[1]
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


def warn_cells_near_edges(scene: Scene, flat: np.ndarray, near: np.ndarray) -> None:
    """Warn when traced cell centres ``flat[near]`` lie off the faces but within the search's
    point-in-polygon margin of an edge (:func:`wavepaths.search.on_faces.points_near_edges`),
    as :func:`wavepaths.search.trace.trace` warns of such end points."""
    if len(near):
        from ..scene.polygon_query import polygon_margin_length

        m = polygon_margin_length(scene)
        warnings.warn(
            f"{len(near)} traced cell centres lie within {m:.2g} m of an edge, off its faces (first: cell "
            f"{int(near[0])} at {flat[near[0]].tolist()}): there the search's point-in-polygon margin may accept a "
            "reflection on the edge's faces just beyond the edge, and the fields may be off by several dB; offset "
            "the grid by a fraction of a cell or change its height (PlanarGrid's `center` and `height`, --center "
            "and --height)",
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
