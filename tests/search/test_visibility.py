"""The part of an edge a transmitter may see (search/visibility.py): proven shadows only."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths.em.materials import PEC
from wavepaths.raycast.numpy_caster import NumpyRayCaster
from wavepaths.scene import load_scene
from wavepaths.scene.builtin import SceneBuilder
from wavepaths.scene.model import build_scene
from wavepaths.search.visibility import visibility_windows


def _wall_and_block(wall_y: tuple[float, float]):
    """A screen in the plane x = 5 (y in ``wall_y``, z in [0, 2]) in front of a block whose
    front top edge runs along y at x = 10, z = 0.5, from y = -5 to 5."""
    b = SceneBuilder()
    y0, y1 = wall_y
    b.add_quad("wall", PEC, [[5, y0, 0], [5, y1, 0], [5, y1, 2], [5, y0, 2]])
    b.add_box("block", PEC, (10, -5, 0), (12, 5, 0.5))
    return build_scene(*b.arrays())


def _front_top_edge(scene) -> int:
    dh = scene.dihedra
    mid = dh.origin + 0.5 * dh.length[:, None] * dh.direction
    hit = np.nonzero(np.isclose(mid[:, 0], 10) & np.isclose(mid[:, 2], 0.5) & np.isclose(dh.length, 10))[0]
    assert len(hit) == 1
    return int(hit[0])


S = np.array([[0.0, 0.0, 1.0]])


def test_window_is_the_part_of_the_edge_the_screen_leaves_in_view():
    # from S = (0, 0, 1), the ray to (10, y, 0.5) crosses x = 5 at (5, y / 2, 0.75): the
    # screen y in [-6, 1] hides y in [-12, 2), so only y in [2, 5] of the edge is seen
    scene = _wall_and_block((-6.0, 1.0))
    d = _front_top_edge(scene)
    v = visibility_windows(scene, S, np.array([d]))
    dh = scene.dihedra
    y_lo, y_hi = sorted(dh.origin[d, 1] + np.array([v.lo[0], v.hi[0]]) * dh.direction[d, 1])
    assert not v.hidden[0]
    assert y_lo == pytest.approx(2.0, abs=1e-6)
    assert y_hi == pytest.approx(5.0, abs=1e-9)
    # the end at y = -5 is hidden, the end at y = 5 is seen
    ends_y = dh.origin[d, 1] + np.array([0.0, dh.length[d]]) * dh.direction[d, 1]
    assert list(np.array([v.open0[0], v.open1[0]])[np.argsort(ends_y)]) == [False, True]


def test_an_edge_seen_through_a_slit_has_the_slits_window():
    """A roof edge 30 m away seen through a 6 cm slit in a 20 cm thick wall: the lit stretch is
    bounded by the slit's far side faces (|y| <= 0.03 x 30 / 10.2 = 0.0882 m), not by the
    wall's front (0.09 m). The march's hint ray at the corner of the front and a side face
    named the front, whose shadow ends there; a second, deeper probe names the side face and
    the window closes to the lit stretch (before, it stopped 1.8 mm wider on one side and
    8.7 m on the other)."""
    from ..conftest import boxes_scene

    half = 0.03
    scene = boxes_scene([((10, -20, 0), (10.2, -half, 30)), ((10, half, 0), (10.2, 20, 30)),
                         ((30, -20, 0), (40, 20, 10))])
    dh = scene.dihedra
    mid = dh.origin + 0.5 * dh.length[:, None] * dh.direction
    d = np.nonzero(np.isclose(mid[:, 0], 30) & np.isclose(mid[:, 2], 10) & np.isclose(dh.length, 40))[0]
    assert len(d) == 1
    v = visibility_windows(scene, np.array([[0.0, 0.0, 1.5]]), d)
    y = np.sort(dh.origin[d[0], 1] + np.array([v.lo[0], v.hi[0]]) * dh.direction[d[0], 1])
    lit = half * 30 / 10.2
    assert y == pytest.approx([-lit, lit], abs=1e-6)
    # and what lies inside is seen, just outside hidden (the window proves only the outside)
    inside = dh.origin[d[0]] + (0.999 * lit * np.array([-1.0, 1.0]) - dh.origin[d[0], 1])[:, None] * dh.direction[d[0]]
    outside = dh.origin[d[0]] + (1.001 * lit * np.array([-1.0, 1.0]) - dh.origin[d[0], 1])[:, None] * dh.direction[d[0]]
    tx = np.repeat([[0.0, 0.0, 1.5]], 2, axis=0)
    assert not scene.raycaster.occluded(tx, inside).any()
    assert scene.raycaster.occluded(tx, outside).all()


def test_an_edge_behind_a_wide_screen_is_hidden_ends_included():
    scene = _wall_and_block((-6.0, 6.0))
    d = _front_top_edge(scene)
    v = visibility_windows(scene, S, np.array([d]))
    assert v.hidden[0]
    assert not v.may_see(np.array([0]), np.array([0.0, 5.0, 10.0]), np.full(3, 10.0)).any()


def test_without_first_face_hints_every_window_is_the_whole_edge(monkeypatch):
    scene = _wall_and_block((-6.0, 6.0))
    d = _front_top_edge(scene)
    monkeypatch.setitem(scene.__dict__, "raycaster", NumpyRayCaster(scene))
    v = visibility_windows(scene, S, np.array([d]))
    assert v.lo[0] == 0 and v.hi[0] == pytest.approx(10.0) and not v.hidden[0]


@pytest.mark.parametrize("tx", [(-60.0, 0.0, 10.0), (20.0, 5.0, 1.5), (0.0, -30.0, 35.0), (70.0, 30.0, 2.0)])
def test_every_edge_point_seen_in_float64_lies_in_its_window(tx):
    """Soundness: sample every diffracting edge of the street canyon (41 points, ends
    included) and decide each in float64 with the reference caster; a point it sees must be
    inside its window (within tau) or an open end. And the windows must prove something."""
    scene = load_scene("street_canyon")
    dh = scene.dihedra
    d = np.nonzero(dh.diffracting)[0]
    src = np.broadcast_to(np.asarray(tx), (len(d), 3))
    v = visibility_windows(scene, src, d)
    k = 41
    t = np.linspace(0.0, 1.0, k)[None, :] * dh.length[d][:, None]
    pts = dh.origin[d][:, None, :] + t[..., None] * dh.direction[d][:, None, :]
    seen = ~NumpyRayCaster(scene).occluded(np.repeat(src, k, axis=0), pts.reshape(-1, 3)).reshape(len(d), k)
    rows = np.repeat(np.arange(len(d)), k)
    may = v.may_see(rows, t.ravel(), np.repeat(dh.length[d], k)).reshape(len(d), k)
    assert not (seen & ~may).any()
    # not vacuous: some edges wholly hidden, some windows shorter than their edge
    assert v.hidden.any()
    partly = ~v.hidden & ((v.lo > 0) | (v.hi < dh.length[d]))
    assert partly.any()
    assert (seen.any(axis=1) & ~v.hidden).any()


def test_aperture_window_holds_every_point_the_back_trace_accepts():
    """Soundness of the aperture windows (transmitter images of order 1 and 2, every
    diffracting edge of the street canyon, 41 points per edge): where the image method's
    back-trace finds a reflection point on the last mirror, the point lies in the window."""
    from wavepaths.search.images import backtrace, build_image_levels
    from wavepaths.search.aperture_windows import aperture_windows

    scene = load_scene("street_canyon")
    dh = scene.dihedra
    d_all = np.nonzero(dh.diffracting)[0]
    levels = build_image_levels(scene, np.array([[-60.0, 0.0, 10.0], [20.0, -5.0, 1.5]]), 2, True)
    for lv in levels[1:]:
        c = np.repeat(np.arange(len(lv)), len(d_all))
        d = np.tile(d_all, len(lv))
        lo, hi = aperture_windows(scene, lv.last[c], lv.polygons[c, -1], d)
        k = 41
        t = np.linspace(0.0, 1.0, k)[None, :] * dh.length[d][:, None]
        pts = (dh.origin[d][:, None, :] + t[..., None] * dh.direction[d][:, None, :]).reshape(-1, 3)
        rows = np.repeat(np.arange(len(d)), k)
        # the last step of the back-trace alone: the leg from the edge point to the last image
        last = type(lv)(lv.source, lv.polygons[:, -1:], lv.images[:, -2:])
        keep, _, _ = backtrace(scene, pts, last, c[rows])
        tk = t.ravel()[keep]
        tau = scene.length_tolerance(1e-9)
        assert ((tk >= lo[rows[keep]] - tau) & (tk <= hi[rows[keep]] + tau)).all()
        assert len(keep) > 0  # not vacuous: some legs do cross their mirrors
        assert (lo > hi).mean() > 0.5  # and most pairs are proven to carry no path


@pytest.mark.parametrize("compiled", [False, True])
def test_chain_aperture_windows_are_the_per_pair_windows(compiled):
    """The windows with each chain's planes built once (the context's form), numpy and
    compiled, against :func:`aperture_windows` pair by pair: the same interval within
    1e-12 m, and the same empty ones (transmitter images of order 1 and 2, every diffracting
    edge of the street canyon)."""
    from wavepaths.search import kernels
    from wavepaths.search.images import build_image_levels
    from wavepaths.search.aperture_windows import aperture_windows, chain_aperture_windows

    if compiled and not kernels.available():
        pytest.skip("numba (the `fast` extra) is not installed")
    scene = load_scene("street_canyon")
    d_all = np.nonzero(scene.dihedra.diffracting)[0]
    levels = build_image_levels(scene, np.array([[-60.0, 0.0, 10.0], [20.0, -5.0, 1.5]]), 2, True)
    for lv in levels[1:]:
        c = np.repeat(np.arange(len(lv)), len(d_all))
        d = np.tile(d_all, len(lv))
        o = np.random.default_rng(1).permutation(len(c))  # chains in any order, repeated
        c, d = c[o], d[o]
        ref_lo, ref_hi = aperture_windows(scene, lv.last[c], lv.polygons[c, -1], d)
        lo, hi = chain_aperture_windows(scene, lv.last, lv.polygons[:, -1], c, d, compiled=compiled)
        empty = ref_lo > ref_hi
        assert np.array_equal(empty, lo > hi)
        assert 0.2 < empty.mean() < 1.0
        assert np.allclose(lo[~empty], ref_lo[~empty], rtol=0, atol=1e-12)
        assert np.allclose(hi[~empty], ref_hi[~empty], rtol=0, atol=1e-12)


def _order_1_pairs_with_apertures(scene, tx):
    """The transmitters' order-1 images and every (image, diffracting edge) pair with a
    non-empty aperture window: ``(level, chain, dihedron, lo, hi)``."""
    from wavepaths.search.images import build_image_levels
    from wavepaths.search.aperture_windows import aperture_windows

    d_all = np.nonzero(scene.dihedra.diffracting)[0]
    lv = build_image_levels(scene, tx, 1, True)[1]
    c = np.repeat(np.arange(len(lv)), len(d_all))
    d = np.tile(d_all, len(lv))
    lo, hi = aperture_windows(scene, lv.last[c], lv.polygons[c, -1], d)
    keep = lo <= hi
    return lv, c[keep], d[keep], lo[keep], hi[keep]


@pytest.mark.parametrize("scene_name", ["street_canyon", "city"])
def test_image_windows_hold_every_edge_point_whose_leg_from_the_mirror_is_clear(scene_name, rng):
    """Soundness of the windows of image sources (``through``): for transmitter images of
    order 1 and every diffracting edge, sample 41 points per edge; where the leg from the
    last mirror (the back-trace's reflection point) to the point is clear by the float64
    rule, the point must lie in its window (within tau) or at an open end. And the
    windows must prove something beyond the aperture windows."""
    from wavepaths.search.images import backtrace

    if scene_name == "street_canyon":
        scene = load_scene("street_canyon")
        tx = np.array([[-60.0, 0.0, 10.0], [20.0, -5.0, 1.5]])
    else:
        from .test_mirror_visibility import _city

        scene = _city(rng, 12)
        tx = np.array([[0.0, 0.0, 30.0], [5.0, -70.0, 2.0]])
    exact = NumpyRayCaster(scene)
    dh = scene.dihedra
    lv, c, d, lo, hi = _order_1_pairs_with_apertures(scene, tx)
    v = visibility_windows(scene, lv.last[c], d, start=(lo, hi), through=lv.polygons[c, -1])
    k = 41
    t = np.linspace(0.0, 1.0, k)[None, :] * dh.length[d][:, None]
    pts = (dh.origin[d][:, None, :] + t[..., None] * dh.direction[d][:, None, :]).reshape(-1, 3)
    rows = np.repeat(np.arange(len(d)), k)
    last = type(lv)(lv.source, lv.polygons[:, -1:], lv.images[:, -2:])
    ok, X, _ = backtrace(scene, pts, last, c[rows])  # rows with a reflection point on the mirror
    clear = np.zeros(len(rows), bool)
    clear[ok] = ~exact.occluded(X[:, -1], pts[ok])
    may = v.may_see(rows, t.ravel(), dh.length[d][rows])
    assert not (clear & ~may).any()
    # not vacuous: clear legs exist, and some pairs are proven hidden beyond their apertures
    assert clear.any()
    assert v.hidden.sum() >= 5


def test_image_window_ends_in_the_mirrors_plane_are_open_without_float64_casts():
    """An edge end lying in the image's mirror plane (the mirror's own edges, coplanar faces'
    edges) is its own crossing point of that plane: the leg from the mirror to it has no
    length and the end is kept open (a window only proves hidden). Cast instead, rounding
    gave such legs a length of ~1e-10 m in the plane, each decided in float64 against the
    whole scene: 320 on the street canyon moved to 1e6 m and rotated; on munich's R2+D2
    context the float64 fallbacks fell from 284 k (1.4 M once in-plane hits were decided in
    float64) to 6,866."""
    from wavepaths.scene import transformed

    c_, s_ = np.cos(np.radians(37.0)), np.sin(np.radians(37.0))
    R, t = np.array([[c_, -s_, 0.0], [s_, c_, 0.0], [0.0, 0.0, 1.0]]), np.array([1e6, -2e6, 30.0])
    scene = transformed(load_scene("street_canyon"), R, t)
    lv, c, d, lo, hi = _order_1_pairs_with_apertures(scene, np.array([[-60.0, 0.0, 10.0], [20.0, -5.0, 1.5]]) @ R.T + t)
    dh, q = scene.dihedra, lv.polygons[c, -1]
    tol = scene.length_tolerance(1e-9)  # the windows' tau
    L = dh.length[d]
    ends = (dh.origin[d], dh.origin[d] + L[:, None] * dh.direction[d])
    in_plane = [np.abs(np.einsum("ij,ij->i", e, scene.polygon_normal[q]) - scene.polygon_offset[q]) <= tol for e in ends]
    before = scene.raycaster.exact_fallbacks
    v = visibility_windows(scene, lv.last[c], d, start=(lo, hi), through=q)
    assert in_plane[0].sum() + in_plane[1].sum() > 100  # not vacuous
    assert scene.raycaster.exact_fallbacks - before <= 5
    assert v.open0[in_plane[0] & (lo <= v.tau)].all() and v.open1[in_plane[1] & (hi >= L - v.tau)].all()


def test_image_windows_in_blocks_equal_one_call(monkeypatch):
    """The context computes the images' windows in blocks of pairs (bounded memory); a block
    boundary changes nothing: each pair's march is its own."""
    from wavepaths.search import context

    scene = load_scene("street_canyon")
    lv, c, d, lo, hi = _order_1_pairs_with_apertures(scene, np.array([[-60.0, 0.0, 10.0]]))
    one = visibility_windows(scene, lv.last[c], d, start=(lo, hi), through=lv.polygons[c, -1])
    monkeypatch.setattr(context, "WINDOW_BLOCK", 37)
    got = context._windows_in_blocks(scene, lv, c, d, lo, hi)
    assert len(c) > 5 * 37 and one.hidden.any()  # several blocks, and something proven
    for f in ("lo", "hi", "open0", "open1"):
        assert np.array_equal(getattr(got, f), getattr(one, f)), f
    assert got.rays == one.rays and got.tau == one.tau


