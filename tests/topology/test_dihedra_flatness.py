"""Flat edges (seed §3.2, step 3 of :mod:`wavepaths.topology.dihedra`): an edge whose faces are
coplanar is never a dihedron, whether the mesh file rounded its vertices or not; a fold
the scene's tolerance can resolve stays one."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths.em.materials import PEC
from wavepaths.scene import build_scene

GROUND = 500.0  # half-size of the ground square [m]: a scene about 1.4 km across


def _strips_scene(corners: np.ndarray):
    """A ground square at z = 0 and free-standing quads ``corners`` (k, 4, 3), each split
    along its diagonal 0-2 into two triangles, one object per quad."""
    g = GROUND
    verts = [np.array([[-g, -g, 0.0], [g, -g, 0.0], [g, g, 0.0], [-g, g, 0.0]])]
    tris = [np.array([[0, 1, 2], [0, 2, 3]])]
    obj = [np.zeros(2, int)]
    for i, q in enumerate(corners):
        base = 4 * (i + 1)
        verts.append(q)
        tris.append(np.array([[0, 1, 2], [0, 2, 3]]) + base)
        obj.append(np.full(2, i + 1))
    names = [f"o{i}" for i in range(len(corners) + 1)]
    tri = np.concatenate(tris)
    return build_scene(np.concatenate(verts), tri, np.concatenate(obj), np.zeros(len(tri), int), names, [PEC])


def _strip(center, yaw: float, tilt: float, length: float, height: float) -> np.ndarray:
    """A rectangle ``length`` x ``height`` [m] centred on ``center``, its long side horizontal
    at azimuth ``yaw``, its short side ``tilt`` from the vertical (a roof's slope)."""
    u = np.array([np.cos(yaw), np.sin(yaw), 0.0]) * length / 2
    side = np.array([-np.sin(yaw), np.cos(yaw), 0.0])
    z = (np.cos(tilt) * np.array([0.0, 0.0, 1.0]) + np.sin(tilt) * side) * height / 2
    c = np.asarray(center, float)
    return np.array([c - u - z, c + u - z, c + u + z, c - u + z])


def _on_diagonal(scene, corners: np.ndarray) -> np.ndarray:
    """Per quad, whether some dihedron runs along its diagonal 0-2."""
    d = scene.dihedra
    mid = d.origin + 0.5 * d.length[:, None] * d.direction
    out = []
    for q in corners:
        axis = (q[2] - q[0]) / np.linalg.norm(q[2] - q[0])
        parallel = np.abs(d.direction @ axis) > 1 - 1e-6
        rel = mid - q[0]
        off = np.linalg.norm(rel - (rel @ axis)[:, None] * axis, axis=1)
        out.append(bool((parallel & (off < 1e-3)).any()))
    return np.array(out)


def _rounded_strips() -> np.ndarray:
    """Forty 40 m x 0.3 m sloping strips 300-450 m from the origin (random, seed 3), their
    vertices rounded to float32: (40, 4, 3)."""
    rng = np.random.default_rng(3)
    r = rng.uniform(300.0, 450.0, 40)
    t = rng.uniform(0.0, 2 * np.pi, 40)
    corners = np.array([_strip([ri * np.cos(ti), ri * np.sin(ti), 7.0], yaw, tilt, 40.0, 0.3)
                        for ri, ti, yaw, tilt in zip(r, t, rng.uniform(0.0, np.pi, 40), rng.uniform(0.2, 1.3, 40))])
    return corners.astype(np.float32).astype(np.float64)


def _lifted_strip(tolerance: str, factor: float):
    """One float64 strip with its corner 3 lifted off the plane of triangle 0-1-2 by ``factor``
    times the scene's tolerance named ``tolerance`` [m]: (corners (4, 3), scene, that tolerance)."""
    q = _strip([350.0, 120.0, 7.0], 0.7, 0.5, 40.0, 0.3)
    scene0 = _strips_scene(q[None])
    tol = scene0.length_tolerance(getattr(scene0.tolerances, tolerance))
    normal = np.cross(q[1] - q[0], q[2] - q[0])
    q = q.copy()
    q[3] += factor * tol * normal / np.linalg.norm(normal)
    scene = _strips_scene(q[None])
    assert scene.length_tolerance(getattr(scene.tolerances, tolerance)) == pytest.approx(tol, rel=1e-6)
    return q, scene, tol


def test_thin_wall_strips_rounded_to_float32_have_no_dihedron_on_their_diagonal():
    """Forty 40 m x 0.3 m sloping strips 300-450 m from the origin, their vertices rounded to
    float32 as a PLY or Mitsuba file stores them (up to 3e-5 m of rounding at 450 m). Each
    triangle's corner lies 0.3 m from the diagonal, so the rounding turns its face direction
    by up to ~1e-4 rad, beyond ``coplanar_angle`` (1e-5 rad): the diagonals became dihedra
    with n - 1 ~ 1e-5 (spurious diffracting edges, 4,769 of munich's 36,565). Measured as a
    distance, every corner lies within 1e-4 m of the other triangle's plane, far inside the
    plane tolerance (1e-6 of the scene's size, 1.4 mm): every diagonal is flat, and the
    dihedra are exactly the strips' 160 free borders and the ground's 4."""
    rounded = _rounded_strips()
    scene = _strips_scene(rounded)
    # the rounding is there: the strips' two triangles disagree by more than the angle tolerance
    # (so the polygons stay apart and the angle test alone calls most diagonals folds)
    a, b = rounded[:, 1] - rounded[:, 0], rounded[:, 2] - rounded[:, 0]
    c = rounded[:, 3] - rounded[:, 0]
    n1, n2 = np.cross(a, b), np.cross(b, c)
    cosang = np.einsum("ij,ij->i", n1, n2) / np.linalg.norm(n1, axis=1) / np.linalg.norm(n2, axis=1)
    angle = np.arccos(np.clip(cosang, -1, 1))
    assert (angle > scene.tolerances.coplanar_angle).sum() >= 10, angle
    assert not _on_diagonal(scene, rounded).any()
    d = scene.dihedra
    assert len(d.length) == 4 * 40 + 4
    assert d.diffracting.all()
    np.testing.assert_allclose(d.max_sector / np.pi, 2.0, atol=1e-9)  # the free borders: n = 2


@pytest.mark.parametrize("factor, folded", [(3.0, True), (0.3, False)])
def test_a_fold_is_a_dihedron_exactly_when_the_plane_tolerance_resolves_it(factor, folded):
    """The same strip in float64, its corner 3 lifted off the plane of triangle 0-1-2 by
    ``factor`` times the plane tolerance (1.4 mm here): at 3x the fold (4e-3 m over the
    corner's 0.3 m from the diagonal, 0.8 deg) is a diffracting dihedron with n - 1 = fold / pi
    to 1e-9; at 0.3x the corner could be moved into the plane within the tolerance, and the
    diagonal is flat."""
    q, scene, tol = _lifted_strip("plane_distance", factor)
    on = _on_diagonal(scene, q[None])[0]
    assert on == folded
    if folded:
        d = scene.dihedra
        axis = (q[2] - q[0]) / np.linalg.norm(q[2] - q[0])
        i = int(np.argmax(np.abs(d.direction @ axis)))
        rel = q[3] - q[0]
        h = np.linalg.norm(rel - (rel @ axis) * axis)  # the lifted corner's distance from the diagonal
        fold = np.arcsin(factor * tol / h)
        assert d.diffracting[i]
        assert d.max_sector[i] / np.pi - 1 == pytest.approx(fold / np.pi, rel=1e-6)


def test_thin_strips_rounded_to_float32_are_one_polygon_each():
    """The forty float32-rounded strips of the test above: the angle between a strip's two
    triangles exceeds ``coplanar_angle`` in most of them, so by angle alone each was two
    polygons (two reflection candidates and a seam per strip). By distance (every corner
    within ``coplanar_distance``, 1e-7 of the scene's size, of the other triangle's plane)
    each strip is one polygon, all its vertices within that distance of the polygon's plane."""
    scene = _strips_scene(_rounded_strips())
    assert scene.num_polygons == 1 + 40
    tol = scene.length_tolerance(scene.tolerances.coplanar_distance)
    for q in range(scene.num_polygons):
        v = scene.vertices[np.unique(scene.triangles[scene.polygon_triangles(q)])]
        assert np.abs(v @ scene.polygon_normal[q] - scene.polygon_offset[q]).max() <= tol


@pytest.mark.parametrize("factor, polygons", [(3.0, 2), (0.3, 1)])
def test_a_fold_splits_the_polygon_exactly_when_the_coplanar_distance_resolves_it(factor, polygons):
    """One float64 strip, its corner 3 lifted off the plane of triangle 0-1-2 by ``factor``
    times ``coplanar_distance`` (0.18 mm here; the fold is 6e-4 or 6e-5 rad, both beyond
    ``coplanar_angle``): two polygons at 3x, one at 0.3x. Either way the diagonal is flat
    (below the plane tolerance, ten times larger)."""
    q, scene, _ = _lifted_strip("coplanar_distance", factor)
    assert scene.num_polygons == 1 + polygons
    assert not _on_diagonal(scene, q[None])[0]


@pytest.mark.parametrize("factor, diffracts", [(3.0, True), (0.5, False)])
def test_a_facade_continued_by_a_narrow_block_diffracts_only_past_the_plane_tolerance(factor, diffracts):
    """A 10 m cube and a 0.5 m wide block against it, whose facade continues the cube's
    (y = 0) but ends ``factor`` plane tolerances behind it: the vertical edge between them
    carries four faces (two facades, two party walls), and its widest sector, on the street
    side, is pi plus the facades' angle (``factor`` * 2e-5 m over 0.5 m, 2e-5 or 1.2e-4 rad,
    both beyond ``coplanar_angle``). At 0.5 tolerances the facades are coplanar by distance
    and the edge does not diffract (it had n - 1 = 6e-6: float32 rounding left 226 such edges
    in munich); at 3 tolerances it diffracts, with n - 1 = angle / pi. No D path then uses it."""
    from wavepaths.scene.builtin import SceneBuilder
    from wavepaths.search import TraceOptions, trace

    def blocks(dy):
        b = SceneBuilder()
        b.add_prism("cube", PEC, [(0, 0), (10, 0), (10, 10), (0, 10)], 10.0)
        b.add_prism("block", PEC, [(10, 0), (10.5, dy), (10.5, 10), (10, 10)], 10.0)
        return build_scene(*b.arrays())

    scene0 = blocks(0.0)
    tol = scene0.length_tolerance(scene0.tolerances.plane_distance)
    dy = factor * tol
    scene = blocks(dy)
    assert scene.length_tolerance(scene.tolerances.plane_distance) == pytest.approx(tol, rel=1e-6)
    d = scene.dihedra
    on = np.flatnonzero((np.linalg.norm(d.origin[:, :2] - [10.0, 0.0], axis=1) < 1e-9)
                        & (np.abs(d.direction[:, 2]) > 0.999))
    assert len(on) == 1
    i = int(on[0])
    assert d.faces_per_dihedron[i] == 4
    angle = np.arctan2(dy, 0.5)
    assert d.max_sector[i] - np.pi == pytest.approx(angle, rel=1e-6)
    assert bool(d.diffracting[i]) == diffracts
    p = trace(scene, np.array([[5.0, -20.0, 5.0]]), np.array([[30.0, -2.0, 5.0]]),
              TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=0))
    uses = [k for k in range(len(p)) if p.depth[k] == 1 and p.primitive[k, 0] == i]
    assert (len(uses) > 0) == diffracts


