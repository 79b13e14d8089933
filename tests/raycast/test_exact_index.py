"""The triangle grid of ExactSegments.blocked: the same answers as trying every triangle.

``ExactSegments.blocked`` finds each segment's triangles through a uniform grid; with
``index=False`` it tries every triangle (the reference). The grid only leaves out
triangles whose padded boxes a segment does not pass through, so the two agree bit for
bit: checked on random, scene-crossing, far-reaching, short, axis-aligned and zero-length
segments, segments with ends exactly on faces, edges and vertices, and segments lying on
the grid's own cell boundaries, in built-in scenes, in a scene moved to 1e6 m, in a
triangle soup and in a scene of large overlapping triangles (a coarsened grid).
"""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths.em.materials import PEC
from wavepaths.raycast import canonical
from wavepaths.raycast.numpy_caster import ExactSegments, TriangleGrid
from wavepaths.scene import build_scene, load_scene, transformed

BUILTIN = ["half_plane", "wedge", "box_on_ground", "slit_shutter", "street_canyon", "three_face_edge", "touching_blocks"]


def soup(rng: np.random.Generator, n: int = 400, big: float = 40.0) -> "object":
    """A scene of ``n`` random triangles, sizes log-uniform from 5 cm to ``big`` m."""
    c = rng.uniform(-50, 50, (n, 3)) * [1, 1, 0.3]
    size = np.exp(rng.uniform(np.log(0.05), np.log(big), n))
    v = c[:, None, :] + rng.normal(size=(n, 3, 3)) * size[:, None, None]
    return build_scene(v.reshape(-1, 3), np.arange(3 * n).reshape(n, 3), np.zeros(n, int), np.zeros(n, int),
                       ["soup"], [PEC], source="soup")


def on_faces(ex: ExactSegments, rng: np.random.Generator, k: int) -> np.ndarray:
    """(k, 3) recentred points inside faces, on edges and at vertices of the scene."""
    t = rng.integers(0, len(ex.corners), k)
    w = rng.dirichlet(np.ones(3), k)
    kind = rng.integers(0, 3, k)
    w[kind == 1, 2] = 0.0  # on an edge
    w[kind == 2] = [1.0, 0.0, 0.0]  # at a vertex
    w /= w.sum(axis=1, keepdims=True)
    return np.einsum("kij,ki->kj", ex.corners[t], w)


def on_cell_boundaries(ex: ExactSegments, rng: np.random.Generator, k: int) -> np.ndarray:
    """(k, 3) recentred points with one to three coordinates exactly on the grid's cell faces."""
    g = ex.grid
    p = rng.uniform(g.origin, g.origin + g.shape * g.size, (k, 3))
    snap = rng.random((k, 3)) < 0.6
    face = g.origin + rng.integers(0, g.shape + 1, (k, 3)) * g.size
    return np.where(snap, face, p)


def segments(ex: ExactSegments, rng: np.random.Generator, k: int = 600) -> tuple[np.ndarray, np.ndarray]:
    """Recentred, canonical segments of every kind the grid could get wrong."""
    lo, hi = ex.lo.min(axis=0), ex.hi.max(axis=0)
    span = hi - lo
    box = lambda m: rng.uniform(lo - 0.1 * span, hi + 0.1 * span, (m, 3))  # noqa: E731
    unit = rng.normal(size=(k, 3))
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    faces, cells = on_faces(ex, rng, 2 * k), on_cell_boundaries(ex, rng, 2 * k)
    axis_b = faces[:k].copy()
    axis_b[np.arange(k), rng.integers(0, 3, k)] += rng.normal(size=k) * span.max()
    flat_b = cells[k:].copy()
    keep = rng.integers(0, 3, k)
    flat_b[np.arange(k), keep] = cells[np.arange(k), keep]  # in the same cell-face plane as its start
    pairs = [
        (box(k), box(k)),  # random, mostly across the scene
        (faces[:k], faces[k:]),  # ends on faces, edges, vertices
        (faces[:k], box(k)),
        (box(k) + 1e3 * span.max() * unit, box(k)),  # from far away
        (faces[:k], faces[:k] + 1e-6 * unit),  # short
        (faces[k:], faces[k:] + 1e-11 * unit),  # shorter than the plane tolerance
        (faces[:k], axis_b),  # axis-aligned
        (cells[:k], cells[k:]),  # between points on cell boundaries
        (cells[:k], flat_b),  # in a plane of cell faces (along cell edges, where two are kept)
        (faces[:50], faces[:50]),  # zero length
    ]
    a = np.concatenate([p[0] for p in pairs])
    b = np.concatenate([p[1] for p in pairs])
    a, b, _ = canonical(a, b)
    return a, b