def test_compiled_shadow_intervals_are_the_numpy_ones(rng):
    """Both modes of :func:`shadow_intervals`, compiled pair by pair, against numpy on
    random (source, triangle, edge) triples of a city: the same empty intervals, the same
    ends within 1e-9 m (ulps of the recentred coordinates), on a sample where many are
    non-empty."""
    from wavepaths.search import kernels
    from wavepaths.search.visibility import both_shadow_intervals

    from .test_mirror_visibility import _city, _outdoor

    if not kernels.available():
        pytest.skip("numba (the `fast` extra) is not installed")
    scene = _city(rng)
    exact = scene.raycaster.exact
    dh = scene.dihedra
    k = 20000
    S = _outdoor(rng, scene, 40, z=rng.uniform(1, 30))[rng.integers(0, 40, k)] - exact.center
    tri = rng.integers(0, len(exact.corners), k)
    d = rng.integers(0, len(dh.length), k)
    args = (exact, S, tri, dh.origin[d] - exact.center, dh.direction[d], dh.length[d].astype(float))
    ref = both_shadow_intervals(*args, compiled=False)
    got = both_shadow_intervals(*args, compiled=True)
    for r, g in zip(ref, got):
        empty = ~np.isfinite(r)
        assert np.array_equal(empty, ~np.isfinite(g))
        assert np.allclose(g[~empty], r[~empty], rtol=0, atol=1e-9)
    assert (ref[0] <= ref[1]).sum() > 200  # proven shadows among them


