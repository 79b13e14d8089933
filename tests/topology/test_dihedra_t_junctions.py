"""Dihedra of edges that meet other edges at T-junctions (seed §3.2: one dihedron per edge
segment with every face on it)."""

from __future__ import annotations

import numpy as np
import pytest


def test_t_junction_splits_a_corner_into_the_shared_flat_stretch_and_the_free_corner():
    """A low block (10 m) against a tall one (20 m), facades continuing each other: the line
    x = y = 0 is a flat facade up to 10 m (four faces, no diffraction) and the tall block's
    right-angled corner above (two faces, n = 1.5). Without the split the corner was one
    20 m dihedron with the low block's faces too (180 degrees: never diffracting), so the
    D path over the upper corner was lost."""
    from wavepaths.em.materials import PEC
    from wavepaths.scene import build_scene
    from wavepaths.scene.builtin import SceneBuilder
    from wavepaths.search import TraceOptions, trace

    b = SceneBuilder()
    b.add_prism("tall", PEC, [(0, 0), (10, 0), (10, 10), (0, 10)], 20.0)
    b.add_prism("low", PEC, [(-10, 0), (0, 0), (0, 10), (-10, 10)], 10.0)
    scene = build_scene(*b.arrays())
    dh = scene.dihedra
    on = np.nonzero((np.linalg.norm(dh.origin[:, :2], axis=1) < 1e-9) & (np.abs(dh.direction[:, 2]) > 0.999))[0]
    spans = sorted((round(float(min(z0, z0 + dz)), 9), round(float(max(z0, z0 + dz)), 9), int(d))
                   for d, z0, dz in zip(on, dh.origin[on, 2], dh.length[on] * dh.direction[on, 2]))
    assert [(lo, hi) for lo, hi, _ in spans] == [(0.0, 10.0), (10.0, 20.0)]
    low_part, high_part = spans[0][2], spans[1][2]
    assert dh.faces_per_dihedron[low_part] == 4 and not dh.diffracting[low_part]
    assert dh.faces_per_dihedron[high_part] == 2 and dh.diffracting[high_part]
    assert np.degrees(dh.max_sector[high_part]) == pytest.approx(270.0, abs=1e-9)
    # tx and rx on either side of the corner, the Keller point at z = 15.65 on the free corner
    p = trace(scene, np.array([[20.0, -20.0, 19.0]]), np.array([[-20.0, -10.0, 13.0]]),
              TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=0))
    d_paths = [i for i in range(len(p)) if p.depth[i] == 1 and p.primitive[i, 0] == high_part]
    assert len(d_paths) == 1
    P = p.vertices[d_paths[0], 1]
    assert P[:2] == pytest.approx([0.0, 0.0], abs=1e-9) and 10.0 < P[2] < 20.0
    # and nothing diffracts on the flat stretch below the low roof
    assert not any(p.primitive[i, 0] == low_part for i in range(len(p)) if p.depth[i] == 1)
