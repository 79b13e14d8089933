"""End points on a solid's edges and corners (S19): legs that enter the solid, and only those, are dropped.

A transmitter on a roof's edge or corner (a parapet antenna) lies on two or three faces of
its building. A leg from it enters the building only when it points into the solid's
tangent cone there: against every face for a convex edge or corner, against either face
for a reflex one. The reference here is independent of the engine: the solids are boxes
and an L-shaped prism whose interiors are tested directly, and a leg enters a solid when
points just beyond its start lie inside it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import wavepaths as wp
from wavepaths.scene import WavepathsWarning
from wavepaths.search.on_faces import _on_face_pairs, solid_surface_cones

from ..scene.test_mesh_files import inside as inside_polygon

# the street canyon's building_north_0 (x -90..-50, y 10..25, z 0..15) and a street line
BUILDING = (np.array([-90.0, 10.0, 0.0]), np.array([-50.0, 25.0, 15.0]))
SURFACE_POINTS = {
    "roof corner": [-50.0, 10.0, 15.0],
    "roof edge": [-70.0, 10.0, 15.0],
    "east roof edge": [-50.0, 17.0, 15.0],
    "vertical edge": [-50.0, 10.0, 7.0],
    "foot corner": [-50.0, 10.0, 0.0],
    "wall": [-70.0, 10.0, 7.0],
    "roof": [-70.0, 17.0, 15.0],
}
L_XY = np.array([[0, 0], [6, 0], [6, 2], [2, 2], [2, 6], [0, 6]], float)  # reflex corner at (2, 2)
L_HEIGHT = 3.0


def boxes_of(scene) -> list[tuple[np.ndarray, np.ndarray]]:
    """Axis-aligned bounds of each building of a built-in scene (its boxes)."""
    out = []
    for k, name in enumerate(scene.object_names):
        if name.startswith("building"):
            v = scene.vertices[np.unique(scene.triangles[scene.triangle_object == k])]
            out.append((v.min(axis=0), v.max(axis=0)))
    return out


def segment_enters_a_box(a, b, boxes, samples: int = 20001) -> bool:
    t = np.linspace(0.0, 1.0, samples)[1:-1, None]
    pts = np.asarray(a)[None] + t * (np.asarray(b) - np.asarray(a))[None]
    return any(np.all((pts > lo + 1e-9) & (pts < hi - 1e-9), axis=1).any() for lo, hi in boxes)


@pytest.mark.parametrize("where", list(SURFACE_POINTS))
def test_line_of_sight_from_a_building_surface_point_is_kept_exactly_when_clear(where):
    # before S19 a leg from a roof edge counted as entering the building when it pointed
    # below the roof, whatever the wall: a parapet antenna saw no street receiver
    scene = wp.load_scene("street_canyon")
    boxes = boxes_of(scene)
    rng = np.random.default_rng(5)
    street = np.column_stack([rng.uniform(-100, 100, 20), rng.uniform(-8, 8, 20), rng.uniform(1, 12, 20)])
    behind = np.column_stack([rng.uniform(-100, -40, 20), rng.uniform(26, 40, 20), rng.uniform(1, 12, 20)])
    rx = np.vstack([street, behind])
    src = np.array(SURFACE_POINTS[where])
    truth = np.array([not segment_enters_a_box(src, r, boxes) for r in rx])
    assert (~truth).any() and (truth.any() or where == "roof")  # both kinds (a roof's middle sees no street)
    los = wp.TraceOptions(max_reflections=0, diffraction=False)
    with pytest.warns(WavepathsWarning, match="on a face"):
        forward = wp.trace(scene, src[None], rx, los)
    got = np.bincount(forward.rx_index, minlength=len(rx)) > 0
    np.testing.assert_array_equal(got, truth)
    with pytest.warns(WavepathsWarning, match="on a face"):
        backward = wp.trace(scene, rx, src[None], los)  # the surface point as the receiver
    np.testing.assert_array_equal(np.bincount(backward.tx_index, minlength=len(rx)) > 0, truth)


def test_a_parapet_transmitter_lights_the_street_as_one_a_micrometre_off_it():
    scene = wp.load_scene("street_canyon")
    grid = wp.PlanarGrid(center=[-40.0, 0.0], size=[80.0, 16.0], cell_size=2.0, height=1.5)
    opts = wp.TraceOptions(max_reflections=0, diffraction=False)
    with pytest.warns(WavepathsWarning, match="on a face"):
        on = wp.coverage(scene, [-70.0, 10.0, 15.0], grid, opts, settings=wp.CoverageOptions(workers=1))
    off = wp.coverage(scene, [-70.0, 10.0 - 1e-6, 15.0 + 1e-6], grid, opts, settings=wp.CoverageOptions(workers=1))
    lit_on, lit_off = on.num_paths[0, 0] > 0, off.num_paths[0, 0] > 0
    assert lit_off.sum() > 100
    np.testing.assert_array_equal(lit_on, lit_off)


def write_l_prism(path: Path) -> Path:
    """A closed L-shaped prism (its top and bottom hexagons ear-clipped on load)."""
    k = len(L_XY)
    lines = [f"v {x} {y} 0" for x, y in L_XY] + [f"v {x} {y} {L_HEIGHT}" for x, y in L_XY]
    lines.append("f " + " ".join(str(i + 1) for i in reversed(range(k))))  # bottom, facing -z
    lines.append("f " + " ".join(str(k + i + 1) for i in range(k)))  # top, facing +z
    for i in range(k):
        j = (i + 1) % k
        lines.append(f"f {i + 1} {j + 1} {k + j + 1} {k + i + 1}")  # sides, facing out (counter-clockwise L)
    path.write_text("o l_prism\n" + "\n".join(lines) + "\n")
    return path


def inside_l_prism(p: np.ndarray) -> np.ndarray:
    return (p[:, 2] > 0) & (p[:, 2] < L_HEIGHT) & inside_polygon(p[:, :2], L_XY)


def inside_unit_box(p: np.ndarray) -> np.ndarray:
    return np.all((p > 0) & (p < 1), axis=1)


@pytest.mark.parametrize("solid, point", [
    ("box", [1.0, 1.0, 1.0]),  # a convex corner
    ("box", [1.0, 0.5, 1.0]),  # a convex edge
    ("box", [0.5, 0.5, 1.0]),  # a face
    ("box", [0.0, 1.0, 0.3]),  # another convex edge
    ("l", [2.0, 2.0, 1.0]),  # the reflex edge
    ("l", [2.0, 2.0, 3.0]),  # the reflex edge's top end: a corner with a reflex edge
    ("l", [6.0, 2.0, 3.0]),  # a convex corner
    ("l", [4.0, 2.0, 1.5]),  # the inner face
])
def test_into_is_the_solids_interior_beyond_the_point(tmp_path, solid, point):
    if solid == "box":
        import trimesh

        trimesh.creation.box(extents=(1, 1, 1)).apply_translation((0.5, 0.5, 0.5)).export(tmp_path / "box.obj")
        scene = wp.load_scene(str(tmp_path / "box.obj"))
        inside = inside_unit_box
    else:
        scene = wp.load_scene(str(write_l_prism(tmp_path / "l.obj")))
        inside = inside_l_prism
    p = np.array([point], float)
    (cones,) = solid_surface_cones(scene, p).values()
    assert len(cones) == 1
    d = np.random.default_rng(2).normal(size=(4000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    truth = inside(p + 1e-7 * d)
    assert 0 < truth.sum() < len(d)
    np.testing.assert_array_equal(cones[0].into(d), truth)
    # legs along the surface (toward points of the faces the point lies on) are the limit
    # from outside: not into
    rng = np.random.default_rng(3)
    _, polygons = _on_face_pairs(scene, p, 10**9)
    assert len(polygons) == len(cones[0].normals)
    for q in polygons:
        for t in scene.polygon_triangles(int(q)):
            w = rng.dirichlet(np.ones(3), 20) @ scene.vertices[scene.triangles[t]]
            along = w - p
            along = along[np.linalg.norm(along, axis=1) > 1e-6]
            assert not cones[0].into(along).any()


def write_obj_solids(path: Path, solids: list[list[tuple]], objects: list[str]) -> Path:
    """Closed prisms (2-D polygons counter-clockwise, z0, z1) as OBJ objects: ``solids[k]`` the
    prisms of ``objects[k]`` (several closed parts in one object when it lists more)."""
    lines, base = [], 0
    for name, parts in zip(objects, solids):
        lines.append(f"o {name}")
        for xy, z0, z1 in parts:
            k = len(xy)
            lines += [f"v {float(x)!r} {float(y)!r} {float(z0)!r}" for x, y in xy]
            lines += [f"v {float(x)!r} {float(y)!r} {float(z1)!r}" for x, y in xy]
            lines.append("f " + " ".join(str(base + i + 1) for i in reversed(range(k))))
            lines.append("f " + " ".join(str(base + k + i + 1) for i in range(k)))
            for i in range(k):
                j = (i + 1) % k
                lines.append(f"f {base + i + 1} {base + j + 1} {base + k + j + 1} {base + k + i + 1}")
            base += 2 * k
    path.write_text("\n".join(lines) + "\n")
    return path


def inside_prisms(p: np.ndarray, parts: list[tuple]) -> np.ndarray:
    out = np.zeros(len(p), dtype=bool)
    for xy, z0, z1 in parts:
        out |= (p[:, 2] > z0) & (p[:, 2] < z1) & inside_polygon(p[:, :2], np.asarray(xy, float))
    return out


def square(x0, y0, x1, y1):
    return [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]


HALF_SLOT = 0.5 * np.tan(0.5e-4)  # a V-slot 0.5 m deep whose walls meet at 1e-4 rad
CASES = {
    # one object of two closed parts: a penthouse on a roof (found by a review: every answer flipped)
    "penthouse": ([[(square(0, 0, 20, 20), 0.0, 10.0), (square(5, 5, 10, 10), 10.0, 13.0)]], ["building"],
                  [(10.0, 7.0, 10.0), (5.0, 5.0, 10.0), (10.0, 10.0, 10.0), (7.0, 7.0, 13.0), (12.0, 12.0, 10.0)]),
    # two objects touching along a face: their contact faces bound each block
    "terrace": ([[(square(0, 0, 10, 10), 0.0, 10.0)], [(square(10, 0, 20, 10), 0.0, 10.0)]], ["a", "b"],
                [(10.0, 0.0, 10.0), (10.0, 5.0, 10.0), (10.0, 0.0, 5.0)]),
    # a slot whose walls meet at 1e-4 rad (the reference's tilt must stay between them)
    "slot": ([[([(0, 0), (10, 0), (10, 1), (5 + HALF_SLOT, 1), (5, 0.5), (5 - HALF_SLOT, 1), (0, 1)], 0.0, 1.0)]],
             ["slotted"], [(5.0, 0.5, 0.5)]),
}


@pytest.mark.parametrize("case", list(CASES))
def test_into_on_several_shells_touching_objects_and_a_thin_slot(tmp_path, case):
    solids, names, points = CASES[case]
    scene = wp.load_scene(str(write_obj_solids(tmp_path / f"{case}.obj", solids, names)))
    parts = [part for obj in solids for part in obj]
    d = np.random.default_rng(6).normal(size=(4000, 3))
    if case == "slot":
        d = np.vstack([d, [[0, 1, 0.3], [0, 1, -0.3], [0, 1, 0]]])  # up the slot: its air
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    found = solid_surface_cones(scene, np.asarray(points, float))
    assert sorted(found) == list(range(len(points)))
    for k, p in enumerate(points):
        got = np.zeros(len(d), dtype=bool)
        for cone in found[k]:
            got |= cone.into(d)
        truth = inside_prisms(np.asarray(p) + 1e-7 * d, parts)
        assert 0 < truth.sum() < len(d)
        np.testing.assert_array_equal(got, truth, err_msg=f"{case} {p}")


def test_into_at_a_triangles_centroid(tmp_path):
    # the reference direction pointed from the point to its triangle's centroid: NaN there
    import trimesh

    trimesh.creation.box(extents=(1, 1, 1)).apply_translation((0.5, 0.5, 0.5)).export(tmp_path / "box.obj")
    scene = wp.load_scene(str(tmp_path / "box.obj"))
    top = np.flatnonzero(scene.vertices[scene.triangles][:, :, 2].min(axis=1) > 0.999)[0]
    p = scene.vertices[scene.triangles[top]].mean(axis=0)
    (cone,) = solid_surface_cones(scene, p[None])[0]
    assert np.isfinite(cone.reference).all()
    np.testing.assert_array_equal(cone.into(np.array([[0, 0, -1.0], [0.3, 0.1, -1], [0, 0, 1.0], [1, 0, 0.0]])),
                                  [True, True, False, False])


def test_many_points_on_faces_edges_and_corners_at_once(tmp_path):
    """Receivers inside one face take the half-space shortcut (all at once, a review timed the
    general cone per receiver at 0.5 ms), the others the general cone; either way a leg from
    a transmitter counts as entering the solid exactly when points just short of the receiver
    along it lie inside. 600 points drawn on the L prism's faces (inside triangles, on their
    sides, on the prism's edges and corners), each reached from 8 random transmitters."""
    from wavepaths.search.on_faces import legs_into_solids
    from wavepaths.search.paths import Paths

    scene = wp.load_scene(str(write_l_prism(tmp_path / "l.obj")))
    rng = np.random.default_rng(11)
    tri = rng.integers(0, scene.num_triangles, 600)
    w = rng.dirichlet(np.ones(3), 600)
    w[:150, 0] = 0.0  # on a triangle's side: a face's diagonal or the prism's edge
    w[:150] /= w[:150].sum(axis=1, keepdims=True)
    w[150:200] = np.eye(3)[rng.integers(0, 3, 50)]  # on a corner of the prism
    rx = np.einsum("ni,nij->nj", w, scene.vertices[scene.triangles[tri]])
    cones = solid_surface_cones(scene, rx)
    assert len(cones) == len(rx)
    simple = sum(c[0].is_face_interior for c in cones.values() if len(c) == 1)
    assert 300 < simple < 450  # both ways are taken
    tx = rng.uniform(-4, 10, (8, 3))
    ti, ri = np.repeat(np.arange(8), len(rx)), np.tile(np.arange(len(rx)), 8)
    v = np.stack([tx[ti], rx[ri]], axis=1)
    z = np.zeros((len(ti), 0), np.int64)
    paths = Paths(tx, rx, ti, ri, np.zeros(len(ti), np.int64), z.astype(np.int8), z, z,
                  np.full((len(ti), 2), -1), v)
    got = legs_into_solids(paths, {}, cones)
    d = tx[ti] - rx[ri]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    truth = inside_l_prism(rx[ri] + 1e-7 * d)
    assert 0.2 < truth.mean() < 0.8
    np.testing.assert_array_equal(got, truth)
