"""Property-based tests (Hypothesis) of the proven shadows (search/visibility.py): sources
anywhere, on vertices, edges and faces or 1e-9 m off them; no point the float64 occlusion
rule sees may fall outside its window, and every point of a proven shadow interval is
blocked by that rule."""

from __future__ import annotations

import numpy as np
from hypothesis import given, note
from hypothesis import strategies as st

from wavepaths.raycast import canonical
from wavepaths.raycast.numpy_caster import NumpyRayCaster
from wavepaths.search.visibility import shadow_intervals, visibility_windows

from .test_stress_properties import SCENES, SETTINGS, points

K = 31  # points per edge, ends included


def _check_windows(name: str, S: np.ndarray) -> None:
    scene = SCENES[name]
    dh = scene.dihedra
    d = np.nonzero(dh.diffracting)[0]
    src = np.broadcast_to(S, (len(d), 3))
    v = visibility_windows(scene, src, d)
    assert np.isfinite(v.lo).all() and np.isfinite(v.hi).all()
    t = np.linspace(0.0, 1.0, K)[None, :] * dh.length[d][:, None]
    pts = dh.origin[d][:, None, :] + t[..., None] * dh.direction[d][:, None, :]
    seen = ~NumpyRayCaster(scene).occluded(np.repeat(src, K, axis=0), pts.reshape(-1, 3)).reshape(len(d), K)
    may = v.may_see(np.repeat(np.arange(len(d)), K), t.ravel(), np.repeat(dh.length[d], K)).reshape(len(d), K)
    bad = np.argwhere(seen & ~may)
    note(f"S={S.tolist()} hidden={int(v.hidden.sum())} bad={bad[:5].tolist()}")
    assert len(bad) == 0


@SETTINGS
@given(st.data())
def test_windows_hold_every_point_seen_three_face_edge(data):
    _check_windows("three_face_edge", data.draw(points("three_face_edge")))


@SETTINGS
@given(st.data())
def test_windows_hold_every_point_seen_touching_blocks(data):
    _check_windows("touching_blocks", data.draw(points("touching_blocks")))


@SETTINGS
@given(st.data())
def test_every_point_of_a_proven_shadow_is_blocked(data):
    """For a random source and every (triangle, edge) pair of the scene, points drawn inside
    the proven interval are blocked by the float64 rule (the segment crosses that triangle)."""
    name = data.draw(st.sampled_from(sorted(SCENES)))
    scene = SCENES[name]
    S = data.draw(points(name))
    exact = scene.raycaster.exact
    dh = scene.dihedra
    d = np.nonzero(dh.diffracting)[0]
    tri = np.arange(scene.num_triangles)
    dd, tt = np.repeat(d, len(tri)), np.tile(tri, len(d))
    c0 = exact.center
    S_r = np.broadcast_to(S - c0, (len(dd), 3))
    lo, hi = shadow_intervals(exact, S_r, tt, dh.origin[dd] - c0, dh.direction[dd], dh.length[dd])
    some = np.nonzero(lo <= hi)[0]
    note(f"S={S.tolist()} intervals={len(some)}")
    if len(some) == 0:
        return
    u = np.array(data.draw(st.lists(st.floats(0, 1), min_size=3, max_size=3)))
    rows = np.repeat(some, 3)
    t = lo[rows] + np.tile(u, len(some)) * (hi[rows] - lo[rows])
    E = dh.origin[dd[rows]] - c0 + t[:, None] * dh.direction[dd[rows]]
    a, b, _ = canonical(S_r[rows], E)
    assert exact.crosses(a, b, tt[rows]).all()
