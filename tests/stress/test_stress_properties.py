"""Property-based tests (Hypothesis) on whole traces: random end points, including points
snapped onto vertices, edges and faces of the scene, must give paths that obey the laws at
every vertex, finite fields, and reciprocal paths and coefficients.

An example without paths checks nothing, so the strategies draw end points where the engine
computes paths (distinct, outside the solid blocks, a free end in view of a snapped one), and
each test counts its examples (Tally) and requires that most of them found and checked paths,
many with an end point on the scene."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, note, settings
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
SNAPPED = ("vertex", "edge", "face", "near_face")


def _solid_boxes(scene) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """{object: (lo, hi)} of the scene's solid objects (these scenes' solids are axis-aligned
    boxes: every vertex of one lies on its bounding box's faces)."""
    out = {}
    for o in np.unique(scene.polygon_object[scene.outward_sign != 0]):
        lo, hi = scene.object_boxes[0][o], scene.object_boxes[1][o]
        v = scene.vertices[np.unique(scene.triangles[scene.triangle_object == o])]
        assert ((v == lo) | (v == hi)).all(), "the solids of these scenes are boxes"
        out[int(o)] = (lo, hi)
    return out


ON_BOX = 1e-8  # m: a point this close to a block's face (snapped, or 1e-9 m off it) is on it


def outer_side(name, p, q) -> np.ndarray:
    """``q`` mirrored in the planes of the faces of the first solid block whose surface holds
    ``p`` that have ``q`` on their inner side: from there ``q`` sees ``p`` from outside the block
    (if nothing else is in the way); ``q`` itself if ``p`` lies on no block or the mirror image
    falls inside one."""
    for lo, hi in OBJECT_BOX[name].values():
        if np.all((lo - ON_BOX <= p) & (p <= hi + ON_BOX)) and not np.all((lo + ON_BOX < p) & (p < hi - ON_BOX)):
            m = q.copy()
            for k in range(3):
                for bound, sign in ((lo[k], -1.0), (hi[k], 1.0)):
                    if abs(p[k] - bound) <= ON_BOX and sign * (m[k] - bound) < 0:
                        m[k] = 2 * bound - m[k]
            return q if inside_solid(name, m) else m
    return q


def _seen_triangles(name) -> np.ndarray:
    """Triangles of the scene whose outer side reaches into the sampling box: both sides of a
    sheet, the outward side of a solid's face (not the blocks' bottoms at z = 0, below the
    box: a point there sees only the inside of its block, so it can have no path)."""
    s = SCENES[name]
    lo, hi = BOX[name]
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    q = s.triangle_polygon
    out = s.polygon_normal[q] * s.outward_sign[q][:, None]
    first = s.vertices[s.triangles[:, 0]]
    reach = (np.einsum("tk,ck->tc", out, corners) - np.einsum("tk,tk->t", out, first)[:, None]).max(axis=1)
    return np.nonzero((s.outward_sign[q] == 0) | (reach > 0))[0]


OBJECT_BOX = {name: _solid_boxes(s) for name, s in SCENES.items()}
SEEN = {name: _seen_triangles(name) for name in SCENES}


def inside_solid(name, p) -> bool:
    """Strictly inside one of the scene's solid blocks (where trace reports the end point)."""
    return any(bool(np.all((lo < p) & (p < hi))) for lo, hi in OBJECT_BOX[name].values())


def _point(draw, name, kind, outside):
    """A point of one ``kind``; see :func:`points`."""
    s = SCENES[name]
    lo, hi = BOX[name]
    u = np.array([draw(st.floats(0, 1)) for _ in range(3)])
    if kind == "free":
        p = lo + u * (hi - lo)
        if outside and inside_solid(name, p):  # the blocks fill 5 to 11 % of the box: take the mirror image
            p = lo + (1 - u) * (hi - lo)
            assume(not inside_solid(name, p))
        return p
    choice = SEEN[name] if outside else np.arange(s.num_triangles)
    t = int(choice[draw(st.integers(0, len(choice) - 1))])
    tri = s.vertices[s.triangles[t]]
    if kind == "vertex":
        return tri[int(3 * u[0]) % 3]
    if kind == "edge":
        return tri[0] + u[0] * (tri[1] - tri[0])
    a, b = sorted(u[:2])
    p = tri[0] * a + tri[1] * (b - a) + tri[2] * (1 - b)
    if kind == "near_face":
        q = s.triangle_polygon[t]
        side = draw(st.sampled_from([-1.0, 1.0]))
        if outside and s.outward_sign[q] != 0:  # inside the block, trace would report the point
            side = float(s.outward_sign[q])
        p = p + 1e-9 * side * s.polygon_normal[q]
    return p