@pytest.mark.parametrize("through", [False, True])
def test_compiled_windows_are_the_numpy_windows(through):
    """The visibility windows with the compiled shadow intervals against numpy's, from a
    transmitter (order 0) and from its order-1 images (``through``): the same hidden pairs,
    the same ends within 1e-9 m."""
    from wavepaths.search import kernels
    from wavepaths.search.images import build_image_levels

    if not kernels.available():
        pytest.skip("numba (the `fast` extra) is not installed")
    scene = load_scene("street_canyon")
    d_all = np.nonzero(scene.dihedra.diffracting)[0]
    lv = build_image_levels(scene, np.array([[-60.0, 0.0, 10.0]]), 1, True)[1 if through else 0]
    c = np.repeat(np.arange(len(lv)), len(d_all))
    d = np.tile(d_all, len(lv))
    kw = {"through": lv.polygons[c, -1]} if through else {}
    ref = visibility_windows(scene, lv.last[c], d, compiled=False, **kw)
    got = visibility_windows(scene, lv.last[c], d, compiled=True, **kw)
    assert np.array_equal(ref.hidden, got.hidden) and ref.hidden.sum() > 5
    assert np.array_equal(ref.open0, got.open0) and np.array_equal(ref.open1, got.open1)
    assert np.allclose(got.lo, ref.lo, rtol=0, atol=1e-9) and np.allclose(got.hi, ref.hi, rtol=0, atol=1e-9)
    assert ref.rays == got.rays


