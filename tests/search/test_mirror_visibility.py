"""Mirrors proven hidden from sources, and from each other (search/mirror_visibility.py).

Every pair the module calls hidden is checked against the occlusion rule itself (the
float64 caster) on sampled points of both ends; the tests also require that something is
culled, so that they could fail.
"""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths.em.materials import PEC
from wavepaths.raycast.numpy_caster import NumpyRayCaster
from wavepaths.scene import load_scene
from wavepaths.scene.builtin import SceneBuilder
from wavepaths.scene.model import build_scene
from wavepaths.search import TraceOptions, trace
from wavepaths.search.images import build_image_levels, reflecting_polygons
from wavepaths.search.mirror_visibility import hidden_after_mirror, hidden_mirrors

from ..conftest import boxes_scene
from .helpers import path_keys


def _monotone_chain(pts: np.ndarray) -> list[int]:
    """Reference hull (Andrew's monotone chain, counter-clockwise, collinear points left out)."""
    order = sorted(range(len(pts)), key=lambda i: (pts[i][0], pts[i][1]))

    def half(seq):
        out: list[int] = []
        for i in seq:
            while len(out) >= 2:
                a, b, c = pts[out[-2]], pts[out[-1]], pts[i]
                if (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]) <= 0:
                    out.pop()
                else:
                    break
            out.append(i)
        return out

    return half(order)[:-1] + half(order[::-1])[:-1]


def _city(rng, n: int = 14):
    """Random boxes (buildings) on a ground square: walls that hide each other."""
    boxes = []
    while len(boxes) < n:
        c = rng.uniform(-60, 60, 2)
        h = rng.uniform(4, 10, 2)
        lo, hi = c - h, c + h
        if any((lo < b[1][:2] + 3).all() and (hi > b[0][:2] - 3).all() for b in boxes):
            continue
        boxes.append((np.array([lo[0], lo[1], 0.0]), np.array([hi[0], hi[1], rng.uniform(6, 25)])))
    return boxes_scene([(tuple(a), tuple(b)) for a, b in boxes], ground=80.0)


def _outdoor(rng, scene, n: int, z: float = 1.5) -> np.ndarray:
    from wavepaths.coverage import inside_solid_objects, solid_objects

    pts = np.column_stack([rng.uniform(-75, 75, 8 * n), rng.uniform(-75, 75, 8 * n), np.full(8 * n, z)])
    return pts[~inside_solid_objects(scene, pts, solid_objects(scene))][:n]


def _points_on(scene, polygon: int, rng, k: int) -> np.ndarray:
    """(k, 3) random points of ``polygon`` (its triangles, by area), its corners first."""
    tris = scene.polygon_triangles(polygon)
    c = scene.vertices[scene.triangles[tris]]
    corners = np.unique(c.reshape(-1, 3), axis=0)
    area = 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
    t = rng.choice(len(tris), size=k, p=area / area.sum())
    u, v = rng.uniform(size=(2, k))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    pts = c[t, 0] + u[:, None] * (c[t, 1] - c[t, 0]) + v[:, None] * (c[t, 2] - c[t, 0])
    return np.concatenate([corners, pts])


def test_hulls_match_the_monotone_chain_and_turn_about_the_normal():
    b = SceneBuilder()
    b.add_box("box", PEC, (0, 0, 0), (4, 3, 2))
    scene = build_scene(*b.arrays())
    for s in (scene, load_scene("street_canyon")):
        hulls = s.polygon_hulls
        for p in range(s.num_polygons):
            vid = np.unique(s.triangles[s.polygon_triangles(p)])
            pts = s.vertices[vid]
            n = s.polygon_normal[p]
            u = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
            u /= np.linalg.norm(u)
            w = np.cross(n, u)
            xy = np.stack([(pts - pts.mean(0)) @ u, (pts - pts.mean(0)) @ w], 1)
            ref = _monotone_chain(xy)
            c = int(hulls.count[p])
            assert c == len(ref)
            got = hulls.corners[p, :c]
            # the same corners, in the same cyclic order
            start = int(np.argmin(np.linalg.norm(pts[ref] - got[0], axis=1)))
            np.testing.assert_allclose(got, np.roll(pts[ref], -start, axis=0), atol=1e-12)
            # counter-clockwise about the normal: inward side normals see every corner inside
            inside = np.einsum("kj,cj->kc", hulls.edge_normal[p, :c], got) - hulls.edge_offset[p, :c, None]
            assert (inside >= -1e-9).all()
            assert hulls.occluder[p]  # boxes and the canyon's walls are convex and planar


