"""Property-based tests (Hypothesis) on whole traces: random end points, including points
snapped onto vertices, edges and faces of the scene, must give paths that obey the laws at
every vertex, finite fields, and reciprocal paths and coefficients."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, note, settings
from hypothesis import strategies as st

from wavepaths import TraceOptions, trace
from wavepaths.em.materials import PEC
from wavepaths.fields import compute_fields
from wavepaths.scene import build_scene
from wavepaths.scene.builtin import builtin_arrays

from .helpers import check_laws, config, path_table, reported

SETTINGS = settings(max_examples=100, deadline=None, database=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
OPTS = TraceOptions(max_reflections=1, diffraction_reflections=1)


def pec(name: str):
    v, t, o, _, names, _ = builtin_arrays(name)
    return build_scene(v, t, o, np.zeros(len(t), int), names, [PEC])


SCENES = {name: pec(name) for name in ("three_face_edge", "touching_blocks")}
BOX = {"three_face_edge": (np.array([-3.0, -3.0, 0.5]), np.array([10.0, 7.0, 9.0])),
       "touching_blocks": (np.array([-3.0, -3.0, 0.5]), np.array([11.0, 11.0, 9.0]))}


ON = ("free", "free", "vertex", "edge", "face")
NEAR = ON + ("near_face",)


@st.composite
def points(draw, name, kinds=NEAR):
    """A free point in the scene's box, or a point snapped onto one of its vertices, edges or
    triangles (the defined edge cases), or 1e-9 m off a triangle."""
    s = SCENES[name]
    lo, hi = BOX[name]
    kind = draw(st.sampled_from(kinds))
    u = np.array([draw(st.floats(0, 1)) for _ in range(3)])
    if kind == "free":
        return lo + u * (hi - lo)
    tri = s.vertices[s.triangles[draw(st.integers(0, s.num_triangles - 1))]]
    if kind == "vertex":
        return tri[int(3 * u[0]) % 3]
    if kind == "edge":
        return tri[0] + u[0] * (tri[1] - tri[0])
    a, b = sorted(u[:2])
    p = tri[0] * a + tri[1] * (b - a) + tri[2] * (1 - b)
    if kind == "near_face":
        n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
        p = p + 1e-9 * draw(st.sampled_from([-1.0, 1.0])) * n / np.linalg.norm(n)
    return p


def trace_or_report(scene, a, b):
    """Paths, or None when the engine reports the case (same position, point inside a block)."""
    return reported(lambda: trace(scene, a[None], b[None], OPTS), allow_on_face=True)


@pytest.mark.parametrize("name", list(SCENES))
def test_random_end_points_obey_the_laws_and_give_finite_fields(name):
    @SETTINGS
    @given(points(name), points(name))
    def check(a, b):
        note(f"a = {a.tolist()!r}, b = {b.tolist()!r}")
        s = SCENES[name]
        p = trace_or_report(s, a, b)
        if p is None:
            return
        assert np.isfinite(p.vertices).all()
        check_laws(s, p, tol=1e-9)
        f = compute_fields(s, p, config("V", 3.5e9))
        assert np.isfinite(f.a).all()
        path_table(p)  # no path twice

    check()


S11 = (
    "BUG S11: FindDihedron decides with cosines (u_e . P_f, u_e . u_r); within ~1.5e-8 rad of a face "
    "they round to 1 and the decision becomes arbitrary and asymmetric, while sector_of (atan2, "
    "tolerance 1e-12 rad) lets such sources through: e.g. three_face_edge, a = (3.999999999, 4, 4), "
    "b = (4, 2, 3.999999999) diffract on the awning's free edge tx -> rx but not rx -> tx. "
    "(Also S10: grazing/coplanar segments' line of sight depends on the direction.)"
)


def reciprocity_check(name, kinds, examples=()):
    @SETTINGS
    @given(points(name, kinds), points(name, kinds))
    def check(a, b):
        note(f"a = {a.tolist()!r}, b = {b.tolist()!r}")
        s = SCENES[name]
        p = trace_or_report(s, a, b)
        q = trace_or_report(s, b, a)
        assert (p is None) == (q is None)
        if p is None:
            return
        fwd, bwd = path_table(p), path_table(q, reverse=True)
        assert set(fwd) == set(bwd), (sorted(set(fwd) - set(bwd)), sorted(set(bwd) - set(fwd)))
        cfg = config("V", 3.5e9)
        fa, fb = compute_fields(s, p, cfg).a, compute_fields(s, q, cfg).a
        for key, i in fwd.items():
            j = bwd[key]
            # coefficients that cancel to ~1e-11 of their terms (a soft field grazing a PEC
            # face) keep only an absolute accuracy: 1e-9 of free space over the path length
            scale = max(abs(fa[i]), abs(fb[j]), cfg.wavelength / (4 * np.pi * p.lengths[i]))
            assert abs(fa[i] - fb[j]) <= 1e-9 * scale, key

    for a, b in examples:
        check = example(np.array(a), np.array(b))(check)
    return check


@pytest.mark.parametrize("name", list(SCENES))
def test_random_end_points_are_reciprocal(name):
    """tx -> rx and rx -> tx give mirror-image path sets and, for perfect conductors, equal
    complex coefficients path by path (1e-9 relative, or of the free-space amplitude for
    coefficients that nearly cancel: the same float64 geometry traversed in the other order).
    End points free, or exactly on vertices, edges and faces (the defined cases)."""
    reciprocity_check(name, ON)()


# S11 fixed: sector_of and FindDihedron share one angular resolution (FACE_ANGLE_TOL)
def test_random_end_points_next_to_faces_are_reciprocal():
    """The same with end points also 1e-9 m off the faces (three_face_edge: the awning's
    free edge and the three-face hinge)."""
    found = [([3.999999999, 4.0, 4.0], [4.0, 2.0, 3.999999999])]  # by this search, kept as an example
    reciprocity_check("three_face_edge", NEAR, found)()