@st.composite
def points(draw, name, kinds=NEAR, outside=False):
    """A free point in the scene's box, or a point snapped onto one of its vertices, edges or
    triangles (the defined edge cases), or 1e-9 m off a triangle.

    ``outside``: only points where the engine computes paths: a free point not inside a solid
    block, a snapped one on a triangle the box sees (:func:`_seen_triangles`), a near-face point
    on the outer side of a solid's face (inside the block, trace reports it)."""
    return _point(draw, name, draw(st.sampled_from(kinds)), outside)


@st.composite
def point_of_kind(draw, name, kind, outside=False):
    """A point of one ``kind`` (see :func:`points`)."""
    return _point(draw, name, kind, outside)


# The kinds of the two ends of a pair: "snap" is one of the snapped kinds of the test, and a
# free end paired with a snapped one sees the face it was snapped to (end_points); two snapped
# ends rarely see each other, and both free give no edge case; "specular" are two free points
# placed for a reflection on a face (free points in these scenes without a ground rarely see
# one face both). Each test counts what its examples checked (Tally).
PAIRS = (("free", "free"), ("snap", "free"), ("free", "snap"), ("specular", "specular"),
         ("snap", "free"), ("free", "snap"), ("specular", "specular"), ("snap", "snap"))
GAP = 0.1  # m between the ends: trace refuses coincident ones, compute_fields warns of paths under a wavelength
MIN_CHECKED = 0.6  # of the examples of a test must find paths and check them
MIN_SNAPPED = 25  # of them, with an end point snapped onto (or next to) the scene
# (35 to 80 measured: Hypothesis draws literal constants from the modules imported before the
# test as interesting values, so the examples, and these counts, depend on what else ran
# first; derandomize fixes them for one set of imports only)


