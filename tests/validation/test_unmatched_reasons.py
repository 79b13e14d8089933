"""Why a Sionna path has no wavepaths match: each reason is given only where it holds.

Sionna RT paths are made up here (no Sionna run): the reasons depend on the geometry alone.
"""

from __future__ import annotations

import numpy as np

from wavepaths import TraceOptions, load_scene, trace
from wavepaths.fields import FieldConfig, compute_fields
from wavepaths.search.geometry import diffraction_point_parameter
from wavepaths.validation.compare import SIONNA_DUPLICATE, compare_paths
from wavepaths.validation.disagreements import (KELLER_IMAGE_TOL, SIONNA_ONLY_FAILURE, SIONNA_ONLY_MIRROR_SUBSTITUTION,
                                                SIONNA_ONLY_NOT_A_WEDGE, SIONNA_ONLY_OWN_FACE, _explain_sionna_only,
                                                _image_keller_residual, _sionna_mirror_substitution)
from wavepaths.validation.sionna_runner import SionnaPaths


def _sionna_paths(rows: list[tuple], depth: int = 1, names: tuple = ("box", "other_box", "ground")) -> SionnaPaths:
    """Fake Sionna paths: (vertices (k + 2, 3), interaction kinds, object ids[, primitive ids]) per
    row, one tx and one rx; the object ids index ``names``."""
    n = len(rows)
    verts = np.full((n, depth + 2, 3), np.nan)
    inter = np.zeros((n, depth), np.int8)
    objs = np.full((n, depth), -1, np.int64)
    prims = np.zeros((n, depth), np.int64)
    for i, (v, kinds, ob, *pr) in enumerate(rows):
        verts[i, : len(v)] = v
        inter[i, : len(kinds)] = kinds
        objs[i, : len(ob)] = ob
        if pr:
            prims[i, : len(pr[0])] = pr[0]
    length = np.array([np.linalg.norm(np.diff(r[0], axis=0), axis=1).sum() for r in rows])
    return SionnaPaths(np.zeros(n, np.int64), np.zeros(n, np.int64), inter, np.array([len(r[1]) for r in rows]),
                       verts, np.full(n, 1e-6 + 0j), length / 299_792_458.0, objs, prims,
                       tuple(names), 3.5e9, depth, 0, 0.0, 0.0, "fake")


def test_unmatched_sionna_paths_get_the_reason_that_holds():
    scene = load_scene("box_on_ground")  # a 10 m box on a 60 m ground; its foot is a concave edge
    tx, rx = np.array([0.0, -20.0, 10.0]), np.array([3.0, -15.0, 2.0])  # both in front of the face y = -5
    wp = trace(scene, tx[None], rx[None], TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=0))
    a = compute_fields(scene, wp, FieldConfig(3.5e9)).a
    d = int(np.nonzero((wp.interactions[:, 0] == 2) & (wp.depth == 1))[0][0])
    real = wp.vertices[d, :3]  # a diffracted path wavepaths finds (over a roof edge)
    # the foot of the face y = -5: from (-5, -5, 0) along x, free-space angle pi/2 around tx and rx
    t = float(diffraction_point_parameter(tx, rx, np.array([-5.0, -5.0, 0.0]), np.array([1.0, 0.0, 0.0])))
    foot = np.array([-5.0 + t, -5.0, 0.0])
    rows = [
        (real, [2], [0]),                                  # matched
        (real, [2], [1]),                                  # the same path on another object's copy of the edge
        (np.stack([tx, foot, rx]), [2], [0]),              # diffraction at the concave foot
        (np.stack([tx, np.array([0.0, -5.0, 7.0]), rx]), [2], [0]),  # a point on no edge
        (real, [2], [0], [7]),                             # the same path on another wedge of the same mesh
    ]
    sn = _sionna_paths(rows)
    comp = compare_paths(wp, a, sn, explain=lambda side, i: _explain_sionna_only(scene, sn, i) if side == "sionna" else "")
    reasons = {x["index"]: x["reason"] for x in comp.only_sionna}
    assert 0 not in reasons
    assert reasons[1] == SIONNA_DUPLICATE
    assert reasons[2] == SIONNA_ONLY_NOT_A_WEDGE
    assert reasons[3] == SIONNA_ONLY_FAILURE
    # two blocks of one mesh on one edge (a non-manifold edge): Sionna diffracts on each block's
    # wedge, the same path through two primitives of one object
    assert reasons[4] == SIONNA_DUPLICATE
    # without its matched twin, a duplicate is not excused: both copies are explained on their own
    sn2 = _sionna_paths(rows[1:2] + rows[1:2])
    none = wp.select(np.zeros(len(wp), bool))
    comp2 = compare_paths(none, a[:0], sn2, explain=lambda side, i: _explain_sionna_only(scene, sn2, i))
    assert [x["reason"] for x in comp2.only_sionna] == [SIONNA_ONLY_FAILURE, SIONNA_ONLY_FAILURE]