def test_a_non_convex_polygon_never_occludes():
    # an L of three coplanar quads, welded into one polygon
    quads = [[(0, 0, 0), (2, 0, 0), (2, 2, 0), (0, 2, 0)], [(2, 0, 0), (6, 0, 0), (6, 2, 0), (2, 2, 0)],
             [(0, 2, 0), (2, 2, 0), (2, 6, 0), (0, 6, 0)]]
    from ..conftest import quads_scene

    scene = quads_scene(quads, objects=[0, 0, 0])
    assert scene.num_polygons == 1
    hulls = scene.polygon_hulls
    assert hulls.count[0] == 5  # the hull of the L (its inner corner left out)
    assert not hulls.occluder[0]


def _groups_of_four(rng, scene, n: int, spread: float = 3.0) -> np.ndarray:
    """(4 n, 3): n groups of four outdoor points within ``spread`` m of an outdoor centre."""
    out = []
    while len(out) < n:
        c = _outdoor(rng, scene, 1)[0]
        g = c + np.column_stack([rng.uniform(-spread, spread, (4, 2)), np.zeros(4)])
        if len(_outdoor_points(scene, g)) == 4:
            out.append(g)
    return np.concatenate(out)


def _outdoor_points(scene, pts):
    from wavepaths.coverage import inside_solid_objects, solid_objects

    return pts[~inside_solid_objects(scene, pts, solid_objects(scene))]


@pytest.mark.parametrize("size", [1, 4])
def test_hidden_mirrors_are_hidden_by_the_occlusion_rule(size, rng):
    """Each (group, mirror) pair called hidden: every sampled point of the mirror (its corners
    and 40 random points) is blocked from every source of the group, by the float64 rule."""
    scene = _city(rng)
    exact = NumpyRayCaster(scene)
    mirrors = np.nonzero(reflecting_polygons(scene, True))[0]
    src = _outdoor(rng, scene, 6) if size == 1 else _groups_of_four(rng, scene, 6)
    group = np.arange(len(src)) // size  # consecutive points, as built
    hidden, rays = hidden_mirrors(scene, src, group, mirrors)
    every, rays_every = hidden_mirrors(scene, src, group, mirrors, pilot_stride=1)
    assert rays_every == hidden.size  # one hint ray per pair (every hull is small here)
    assert rays < rays_every and (hidden | ~every).all()  # shared hints: fewer rays, nothing lost
    assert hidden.sum() >= 10, "almost nothing hidden: the test would prove little"
    assert not hidden.all(axis=1).any()  # and every group still sees something
    for g, m in zip(*np.nonzero(hidden)):
        pts = _points_on(scene, int(mirrors[m]), rng, 40)
        members = src[group == g]
        a = np.repeat(members, len(pts), axis=0)
        b = np.tile(pts, (len(members), 1))
        assert exact.occluded(a, b).all(), (g, m)


