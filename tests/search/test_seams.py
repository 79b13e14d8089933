"""A path whose interaction point lies on a seam is one path.

A reflection point on the common border of two coplanar polygons lies in both, and a
diffraction point where two collinear dihedra meet lies on both: the search finds the one
geometrical path once per primitive, and the field counted it twice (found by a review on
walls of two materials, touching and stacked boxes, and T-junctions of walls). The
duplicates are dropped (``search.paths.coincident_paths``), in path queries and in
coverage maps alike.
"""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths import InteractionType, TraceOptions, trace
from wavepaths.coverage import CoverageOptions, PlanarGrid, coverage
from wavepaths.em.materials import PEC, itu_material
from wavepaths.scene.builtin import SceneBuilder
from wavepaths.scene.model import build_scene


def _two_material_wall():
    """A 10 m x 3 m wall in the plane y = 0: PEC for x < 0, concrete for x > 0; the seam at
    x = 0 is flat (no dihedron), its top edge two collinear dihedra meeting at (0, 0, 3)."""
    b = SceneBuilder()
    b.add_quad("metal", PEC, [(-5, 0, 0), (0, 0, 0), (0, 0, 3), (-5, 0, 3)])
    b.add_quad("concrete", itu_material("concrete"), [(0, 0, 0), (5, 0, 0), (5, 0, 3), (0, 0, 3)])
    return build_scene(*b.arrays())


def test_a_reflection_on_the_seam_of_two_polygons_is_one_path():
    scene = _two_material_wall()
    # symmetric about x = 0: the reflection point is (0, 0, 1.5), on the seam
    p = trace(scene, [[-1.0, -3.0, 1.0]], [[1.0, -3.0, 2.0]], TraceOptions(max_reflections=1, diffraction=False))
    refl = np.nonzero(p.depth == 1)[0]
    assert len(refl) == 1
    assert p.vertices[refl[0], 1] == pytest.approx([0.0, 0.0, 1.5], abs=1e-9)
    assert p.stats["paths_dropped_coincident"] == 1
    # 1e-3 m off the seam each polygon has its own, distinct path
    p = trace(scene, [[-1.0, -3.0, 1.0]], [[1.002, -3.0, 2.0]], TraceOptions(max_reflections=1, diffraction=False))
    assert (p.depth == 1).sum() == 1 and "paths_dropped_coincident" not in p.stats


def test_a_diffraction_where_two_collinear_dihedra_meet_is_one_path():
    scene = _two_material_wall()
    dh = scene.dihedra
    top = np.nonzero((np.abs(dh.direction[:, 0]) > 0.999) & (np.abs(dh.origin[:, 2] - 3.0) < 1e-9))[0]
    assert len(top) == 2  # the top edge's two pieces (their faces differ)
    p = trace(scene, [[-1.0, -2.0, 1.0]], [[1.0, 2.0, 1.0]],
              TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=0))
    on_top = [i for i in range(len(p)) if p.depth[i] == 1 and p.primitive[i, 0] in top]
    assert len(on_top) == 1
    assert p.vertices[on_top[0], 1] == pytest.approx([0.0, 0.0, 3.0], abs=1e-9)


def test_a_coverage_cell_on_the_seam_counts_the_path_once():
    scene = _two_material_wall()
    grid = PlanarGrid(center=[1.0, -3.0], height=2.0, size=[1.0, 1.0], cell_size=1.0)
    opts = TraceOptions(max_reflections=1, diffraction=False)
    m = coverage(scene, [[-1.0, -3.0, 1.0]], grid, opts, settings=CoverageOptions(workers=1))
    p = trace(scene, [[-1.0, -3.0, 1.0]], grid.cell_centers().reshape(-1, 3), opts)
    assert int(m.num_paths[int(InteractionType.REFLECTION)].sum()) == 1 == int((p.depth == 1).sum())