def test_matching_maximises_the_pairs_within_the_tolerance():
    """Three copies of one path per engine, shifted along x: only 0.073 m and 0.082 m lie within
    2 cm of each other. An assignment on raw distances pairs them all beyond 2 cm (0 matches);
    the matcher must find the one match."""
    import dataclasses

    scene = load_scene("box_on_ground")
    tx, rx = np.array([0.0, -20.0, 10.0]), np.array([3.0, -15.0, 2.0])
    wp = trace(scene, tx[None], rx[None], TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=0))
    d = int(np.nonzero((wp.interactions[:, 0] == 2) & (wp.depth == 1))[0][0])
    three = wp.select(np.array([d, d, d]))
    shift = np.array([1.0, 0.0, 0.0])
    u, v = np.array([0.061, 0.073, 0.054]), np.array([0.094, 0.082, 0.0])
    three = dataclasses.replace(three, vertices=three.vertices + u[:, None, None] * shift)
    sn = _sionna_paths([(wp.vertices[d, :3] + x * shift, [2], [0]) for x in v])
    comp = compare_paths(three, np.full(3, 1e-6 + 0j), sn)
    assert [(m.wp_index, m.sn_index) for m in comp.matches] == [(1, 1)]
    assert abs(comp.matches[0].vertex_error_m - 0.009) < 1e-9


def test_a_reflection_off_the_wedges_own_face_is_named():
    """Sionna RT's D-R at receiver 50 of ``etoile_crop``: a diffraction on a wall's vertical edge,
    then a reflection 1 cm along that wall (float32 points; |a| at -205 dB). A ray from the edge
    into the wedge's exterior never meets the wedge's own faces: such a path is named, and the
    same path reflected off another face still counts as a failure."""
    scene = load_scene("box_on_ground")  # a 10 m box, faces x, y = +-5, on a ground z = 0
    tx, rx = np.array([-20.0, -20.0, 12.0]), np.array([-15.0, -30.0, 1.5])
    p = np.array([-5.0, -5.0, 4.0])  # on the box's vertical edge x = y = -5
    q_own = np.array([-4.99, -5.0, 3.99])  # on the face y = -5, 1 cm from the edge
    q_ground = np.array([-8.0, -12.0, 0.0])  # on the ground, away from the edge

    def primitive(obj: int, q: np.ndarray) -> int:
        # the index, among the object's triangles, of the one that holds q (Sionna's primitive)
        tris = np.nonzero(scene.triangle_object == obj)[0]
        for k, tri in enumerate(tris):
            V = scene.vertices[scene.triangles[tri]]
            n = np.cross(V[1] - V[0], V[2] - V[0])
            lam = np.linalg.solve(np.stack([V[1] - V[0], V[2] - V[0], n], axis=1), q - V[0])
            if abs(lam[2]) < 1e-9 and lam[0] >= 0 and lam[1] >= 0 and lam[0] + lam[1] <= 1:
                return k
        raise AssertionError("no triangle holds the point")

    box, ground = scene.object_names.index("box"), scene.object_names.index("ground")
    # Sionna's object ids index its own names: ("box", "other_box", "ground")
    rows = [
        (np.stack([tx, p, q_own, rx]), [2, 1], [0, 0], [primitive(box, p + [1e-3, 0, 0]), primitive(box, q_own)]),
        (np.stack([tx, p, q_ground, rx]), [2, 1], [0, 2], [0, primitive(ground, q_ground)]),
        (np.stack([tx, q_own, p, rx]), [1, 2], [0, 0], [primitive(box, q_own), 0]),  # before the edge
    ]
    sn = _sionna_paths(rows, depth=2)
    reasons = [_explain_sionna_only(scene, sn, i) for i in range(len(rows))]
    assert reasons == [SIONNA_ONLY_OWN_FACE, SIONNA_ONLY_FAILURE, SIONNA_ONLY_OWN_FACE]