def test_occluder_hints_shared_by_neighbouring_receivers(rng):
    """A row of receivers 0.5 m apart: with the occluders of every fourth receiver's rays as
    hints, most hidden pairs of the others need no ray, every pair proven with one ray per pair is
    still proven, and every pair proven only through a hint is hidden by the float64 rule."""
    scene = _city(rng)
    exact = NumpyRayCaster(scene)
    mirrors = np.nonzero(reflecting_polygons(scene, True))[0]
    start = _outdoor(rng, scene, 1)[0]
    src = _outdoor_points(scene, start + np.outer(np.arange(16) * 0.5, [1.0, 0.3, 0.0]))
    group = np.arange(len(src))  # one receiver per group, in the row's order
    every, rays_every = hidden_mirrors(scene, src, group, mirrors, pilot_stride=1)
    hinted, rays = hidden_mirrors(scene, src, group, mirrors, pilot_stride=4)
    assert every.sum() >= 10
    # a visible mirror always costs a ray; most hidden ones of the non-pilots none
    saved, could = rays_every - rays, int(every[group % 4 != 0].sum())
    assert saved >= 0.5 * could, (saved, could)
    assert not (every & ~hinted).any()
    for g, m in zip(*np.nonzero(hinted & ~every)):
        pts = _points_on(scene, int(mirrors[m]), rng, 40)
        assert exact.occluded(np.repeat(src[g : g + 1], len(pts), axis=0), pts).all(), (g, m)


def test_a_wall_behind_a_wall_is_hidden_and_a_wall_half_behind_is_not():
    b = SceneBuilder()
    b.add_quad("front", PEC, [[5, -4, 0], [5, 4, 0], [5, 4, 6], [5, -4, 6]])
    b.add_quad("behind", PEC, [[10, -3, 1], [10, 3, 1], [10, 3, 4], [10, -3, 4]])
    b.add_quad("half", PEC, [[10, 2, 1], [10, 12, 1], [10, 12, 4], [10, 2, 4]])
    scene = build_scene(*b.arrays())
    S = np.array([[0.0, 0.0, 2.0]])
    name = {scene.object_names[o]: p for p, o in enumerate(scene.polygon_object)}
    mirrors = np.array(sorted(name.values()))
    hidden, _ = hidden_mirrors(scene, S, np.zeros(1, np.int64), mirrors)
    got = dict(zip([scene.object_names[scene.polygon_object[m]] for m in mirrors], hidden[0]))
    assert got == {"front": False, "behind": True, "half": False}
    # a source box reaching past the front wall's edge sees the hidden wall's corner
    wide = np.array([[0.0, 0.0, 2.0], [0.0, 9.0, 2.0]])
    hidden, _ = hidden_mirrors(scene, wide, np.zeros(2, np.int64), mirrors)
    assert not hidden.any()


def test_image_trees_with_the_culling_hold_every_chain_that_carries_a_path(rng):
    """The culled trees are the full ones without the chains that start on a hidden mirror,
    and a city traced to order 3 with diffraction and two reflections finds the same paths."""
    scene = _city(rng)
    tx = np.array([[0.0, 0.0, 30.0]])
    rx = _outdoor(rng, scene, 12)
    full = build_image_levels(scene, rx, 2)
    stats: dict = {}
    cut = build_image_levels(scene, rx, 2, stats=stats, visibility_group=1)
    first = {tuple(r) for r in np.column_stack([full[1].source, full[1].polygons]).tolist()}
    kept_first = {tuple(r) for r in np.column_stack([cut[1].source, cut[1].polygons]).tolist()}
    assert kept_first <= first
    assert len(first) - len(kept_first) == stats["images_order_1_culled_hidden"] > 0
    # order 2: the chains whose first mirror was kept, less those whose second leg is proven
    # blocked (hidden_after_mirror)
    second = {tuple(r) for r in np.column_stack([full[2].source, full[2].polygons]).tolist()}
    kept_second = {tuple(r) for r in np.column_stack([cut[2].source, cut[2].polygons]).tolist()}
    after_first = {c for c in second if c[:2] in kept_first}
    assert kept_second <= after_first
    assert len(after_first) - len(kept_second) == stats["images_order_2_culled_hidden"] > 0
    opts = TraceOptions(max_reflections=3, diffraction=True, diffraction_reflections=2, rx_batch=4)
    on = trace(scene, tx, rx, opts)
    off = trace(scene, tx, rx, opts.with_(disable_culling={"mirror_visibility"}))
    assert len(on) > 50
    assert path_keys(on) == path_keys(off)
    assert on.stats["rx_images_order_1_culled_hidden"] > 0


