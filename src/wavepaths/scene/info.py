"""The numbers that describe a scene (``wavepaths info``)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from .model import Scene


def scene_info(scene: "Scene") -> dict:
    """Counts and bounds of a scene, as plain JSON-ready Python values.

    Keys: ``triangles``, ``objects``, ``materials`` (counts), ``object_names``,
    ``material_names``, ``polygons``, ``dihedra`` (non-flat edge segments),
    ``diffracting_dihedra`` (those with a sector wider than pi),
    ``dihedra_by_face_count`` (``"1"``, ``"2"``, ``"3+"``: distinct polygons on the edge),
    ``skipped_flat_edges``, ``dropped_degenerate_triangles``, ``bounds``
    (``[[xmin, ymin, zmin], [xmax, ymax, zmax]]`` in metres), ``source``.
    """
    d = scene.dihedra
    fc = d.face_count
    return {
        "source": scene.source,
        "triangles": int(scene.num_triangles),
        "objects": len(scene.object_names),
        "materials": len(scene.materials),
        "object_names": list(scene.object_names),
        "material_names": [m.name for m in scene.materials],
        "polygons": int(scene.num_polygons),
        "dihedra": int(len(d)),
        "diffracting_dihedra": int(np.count_nonzero(d.diffracting)),
        "dihedra_by_face_count": {
            "1": int(np.count_nonzero(fc == 1)),
            "2": int(np.count_nonzero(fc == 2)),
            "3+": int(np.count_nonzero(fc >= 3)),
        },
        "skipped_flat_edges": int(d.skipped_flat_edges),
        "dropped_degenerate_triangles": int(scene.dropped_degenerate),
        "bounds": scene.bounds.tolist(),
    }
