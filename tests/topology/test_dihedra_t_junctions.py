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


@pytest.mark.parametrize("h", [1e-8, 1e-6])
@pytest.mark.parametrize("side", [(-1.0, 1.0), (1.0, 1.0)])
def test_a_sliver_along_an_edge_adds_no_face_to_it(h, side):
    """A 10 m cube whose top front edge carries a sliver triangle 4-C-5, its tip C within the
    weld tolerance of the edge (a T-junction patch of a CAD export) but its area above the
    degenerate-area threshold, so it is kept. The edge keeps its two faces and its 270/90
    degree sectors, every face direction a unit vector: the sliver's entries had a zero or
    rounding-noise direction (its tip is the split vertex), or came back as half-faces of
    the sliver 'polygon', and split the air sector (a transmitter there lost the diffraction)."""
    from wavepaths.em.materials import PEC
    from wavepaths.scene.model import build_scene
    from wavepaths.topology.sectors import sector_table

    L = 10.0
    v = np.array([[0, 0, 0], [L, 0, 0], [L, L, 0], [0, L, 0], [0, 0, L], [L, 0, L], [L, L, L], [0, L, L]], float)
    tris = []
    for a, b, c, d in ((0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)):
        tris += [[a, b, c], [a, c, d]]
    v = np.vstack([v, [[L / 2, side[0] * h, L + side[1] * h]]])
    tris = np.array(tris + [[4, 8, 5]])
    scene = build_scene(v, tris, np.zeros(len(tris), int), np.zeros(len(tris), int), ["o"], [PEC])
    assert scene.dropped_degenerate == 0  # the sliver is kept as a triangle
    d = scene.dihedra
    table = sector_table(d)
    top_front = [i for i in range(len(d.length)) if np.allclose(d.origin[i], [0, 0, L], atol=1e-6)
                 and abs(d.direction[i][0]) > 0.9]
    assert len(top_front) == 1
    i = top_front[0]
    faces = d.face_direction[d.faces(i)]
    np.testing.assert_allclose(np.linalg.norm(faces, axis=1), 1.0, atol=1e-12)
    assert d.faces_per_dihedron[i] == 2 and d.diffracting[i]
    np.testing.assert_allclose(np.sort(np.rad2deg(table.width[i][: table.count[i]])), [90.0, 270.0], atol=1e-4)  # the tip bends the edge by h / 5 m