def test_a_matched_path_of_zero_amplitude_is_a_gain_violation():
    # a coefficient that collapsed to 0 in one engine: an infinite gain difference, which the
    # report's rule counts (it skipped it as NaN) and the summary counts as not finite
    from wavepaths.validation.compare import _gain_diff_db
    from wavepaths.validation.report import TOLERANCES, gain_violation

    scene = load_scene("box_on_ground")
    tx, rx = np.array([0.0, -20.0, 10.0]), np.array([3.0, -15.0, 2.0])
    wp = trace(scene, tx[None], rx[None], TraceOptions(max_reflections=0, diffraction=True, diffraction_reflections=0))
    d = int(np.nonzero((wp.interactions[:, 0] == 2) & (wp.depth == 1))[0][0])
    sn = _sionna_paths([(wp.vertices[d, :3], [2], [0])])
    a = compute_fields(scene, wp, FieldConfig(3.5e9)).a.copy()
    tol = TOLERANCES["gain_db_diffraction_compat"]
    sn.a[:] = a[d]
    (m,) = compare_paths(wp, a, sn).matches
    assert abs(m.gain_diff_db) < 1e-12 and not gain_violation(m.gain_diff_db, tol)
    a[d] = 0.0
    comp = compare_paths(wp, a, sn)
    (m,) = comp.matches
    assert m.gain_diff_db == -np.inf and gain_violation(m.gain_diff_db, tol)
    assert comp.summary()["gain_diff_db"] == {"max": None, "median": None, "non_finite": 1}
    assert gain_violation(float("nan"), tol) and gain_violation(tol * 1.001, tol) and not gain_violation(-tol, tol)
    assert _gain_diff_db(0.0, 0.0) == 0.0 and _gain_diff_db(1.0, 0.0) == np.inf
    assert np.isnan(_gain_diff_db(np.nan, 1.0)) and _gain_diff_db(10.0, 1.0) == 20.0


def _holding_triangle(scene, obj: int, q: np.ndarray) -> int:
    """The index, among object ``obj``'s triangles, of the one that holds ``q`` (Sionna's primitive)."""
    for k, tri in enumerate(np.nonzero(scene.triangle_object == obj)[0]):
        V = scene.vertices[scene.triangles[tri]]
        n = np.cross(V[1] - V[0], V[2] - V[0])
        lam = np.linalg.solve(np.stack([V[1] - V[0], V[2] - V[0], n], axis=1), q - V[0])
        if abs(lam[2]) < 1e-6 and lam[0] >= -1e-9 and lam[1] >= -1e-9 and lam[0] + lam[1] <= 1 + 1e-9:
            return k
    raise AssertionError("no triangle holds the point")