def _specular_pair(draw, name):
    """Two points outside the solids, 0.5 to 8 m from a point ``r`` inside a triangle the box sees,
    on its outer side (either side of a sheet), along directions mirror images of each other in
    its plane: a reflection on it at ``r`` unless something is in the way."""
    s = SCENES[name]
    t = int(SEEN[name][draw(st.integers(0, len(SEEN[name]) - 1))])
    tri = s.vertices[s.triangles[t]]
    w = np.array([0.05 + draw(st.floats(0, 1)) for _ in range(3)])  # inside: edges and vertices are the
    r = (w / w.sum()) @ tri  # snapped kinds' business (with r on one, b lies on a reflection boundary)
    q = s.triangle_polygon[t]
    n = s.polygon_normal[q] * (s.outward_sign[q] or draw(st.sampled_from([-1.0, 1.0])))
    e1 = np.cross(n, [0.3, 0.5, 0.8] if abs(n[2]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    cos_t, phi = 0.1 + 0.9 * draw(st.floats(0, 1)), 2 * np.pi * draw(st.floats(0, 1))
    u = cos_t * n + np.sqrt(1 - cos_t**2) * (np.cos(phi) * e1 + np.sin(phi) * e2)
    ends = [r + (0.5 + 7.5 * draw(st.floats(0, 1))) * d for d in (u, 2 * (u @ n) * n - u)]
    assume(not any(inside_solid(name, p) for p in ends))
    return ends


@st.composite
def end_points(draw, name, kinds=NEAR):
    """(a, b, label): two end points at least GAP apart where the engine computes paths
    (``outside``), ``label`` their kinds, e.g. "edge/free" (see PAIRS); the snapped kinds are
    those of ``kinds``. A free end paired with a snapped one on a solid block is put on the outer
    side of the block's faces that hold the snapped end (:func:`outer_side`, unless that lands
    in a block): from behind them it could see the snapped end only around the block."""
    snaps = tuple(k for k in kinds if k != "free")
    pattern = draw(st.sampled_from(PAIRS))
    if pattern[0] == "specular":
        a, b = _specular_pair(draw, name)
        assume(np.linalg.norm(a - b) > GAP)
        return a, b, "specular/specular"
    kind = [k if k == "free" else draw(st.sampled_from(snaps)) for k in pattern]
    ends = [None, None]
    for n, i in enumerate(sorted(range(2), key=lambda i: kind[i] == "free")):  # snapped ends first
        for _ in range(3):  # as Hypothesis' filter: a few tries, then the example is dropped
            p = _point(draw, name, kind[i], True)
            if n == 1 and kind[i] == "free":
                p = outer_side(name, ends[1 - i], p)
            if n == 0 or np.linalg.norm(p - ends[1 - i]) > GAP:
                break
        else:
            assume(False)
        ends[i] = p
    return ends[0], ends[1], "/".join(kind)


class Tally:
    """What the examples of one Hypothesis test did: each records its label and outcome
    ("checked": paths were found and checked; "no paths"; "refused": trace reported the case),
    and :meth:`require` asserts that enough of them checked something."""

    def __init__(self):
        self.rows = []

    def __call__(self, label, outcome):
        self.rows.append((label, outcome))

    def count(self, outcome="checked", snapped=None) -> int:
        return sum(1 for label, o in self.rows if o == outcome
                   and (snapped is None or snapped == any(k in SNAPPED for k in label.split("/"))))

    def require(self, fraction, snapped):
        """At least ``fraction`` of the examples checked paths, and ``snapped`` examples with an
        end point on (or next to) the scene did."""
        summary = {o: self.count(o) for o in ("checked", "no paths", "refused")}
        detail = f"{summary} of {len(self.rows)}, checked with a snapped end: {self.count(snapped=True)}"
        assert self.rows and self.count() >= fraction * len(self.rows), f"too few examples checked paths: {detail}"
        assert self.count(snapped=True) >= snapped, f"too few examples with a snapped end checked paths: {detail}"


def trace_or_report(scene, a, b):
    """Paths, or None when the engine reports the case (same position, point inside a block)."""
    return reported(lambda: trace(scene, a[None], b[None], OPTS), allow_on_face=True)


@pytest.mark.parametrize("name", list(SCENES))
def test_random_end_points_obey_the_laws_and_give_finite_fields(name):
    tally = Tally()

    @SETTINGS
    @given(end_points(name))
    def check(ends):
        a, b, label = ends
        note(f"{label}: a = {a.tolist()!r}, b = {b.tolist()!r}")
        s = SCENES[name]
        p = trace_or_report(s, a, b)
        if p is None or len(p) == 0:
            tally(label, "refused" if p is None else "no paths")
            return
        assert np.isfinite(p.vertices).all()
        check_laws(s, p, tol=1e-9)
        f = compute_fields(s, p, config("V", 3.5e9))
        assert np.isfinite(f.a).all()
        path_table(p)  # no path twice
        tally(label, "checked")

    check()
    tally.require(MIN_CHECKED, MIN_SNAPPED)


S11 = (
    "BUG S11: FindDihedron decides with cosines (u_e . P_f, u_e . u_r); within ~1.5e-8 rad of a face "
    "they round to 1 and the decision becomes arbitrary and asymmetric, while sector_of (atan2, "
    "tolerance 1e-12 rad) lets such sources through: e.g. three_face_edge, a = (3.999999999, 4, 4), "
    "b = (4, 2, 3.999999999) diffract on the awning's free edge tx -> rx but not rx -> tx. "
    "(Also S10: grazing/coplanar segments' line of sight depends on the direction.)"
)


def reciprocity_check(name, kinds, examples=()):
    """Run the reciprocity search; return its :class:`Tally`."""
    tally = Tally()

    @SETTINGS
    @given(end_points(name, kinds))
    def check(ends):
        a, b, label = ends
        note(f"{label}: a = {a.tolist()!r}, b = {b.tolist()!r}")
        s = SCENES[name]
        p = trace_or_report(s, a, b)
        q = trace_or_report(s, b, a)
        assert (p is None) == (q is None)
        if p is None:
            tally(label, "refused")
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
        tally(label, "checked" if fwd else "no paths")

    for a, b in examples:
        check = example((np.array(a), np.array(b), "example"))(check)
    check()
    return tally


@pytest.mark.parametrize("name", list(SCENES))
def test_random_end_points_are_reciprocal(name):
    """tx -> rx and rx -> tx give mirror-image path sets and, for perfect conductors, equal
    complex coefficients path by path (1e-9 relative, or of the free-space amplitude for
    coefficients that nearly cancel: the same float64 geometry traversed in the other order).
    End points free, or exactly on vertices, edges and faces (the defined cases)."""
    reciprocity_check(name, ON).require(MIN_CHECKED, MIN_SNAPPED)


# S11 fixed: sector_of and FindDihedron share one angular resolution (FACE_ANGLE_TOL)
def test_random_end_points_next_to_faces_are_reciprocal():
    """The same with end points also 1e-9 m off the faces (three_face_edge: the awning's
    free edge and the three-face hinge)."""
    found = [([3.999999999, 4.0, 4.0], [4.0, 2.0, 3.999999999]),  # by this search, kept as examples
             # 1e-9 m off a face beside its edge: the diffraction on that edge was not reciprocal
             ([0.0, 4.000000001, 2.0], [10.0, 7.0, 0.5]), ([4.0, 2.0, 4.000000001], [-3.0, -3.0, 7.5])]
    reciprocity_check("three_face_edge", NEAR, found).require(MIN_CHECKED, MIN_SNAPPED)