@pytest.mark.parametrize("radius, sides, half_size", [(0.3, 96, 700.0), (1.0, 48, 7000.0)])
def test_the_creases_of_a_narrowly_faceted_cylinder_still_diffract(radius, sides, half_size):
    """A faceted pillar (facets 2 r sin(pi / N) = 2 cm or 13 cm wide, creased by 3.75 or 7.5
    degrees) in a scene 2 km or 20 km across (plane tolerance 2 mm or 2 cm): each facet's
    corner lies within the tolerance of its neighbour's plane only because the facet is
    narrow. Flat by distance alone, every crease stopped diffracting (a review: munich's church
    lost 226 such edges), and with them the field that fills the gap between two facets'
    reflection boundaries (0.4-0.8 of the incident field for a 7 degree crease, against the
    exact wedge series). Folds beyond ``flat_angle`` are never flat by distance: all N
    vertical creases diffract, with n - 1 = 2 / N."""
    ang = 2 * np.pi * np.arange(sides) / sides
    bottom = np.stack([radius * np.cos(ang), radius * np.sin(ang), np.zeros(sides)], 1)
    verts = list(bottom) + list(bottom + [0.0, 0.0, 3.0])
    tris = [t for i in range(sides) for t in ([i, (i + 1) % sides, sides + (i + 1) % sides],
                                               [i, sides + (i + 1) % sides, sides + i])]
    obj = [0] * len(tris)
    for k, (cx, cy) in enumerate([(-half_size, -half_size), (half_size, half_size)]):  # the scene's size
        b = len(verts)
        verts += [[cx, cy, 0], [cx + 1, cy, 0], [cx + 1, cy + 1, 0], [cx, cy + 1, 0]]
        tris += [[b, b + 1, b + 2], [b, b + 2, b + 3]]
        obj += [k + 1, k + 1]
    s = build_scene(np.array(verts, float), np.array(tris), np.array(obj), np.zeros(len(tris), int),
                    ["pillar", "p1", "p2"], [PEC])
    facet, fold = 2 * radius * np.sin(np.pi / sides), 2 * np.pi / sides
    assert facet * np.sin(fold) < s.length_tolerance(s.tolerances.plane_distance)  # within it by distance
    d = s.dihedra
    vertical = np.abs(d.direction[:, 2]) > 0.99
    assert vertical.sum() == sides and d.diffracting[vertical].all()
    np.testing.assert_allclose(d.max_sector[vertical] / np.pi - 1, 2.0 / sides, rtol=1e-9)