def test_a_mirror_exchanged_after_the_diffraction_point_is_named():
    """etoile_crop's one unexplained Sionna-only path (receiver 80, a D-R off a metal edge): Sionna
    placed the diffraction point with one facade's plane and recorded the reflection on the
    neighbouring facade, 1.13 mrad from it, 12-14 cm from the path wavepaths finds on that facade.

    Here: a screen's free vertical edge, then a wall whose upper facade leans back by 5 mrad
    from the seam at z = 3.5 m (a larger lean for a shift beyond the matcher's 2 cm at this
    scale). The substituted path is named; the exact path on the recorded facade is not (though
    it is exact for a coplanar neighbour too); a point 5 mm off the one the leaning facade gives,
    which no mirror explains, stays a failure."""
    from wavepaths.em.materials import PEC, itu_material
    from wavepaths.scene.builtin import SceneBuilder
    from wavepaths.scene.model import build_scene
    from wavepaths.search.geometry import diffraction_point_parameter

    tilt, seam = 5e-3, 3.5
    b = SceneBuilder()
    b.add_quad("blade", PEC, [(0, 0, 0), (10, 0, 0), (10, 0, 10), (0, 0, 10)])  # free vertical edge at x = 0
    b.add_quad("facade_a", itu_material("concrete"), [(-6, -20, 0), (-6, 5, 0), (-6, 5, seam), (-6, -20, seam)])
    top = (-6 - 6.5 * np.sin(tilt), seam + 6.5 * np.cos(tilt))  # leaning back about the seam's line
    b.add_quad("facade_b", itu_material("concrete"), [(-6, -20, seam), (-6, 5, seam), (top[0], 5, top[1]),
                                                      (top[0], -20, top[1])])
    # in facade_a's plane, another object's polygon: a path exact on one is exact on both
    b.add_quad("facade_c", itu_material("concrete"), [(-6, 5, 0), (-6, 9, 0), (-6, 9, seam), (-6, 5, seam)])
    scene = build_scene(*b.arrays())
    names = tuple(scene.object_names)
    blade, fa, fb = (names.index(x) for x in ("blade", "facade_a", "facade_b"))
    tx, rx = np.array([-5.0, 8.0, 5.0]), np.array([6.0, -8.0, 1.5])
    wp = trace(scene, tx[None], rx[None], TraceOptions(max_reflections=1, diffraction=True, diffraction_reflections=1))
    poly_a = int(scene.triangle_polygon[np.nonzero(scene.triangle_object == fa)[0][0]])
    poly_b = int(scene.triangle_polygon[np.nonzero(scene.triangle_object == fb)[0][0]])
    dr = np.nonzero((wp.depth == 2) & (wp.interactions[:, 0] == 2) & (wp.interactions[:, 1] == 1)
                    & (wp.primitive[:, 1] == poly_a))[0]
    vertical = np.abs(scene.dihedra.direction[wp.primitive[dr, 0], 2]) > 1 - 1e-12
    dr = dr[vertical & (np.abs(scene.dihedra.origin[wp.primitive[dr, 0], 0]) < 1e-9)]
    assert len(dr) == 1  # the D-R path over the edge x = 0 on the recorded facade exists
    exact = wp.vertices[dr[0], :4]
    d = int(wp.primitive[dr[0], 0])
    origin, direction = scene.dihedra.origin[d], scene.dihedra.direction[d]

    def image(x, poly):
        n, off = scene.polygon_normal[poly], scene.polygon_offset[poly]
        return x - 2 * (x @ n - off) * n

    # Sionna's mix: the point placed with facade_b's image of the receiver, the reflection point
    # where the ray from it toward that image crosses facade_a's plane
    img_b = image(rx, poly_b)
    p = origin + float(diffraction_point_parameter(tx, img_b, origin, direction)) * direction
    n_a, off_a = scene.polygon_normal[poly_a], scene.polygon_offset[poly_a]
    q = p + (off_a - p @ n_a) / ((img_b - p) @ n_a) * (img_b - p)
    moved = p + 5e-3 * direction  # 5 mm off the point facade_b gives: on no mirror's law
    q_moved = moved + (off_a - moved @ n_a) / ((img_b - moved) @ n_a) * (img_b - moved)
    assert 0.02 < np.linalg.norm(p - exact[1]) < 0.5 and seam - 1.0 < q[2] < seam  # beyond the matcher's 2 cm, below the seam
    rows = [(np.stack([tx, p, q, rx]), [2, 1], [blade, fa], [0, _holding_triangle(scene, fa, q)]),
            (exact, [2, 1], [blade, fa], [0, _holding_triangle(scene, fa, exact[2])]),
            (np.stack([tx, moved, q_moved, rx]), [2, 1], [blade, fa], [0, _holding_triangle(scene, fa, q_moved)])]
    sn = _sionna_paths(rows, depth=2, names=names)
    edges = np.array([d])
    # the substituted point: off Keller's law for the recorded mirror, on it for the neighbour
    assert _image_keller_residual(scene, rows[0][0], 0, [-1, poly_a], edges) > 100 * KELLER_IMAGE_TOL
    assert _image_keller_residual(scene, rows[0][0], 0, [-1, poly_b], edges) < 1e-9
    assert _image_keller_residual(scene, exact, 0, [-1, poly_a], edges) < 1e-9
    assert 10 * KELLER_IMAGE_TOL < _image_keller_residual(scene, rows[2][0], 0, [-1, poly_b], edges) < 1e-3
    assert [_sionna_mirror_substitution(scene, sn, i, 0, edges) for i in range(3)] == [True, False, False]
    reasons = [_explain_sionna_only(scene, sn, i) for i in range(3)]
    assert reasons == [SIONNA_ONLY_MIRROR_SUBSTITUTION, SIONNA_ONLY_FAILURE, SIONNA_ONLY_FAILURE]
