"""The Embree caster's compiled set-up and confirmation (numba, optional) against its numpy reference."""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths.raycast import embree
from wavepaths.raycast.embree import EmbreeRayCaster
from wavepaths.scene import load_scene, transformed

needs_numba = pytest.mark.skipif(embree._compiled() is None, reason="numba is not installed (the `fast` extra)")


def _segments(scene, rng, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Random segments: free ones (some ends outside the scene's box), vertex to vertex
    (ends on faces and edges), and face points to receivers (the search's legs)."""
    lo, hi = scene.bounds
    span = hi - lo
    a = lo - 0.2 * span + rng.uniform(size=(n, 3)) * 1.4 * span
    b = lo + rng.uniform(size=(n, 3)) * span
    v = scene.vertices[rng.integers(0, len(scene.vertices), (n, 2))]
    tri = scene.vertices[scene.triangles[rng.integers(0, len(scene.triangles), n)]]
    w = rng.dirichlet([1, 1, 1], n)
    on_face = np.einsum("ki,kij->kj", w, tri)
    return np.concatenate([a, v[:, 0], on_face, a[:50]]), np.concatenate([b, v[:, 1], b, a[:50]])  # + zero length


def _street_canyon(moved: bool):
    """The built-in street canyon, or the same moved to 1e6 m and rotated by 37 degrees."""
    scene = load_scene("street_canyon")
    if moved:
        c, s = np.cos(np.radians(37.0)), np.sin(np.radians(37.0))
        scene = transformed(scene, np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.array([1e6, -2e6, 30.0]))
    return scene


@needs_numba
@pytest.mark.parametrize("moved", [False, True], ids=["origin", "at_1e6_m_rotated"])
def test_compiled_and_numpy_embree_casters_decide_every_segment_alike(moved, rng):
    """Bit-for-bit the same verdicts, both directions, on 12,000 segments of the street
    canyon, also with the scene moved to 1e6 m and rotated (float32 recentring)."""
    scene = _street_canyon(moved)
    a, b = _segments(scene, rng, 4000)
    ref, got = EmbreeRayCaster(scene, compiled=False), EmbreeRayCaster(scene, compiled=True, bvh=False)
    for x, y in ((a, b), (b, a)):
        expect = ref.occluded(x, y)
        np.testing.assert_array_equal(got.occluded(x, y), expect)
        assert 0.1 < expect.mean() < 0.9  # both outcomes are exercised
    assert not got.occluded(a[-50:], a[-50:]).any()  # zero-length segments are never blocked
    assert got.rays_cast == ref.rays_cast  # the same half-rays were needed
    assert got.exact_fallbacks == ref.exact_fallbacks


@needs_numba
def test_legs_read_from_the_chains_decide_like_the_gathered_segments(rng):
    """``occluded_legs(V, alive, i, j)`` (the rays made from the chains' array) answers what
    ``occluded(V[alive, i], V[alive, j])`` answers, leg by leg, with the same ray count; and
    the degenerate-chain kernel of ``occluded_chains`` flags what its numpy form flags."""
    from wavepaths.search import _numba as search_numba

    scene = load_scene("street_canyon")
    a, b = _segments(scene, rng, 1500)
    n = len(a) // 3 * 3
    V = np.stack([a[:n], b[:n], a[::-1][:n]], axis=1).reshape(-1, 3, 3)  # chains of three points, two legs
    alive = np.sort(rng.choice(len(V), len(V) // 2, replace=False))
    for i, j in ((0, 1), (2, 1), (1, 2)):
        gathered, legs = EmbreeRayCaster(scene, bvh=False), EmbreeRayCaster(scene, bvh=False)
        expect = gathered.occluded(V[alive, i], V[alive, j])
        np.testing.assert_array_equal(legs.occluded_legs(V, alive, i, j), expect)
        assert legs.rays_cast == gathered.rays_cast
        assert 0.05 < expect.mean() < 0.95
    W = V.copy()
    W[::7, 1] = W[::7, 0] + 1e-13  # a first segment within rounding
    W[1::7, 2] = W[1::7, 1]  # a last segment of length 0
    for s in (2, 3, 4):
        X = np.concatenate([W, W[:, :1]], axis=1)[:, :s] if s == 4 else W[:, :s]
        if s == 4:
            X[2::7, 2] = X[2::7, 1] + 1e-9  # an inner segment below the weld tolerance
        d = np.diff(X, axis=1)
        seg = np.sqrt(np.einsum("ksj,ksj->ks", d, d))
        weld, plane = 1e-7, 1e-10
        ref = (seg[:, 1:-1] <= weld).any(axis=1) if s > 3 else np.zeros(len(X), bool)
        if s > 2:
            ref |= (seg[:, [0, -1]] <= plane).any(axis=1)
        got = search_numba.degenerate_chains(np.ascontiguousarray(X), weld, plane)
        np.testing.assert_array_equal(got, ref)
        assert got.any() == (s > 2)


def test_without_numba_the_default_caster_runs_the_numpy_reference(monkeypatch, rng):
    """``compiled=True`` is a clear error; the default falls back to numpy, same verdicts."""
    scene = load_scene("street_canyon")
    a, b = _segments(scene, rng, 500)
    expect = EmbreeRayCaster(scene, compiled=False).occluded(a, b)
    monkeypatch.setattr(embree, "_compiled", lambda: None)
    with pytest.raises(ImportError, match="numba"):
        EmbreeRayCaster(scene, compiled=True, bvh=False)
    caster = EmbreeRayCaster(scene, bvh=False)
    assert caster._kernels is None
    np.testing.assert_array_equal(caster.occluded(a, b), expect)


@needs_numba
@pytest.mark.parametrize("tree", [False, True], ids=["half_rays", "float64_tree"])
def test_threaded_occlusion_decides_and_counts_like_one_thread(tree, monkeypatch, rng):
    """A query split over threads (numba's thread count) gives the same verdicts, in order,
    and the same ray and fallback counts as on one thread, with Embree's half-rays and with
    the float64 tree."""
    import numba

    scene = load_scene("street_canyon")
    a, b = _segments(scene, rng, 4000)
    monkeypatch.setattr(embree, "THREAD_MIN_SEGMENTS", 1000)  # 12,050 segments: several slices
    one, many = EmbreeRayCaster(scene, bvh=tree), EmbreeRayCaster(scene, bvh=tree)
    old = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        assert one._threads(len(a)) == 1
        expect = one.occluded(a, b)
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        if numba.config.NUMBA_NUM_THREADS < 2:
            pytest.skip("one CPU: nothing to split")
        assert many._threads(len(a)) >= 2
        np.testing.assert_array_equal(many.occluded(a, b), expect)
    finally:
        numba.set_num_threads(old)
    assert many.rays_cast == one.rays_cast
    assert many.exact_fallbacks == one.exact_fallbacks


@needs_numba
@pytest.mark.parametrize("moved", [False, True], ids=["origin", "at_1e6_m_rotated"])
def test_compiled_first_triangle_hints_equal_the_numpy_ones(moved, rng, monkeypatch):
    """The compiled ray set-up of ``first_triangle`` (clipping, float32 rays) builds the very
    rays of the numpy one: the same triangles, on one thread and split over several (cast
    through embreex: the direct casts are the next test's)."""
    scene = _street_canyon(moved)
    a, b = _segments(scene, rng, 4000)
    _same_first_triangles(EmbreeRayCaster(scene, compiled=False), EmbreeRayCaster(scene, compiled=True, direct=False, bvh=False),
                          a, b, monkeypatch)


def _same_first_triangles(ref, got, a, b, monkeypatch):
    """``got.first_triangle`` names ``ref``'s triangles, both directions, on one thread and
    split over several, and both count the same rays."""
    import numba

    for x, y in ((a, b), (b, a)):
        expect = ref.first_triangle(x, y)
        assert 0.1 < (expect >= 0).mean() < 0.95
        np.testing.assert_array_equal(got.first_triangle(x, y), expect)
    monkeypatch.setattr(embree, "THREAD_MIN_SEGMENTS", 1000)
    old = numba.get_num_threads()
    try:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        np.testing.assert_array_equal(got.first_triangle(a, b), ref.first_triangle(a, b))
    finally:
        numba.set_num_threads(old)
    assert got.rays_cast == ref.rays_cast > 0


@needs_numba
@pytest.mark.parametrize("moved", [False, True], ids=["origin", "at_1e6_m_rotated"])
def test_direct_casts_decide_and_count_like_the_embreex_path(moved, rng):
    """The occlusion kernel that casts through Embree's C entry point (``direct``, the
    default with numba) gives the verdicts, ray counts and float64 fallbacks of the
    compiled set-up around embreex's calls, both directions, also at 1e6 m rotated."""
    scene = _street_canyon(moved)
    a, b = _segments(scene, rng, 4000)
    ref, got = EmbreeRayCaster(scene, direct=False, bvh=False), EmbreeRayCaster(scene, bvh=False)
    assert ref._direct is None and got._direct is not None
    for x, y in ((a, b), (b, a)):
        expect = ref.occluded(x, y)
        np.testing.assert_array_equal(got.occluded(x, y), expect)
        assert 0.1 < expect.mean() < 0.9
    V = np.stack([a, b], axis=1)
    alive = np.arange(0, len(V), 3)
    np.testing.assert_array_equal(got.occluded_legs(V, alive, 1, 0), ref.occluded_legs(V, alive, 1, 0))
    assert got.rays_cast == ref.rays_cast > 0
    assert got.exact_fallbacks == ref.exact_fallbacks > 0  # the undecided verdicts were exercised


@needs_numba
@pytest.mark.parametrize("moved", [False, True], ids=["origin", "at_1e6_m_rotated"])
def test_direct_first_triangle_hints_equal_the_embreex_ones(moved, rng, monkeypatch):
    """``first_triangle`` cast from the compiled pass through Embree's C entry point names the
    triangles of the embreex path, ray for ray, both directions, on one thread and split
    over several, and counts the same rays; also for segments that leave the scene's box."""
    scene = _street_canyon(moved)
    a, b = _segments(scene, rng, 4000)
    far = scene.vertices.mean(axis=0) + 3 * scene.diagonal * rng.normal(size=(500, 3))
    a, b = np.concatenate([a, far, far]), np.concatenate([b, b[:500], far[::-1]])  # some miss the box
    ref, got = EmbreeRayCaster(scene, direct=False, bvh=False), EmbreeRayCaster(scene, bvh=False)
    assert ref._direct is None and got._direct is not None
    _same_first_triangles(ref, got, a, b, monkeypatch)


def test_without_embrees_library_the_caster_casts_through_embreex(monkeypatch, rng):
    """When Embree's C library cannot be found, the default caster keeps the embreex path
    (same verdicts); asking for ``direct=True`` then is a clear error."""
    from wavepaths.raycast import embree_c

    scene = load_scene("street_canyon")
    a, b = _segments(scene, rng, 500)
    expect = EmbreeRayCaster(scene, compiled=False).occluded(a, b)
    monkeypatch.setattr(embree_c, "library", lambda: None)
    caster = EmbreeRayCaster(scene, bvh=False)
    assert caster._direct is None
    np.testing.assert_array_equal(caster.occluded(a, b), expect)
    with pytest.raises(ImportError, match="direct=True"):
        EmbreeRayCaster(scene, direct=True)