def test_a_bent_mirror_is_bounded_by_all_its_corners_and_still_culled_behind_a_wall(rng):
    """A polygon merged from two triangles within the coplanar angle is not flat: the points
    that bound it are all its corners (a corner inside the hull in the plane may stand off
    it), and the proof with them still holds, checked by the float64 rule."""
    from ..conftest import quads_scene

    lift = 5e-6  # inside the coplanar angle (1e-5 rad), far above the plane tolerance (1e-12 diagonal)
    behind = [(10, -3, 1), (10, 3, 1), (10 + lift, 3, 4), (10, -3, 4)]
    front = [(5, -4, 0), (5, 4, 0), (5, 4, 6), (5, -4, 6)]
    scene = quads_scene([front, behind])
    assert scene.num_polygons == 2
    hulls = scene.polygon_hulls
    bent = int(scene.polygon_object.tolist().index(1))
    assert hulls.num_points[bent] == 4 and not hulls.occluder[bent]
    got = {tuple(np.round(p, 9)) for p in hulls.points[bent, :4]}
    assert got == {tuple(map(float, c)) for c in behind}
    S = np.array([[0.0, 0.0, 2.0]])
    hidden, _ = hidden_mirrors(scene, S, np.zeros(1, np.int64), np.arange(scene.num_polygons))
    assert hidden[0, bent] and not hidden[0, 1 - bent]
    pts = _points_on(scene, bent, rng, 40)
    assert NumpyRayCaster(scene).occluded(np.repeat(S, len(pts), axis=0), pts).all()


@pytest.mark.parametrize("size", [1, 4])
def test_the_compiled_proof_decides_every_pair_as_the_numpy_reference(size, rng):
    from wavepaths.search import kernels

    if not kernels.available():
        pytest.skip("numba (the `fast` extra) is not installed")
    scene = _city(rng, 18)
    mirrors = np.nonzero(reflecting_polygons(scene, True))[0]
    src = _outdoor(rng, scene, 12) if size == 1 else _groups_of_four(rng, scene, 8)
    group = np.arange(len(src)) // size
    ref, rays_ref = hidden_mirrors(scene, src, group, mirrors, compiled=False)
    got, rays = hidden_mirrors(scene, src, group, mirrors, compiled=True)
    assert ref.sum() >= 10
    assert rays == rays_ref
    assert np.array_equal(got, ref)


def _order_two(rng, scene, n: int = 8):
    """The order-2 chains of ``n`` outdoor sources, without any visibility culling."""
    src = _outdoor(rng, scene, n)
    lv = build_image_levels(scene, src, 2)[2]
    return lv.images[:, 1], lv.polygons[:, 0], lv.polygons[:, 1]


def test_second_legs_proven_blocked_are_blocked_by_the_occlusion_rule(rng):
    """Each order-2 (parent image I, previous mirror p, mirror q) called hidden: for every
    sampled point X_q of q (its corners and 40 random points), the leg from X_p (where
    I -> X_q crosses p's plane, wherever that is in the plane) to X_q is blocked by the
    float64 rule."""
    scene = _city(rng)
    exact = NumpyRayCaster(scene)
    I, p, q = _order_two(rng, scene)
    hidden, rays = hidden_after_mirror(scene, I, p, q)
    assert hidden.sum() >= 20, "almost nothing hidden: the test would prove little"
    assert rays <= len(I) and not hidden.all()
    n, d = scene.polygon_normal, scene.polygon_offset
    for i in np.nonzero(hidden)[0]:
        xq = _points_on(scene, int(q[i]), rng, 40)
        fi = I[i] @ n[p[i]] - d[p[i]]
        t = fi / (fi - (xq @ n[p[i]] - d[p[i]]))
        assert ((t > 0) & (t < 1)).all()
        xp = I[i] + t[:, None] * (xq - I[i])
        assert exact.occluded(xp, xq).all(), i