@pytest.mark.parametrize("scene_name", ["street_canyon", "city"])
def test_two_mirror_windows_hold_every_point_the_full_back_trace_accepts(scene_name, rng):
    """Soundness of the windows through both mirrors of order-2 chains (``previous``): for
    transmitter images of order 2 and every diffracting edge, 41 points per edge; where the
    image method's back-trace through both mirrors finds the reflection points, the edge
    point lies in the window (within tau). Not vacuous: the second mirror empties windows
    the last one alone leaves open."""
    from wavepaths.search.images import backtrace, build_image_levels
    from wavepaths.search.aperture_windows import chain_aperture_windows

    if scene_name == "street_canyon":
        scene = load_scene("street_canyon")
        tx = np.array([[-60.0, 0.0, 10.0], [20.0, -5.0, 1.5]])
    else:
        from .test_mirror_visibility import _city

        scene = _city(rng)
        tx = np.array([[0.0, 0.0, 30.0]])
    dh = scene.dihedra
    d_all = np.nonzero(dh.diffracting)[0]
    lv = build_image_levels(scene, tx, 2, True)[2]
    sel = rng.permutation(len(lv))[:150]
    c = np.repeat(sel, len(d_all))
    d = np.tile(d_all, len(sel))
    lo1, hi1 = chain_aperture_windows(scene, lv.last, lv.polygons[:, -1], c, d)
    lo, hi = chain_aperture_windows(scene, lv.last, lv.polygons[:, -1], c, d, previous=lv.polygons[:, -2])
    k = 41
    t = np.linspace(0.0, 1.0, k)[None, :] * dh.length[d][:, None]
    pts = (dh.origin[d][:, None, :] + t[..., None] * dh.direction[d][:, None, :]).reshape(-1, 3)
    rows = np.repeat(np.arange(len(d)), k)
    keep, _, _ = backtrace(scene, pts, lv, c[rows])
    tk = t.ravel()[keep]
    tau = scene.length_tolerance(1e-9)
    assert len(keep) > 0
    assert ((tk >= lo[rows[keep]] - tau) & (tk <= hi[rows[keep]] + tau)).all()
    assert ((lo > hi) & (lo1 <= hi1)).sum() > 0.05 * (lo1 <= hi1).sum()