def assert_same_as_every_triangle(ex: ExactSegments, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    reference = ex.blocked(a, b, index=False)
    np.testing.assert_array_equal(ex.blocked(a, b), reference)
    np.testing.assert_array_equal(ex.blocked(a, b, budget=1 << 14), reference)  # in many small batches
    return reference


@pytest.mark.parametrize("name", BUILTIN)
def test_the_grid_gives_the_answers_of_every_triangle_in_builtin_scenes(name, rng):
    ex = ExactSegments(load_scene(name))
    blocked = assert_same_as_every_triangle(ex, *segments(ex, rng))
    assert 0.02 < blocked.mean() < 0.9


def test_the_grid_gives_the_answers_of_every_triangle_in_a_scene_moved_to_1e6_m(rng):
    r = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    s = transformed(load_scene("street_canyon"), rotation=r, translation=[1e6, -2e6, 3e5])
    ex = ExactSegments(s)
    blocked = assert_same_as_every_triangle(ex, *segments(ex, rng))
    assert 0.1 < blocked.mean() < 0.9
    # segments given in metres, as the caster gets them: recentred and put in order there
    lo, hi = s.bounds
    a, b = rng.uniform(lo, hi, (2, 2000, 3))
    a, b, _ = canonical(a - ex.center, b - ex.center)
    assert_same_as_every_triangle(ex, a, b)


def test_the_grid_gives_the_answers_of_every_triangle_in_a_triangle_soup(rng):
    ex = ExactSegments(soup(rng))
    blocked = assert_same_as_every_triangle(ex, *segments(ex, rng, 1500))
    assert 0.05 < blocked.mean() < 0.95


def test_large_overlapping_triangles_coarsen_the_grid_and_keep_the_answers(rng):
    """1500 triangles with corners anywhere in a 100 m cube: at 4 cells per triangle each
    would be listed in hundreds of cells; the grid gets coarser to bound its listings."""
    n = 1500
    v = rng.uniform(-50, 50, (3 * n, 3))
    s = build_scene(v, np.arange(3 * n).reshape(n, 3), np.zeros(n, int), np.zeros(n, int), ["big"], [PEC], source="big")
    ex = ExactSegments(s)
    g = ex.grid
    cells = g.cell_ptr.size - 1
    assert cells < n
    assert len(g.cell_triangles) <= 32 * max(n, cells)
    assert_same_as_every_triangle(ex, *segments(ex, rng, 200))


def test_a_segment_with_a_nan_end_is_not_blocked(rng):
    ex = ExactSegments(load_scene("street_canyon"))
    a = np.array([[20.0, -30.0, 5.0], [np.nan, 0.0, 5.0]]) - ex.center
    b = np.array([[20.0, 30.0, 5.0], [20.0, 30.0, 5.0]]) - ex.center
    np.testing.assert_array_equal(ex.blocked(a, b), [True, False])
    np.testing.assert_array_equal(ex.blocked(a, b, index=False), [True, False])


@pytest.mark.parametrize("name", ["street_canyon", "slit_shutter"])
def test_every_triangle_whose_padded_box_a_segment_meets_is_paired_with_it(name, rng):
    """The grid's promise, checked directly: the pairs of a segment include every triangle
    whose box, grown by the padding, the segment passes through (by a slab test)."""
    ex = ExactSegments(load_scene(name))
    a, b = segments(ex, rng, 300)
    live = (a != b).any(axis=1)
    a, b = a[live], b[live]
    g: TriangleGrid = ex.grid
    walk = g.walk(a, b)
    paired = np.zeros((len(a), len(ex.lo)), dtype=bool)
    for seg, tri in g.pairs(walk, np.arange(len(a)), 0, int(walk.slabs.max()), 1 << 16):
        paired[seg, tri] = True
    d = b - a
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (ex.lo[None] - ex.pad - a[:, None]) / d[:, None]
        t2 = (ex.hi[None] + ex.pad - a[:, None]) / d[:, None]
    inside = (a[:, None] >= ex.lo[None] - ex.pad) & (a[:, None] <= ex.hi[None] + ex.pad)  # where d = 0
    enter = np.where(d[:, None] == 0, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2)).max(axis=2)
    leave = np.where(d[:, None] == 0, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2)).min(axis=2)
    meets = (np.maximum(enter, 0.0) <= np.minimum(leave, 1.0))
    assert meets.sum() > len(a)
    assert not (meets & ~paired).any()
    assert paired.sum() < 0.5 * paired.size  # and it leaves triangles out


@pytest.mark.slow
@pytest.mark.sionna
def test_the_grid_gives_the_answers_of_every_triangle_on_munich(rng):
    """Sionna RT's munich (38,936 triangles): segments from a roof-top transmitter to
    receivers at 1.5 m, and between receivers."""
    pytest.importorskip("sionna.rt")
    from wavepaths.bench.scenes import sionna_scene_xml

    s = load_scene(sionna_scene_xml("munich"))
    ex = ExactSegments(s)
    lo, hi = s.bounds
    k = 150
    rx = np.column_stack([rng.uniform(lo[:2], hi[:2], (2 * k, 2)), np.full(2 * k, 1.5)])
    a = np.concatenate([np.repeat([[8.5, 21.0, 27.0]], k, axis=0), rx[:k]])
    b = np.concatenate([rx[:k], rx[k:]])
    a, b, _ = canonical(a - ex.center, b - ex.center)
    blocked = assert_same_as_every_triangle(ex, a, b)
    assert 0.5 < blocked.mean() < 1.0
    a, b = segments(ex, rng, 40)
    assert_same_as_every_triangle(ex, a, b)