def test_a_second_mirror_behind_a_wall_is_hidden_from_the_image_and_not_without_the_wall():
    """S reflects on the wall p (x = -5, facing +x) towards q (x = 20); a wall at x = 10
    covering q's projection hides q from the image, one covering half of it does not, and the
    wall's shadow from S itself does not matter (the leg starts on p)."""
    def scene_with(block):
        b = SceneBuilder()
        b.add_quad("p", PEC, [[-5, -10, 0], [-5, 10, 0], [-5, 10, 6], [-5, -10, 6]])
        b.add_quad("q", PEC, [[20, -3, 1], [20, 3, 1], [20, 3, 4], [20, -3, 4]])
        if block is not None:
            b.add_quad("Q", PEC, block)
        return build_scene(*b.arrays())

    S = np.array([0.0, 0.0, 2.0])
    cases = {None: False,
             ((10, -12, -1), (10, 12, -1), (10, 12, 9), (10, -12, 9)): True,
             ((10, 0.5, -1), (10, 12, -1), (10, 12, 9), (10, 0.5, 9)): False}
    for block, want in cases.items():
        scene = scene_with(block)
        names = [scene.object_names[o] for o in scene.polygon_object]
        p, q = names.index("p"), names.index("q")
        I = S.copy()
        I[0] = -10.0 - S[0]  # S mirrored in x = -5
        hidden, _ = hidden_after_mirror(scene, I[None], np.array([p]), np.array([q]))
        assert bool(hidden[0]) is want, block


def test_the_compiled_second_leg_proof_decides_as_the_numpy_reference(rng):
    from wavepaths.search import kernels

    if not kernels.available():
        pytest.skip("numba (the `fast` extra) is not installed")
    scene = _city(rng, 18)
    I, p, q = _order_two(rng, scene, 6)
    ref, rays_ref = hidden_after_mirror(scene, I, p, q, compiled=False)
    got, rays = hidden_after_mirror(scene, I, p, q, compiled=True)
    assert ref.sum() >= 20 and rays == rays_ref
    assert np.array_equal(ref, got)


@pytest.mark.parametrize("q_z, want", [((10.0, 14.0), True), ((0.5, 4.0), False)])
def test_a_second_leg_starting_beyond_the_occluder_is_not_culled(q_z, want, rng):
    """S reflects on the ground (p) towards a wall q at x = 20 behind a wall Q at x = 10.
    Every segment from the image I (below the ground) to q crosses Q, but for a low q the
    legs start on the ground beyond Q (x up to 16) and reach q unblocked: only the high q,
    whose legs start before Q, may be culled. The float64 caster agrees on sampled legs."""
    b = SceneBuilder()
    b.add_quad("p", PEC, [[-30, -30, 0], [30, -30, 0], [30, 30, 0], [-30, 30, 0]])
    z0, z1 = q_z
    b.add_quad("q", PEC, [[20, -3, z0], [20, 3, z0], [20, 3, z1], [20, -3, z1]])
    b.add_quad("Q", PEC, [[10, -12, -5], [10, 12, -5], [10, 12, 30], [10, -12, 30]])
    scene = build_scene(*b.arrays())
    names = [scene.object_names[o] for o in scene.polygon_object]
    p, q = names.index("p"), names.index("q")
    I = np.array([[0.0, 0.0, -2.0]])  # S = (0, 0, 2) mirrored in the ground
    for compiled in (False, True):
        from wavepaths.search import kernels

        if compiled and not kernels.available():
            continue
        hidden, _ = hidden_after_mirror(scene, I, np.array([p]), np.array([q]), compiled=compiled)
        assert bool(hidden[0]) is want
    xq = _points_on(scene, q, rng, 40)
    t = 2.0 / (xq[:, 2] + 2.0)  # where I -> X_q meets the ground
    xp = I + t[:, None] * (xq - I)
    blocked = NumpyRayCaster(scene).occluded(xp, xq)
    assert blocked.all() if want else not blocked.all()