def test_compiled_two_mirror_windows_are_the_numpy_ones():
    """The windows through both mirrors (``previous``), compiled against numpy, on the street
    canyon's order-2 images: the same empty windows, ends within 1e-6 m (a root of a plane
    almost parallel to the edge amplifies the rounding; the windows' margins are larger)."""
    from wavepaths.search import kernels
    from wavepaths.search.images import build_image_levels
    from wavepaths.search.aperture_windows import chain_aperture_windows

    if not kernels.available():
        pytest.skip("numba (the `fast` extra) is not installed")
    scene = load_scene("street_canyon")
    d_all = np.nonzero(scene.dihedra.diffracting)[0]
    lv = build_image_levels(scene, np.array([[-60.0, 0.0, 10.0], [20.0, -5.0, 1.5]]), 2, True)[2]
    c = np.repeat(np.arange(len(lv)), len(d_all))
    d = np.tile(d_all, len(lv))
    args = (scene, lv.last, lv.polygons[:, -1], c, d)
    ref = chain_aperture_windows(*args, compiled=False, previous=lv.polygons[:, -2])
    got = chain_aperture_windows(*args, compiled=True, previous=lv.polygons[:, -2])
    empty = ref[0] > ref[1]
    assert np.array_equal(empty, got[0] > got[1]) and 0.5 < empty.mean() < 1.0
    for r, g in zip(ref, got):
        assert np.allclose(g[~empty], r[~empty], rtol=0, atol=1e-6)
