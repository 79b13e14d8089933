"""Property-based tests (Hypothesis) on the geometric and UTD kernels, each against an
exact identity or an independent float64 reference."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy.special import fresnel

from wavepaths.em.utd import boundary_offsets, diffraction_jones, kp_coefficients, transition_function
from wavepaths.search.geometry import diffraction_point_parameter, mirror_points
from wavepaths.topology.dihedra import Dihedra
from wavepaths.topology.find_dihedron import find_dihedron

SETTINGS = settings(max_examples=150, deadline=None, database=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow])
EPS = np.finfo(float).eps


def floats(lo, hi):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


def vectors(bound):
    return st.tuples(floats(-bound, bound), floats(-bound, bound), floats(-bound, bound)).map(np.array)


units = st.tuples(floats(-1, 1), floats(-1, 1), floats(-1, 1)).filter(lambda v: np.linalg.norm(v) > 1e-3).map(
    lambda v: np.array(v) / np.linalg.norm(v)
)


def line_frame(e, r, origin, w):
    te, tr = (e - origin) @ w, (r - origin) @ w
    de = np.linalg.norm(e - origin - te * w)
    dr = np.linalg.norm(r - origin - tr * w)
    return te, tr, de, dr


# ---- the closed-form diffraction point (seed §2.3) ---------------------------------------------
@SETTINGS
@given(vectors(1e6), vectors(1e6), vectors(1e6), units)
def test_diffraction_point_lies_on_kellers_cone_and_minimises_the_length(e, r, origin, w):
    """Keller's law ``cos(beta_in) = cos(beta_out)`` at the returned point (tolerance 1e-9,
    for end points at least 1e-3 of the coordinate scale from the line: the float64 error of
    t is then ~1e-13 of the scale), and the unfolded length equals ``hypot(t_r - t_e, d_e + d_r)``
    (rel 1e-12): the exact minimum over the line."""
    scale = max(np.abs(e).max(), np.abs(r).max(), np.abs(origin).max(), 1.0)
    te, tr, de, dr = line_frame(e, r, origin, w)
    assume(de > 1e-3 * scale and dr > 1e-3 * scale)
    t = float(diffraction_point_parameter(e, r, origin, w))
    p = origin + t * w
    cos_in = (p - e) @ w / np.linalg.norm(p - e)
    cos_out = (r - p) @ w / np.linalg.norm(r - p)
    assert abs(cos_in - cos_out) <= 1e-9
    length = np.linalg.norm(p - e) + np.linalg.norm(r - p)
    assert abs(length / np.hypot(tr - te, de + dr) - 1) <= 1e-12


@SETTINGS
@given(vectors(1e6), vectors(1e6), vectors(1e6), units, floats(-1e3, 1e3))
def test_diffraction_point_is_reciprocal_and_frame_independent(e, r, origin, w, shift):
    """Swapping E and R gives the bit-identical parameter (the formula is symmetric and IEEE
    + and * commute); reversing the edge or moving its origin along it gives the same point
    (to 1e-12 of the scale per unit of the conditioning 1 / (d_e + d_r))."""
    assert diffraction_point_parameter(e, r, origin, w) == diffraction_point_parameter(r, e, origin, w)
    scale = max(np.abs(e).max(), np.abs(r).max(), np.abs(origin).max(), abs(shift), 1.0)
    te, tr, de, dr = line_frame(e, r, origin, w)
    assume(de + dr > 1e-3 * scale)
    p = origin + float(diffraction_point_parameter(e, r, origin, w)) * w
    o2 = origin + shift * w
    p_rev = o2 + float(diffraction_point_parameter(e, r, o2, -w)) * (-w)
    assert np.abs(p_rev - p).max() <= 1e-10 * scale


@SETTINGS
@given(vectors(1e300), vectors(1e300), vectors(1e300), units, st.sampled_from(["free", "on_line", "same"]))
def test_diffraction_point_is_finite_for_any_finite_input(e, r, origin, w, kind):
    """No NaN or inf for coordinates up to 1e300 m (beyond about 1e154 the squares of the
    distances overflow: those rows are recomputed on coordinates scaled by a power of two),
    including both end points on the edge line and E = R. (A review found NaN from 1e160.)"""
    if kind == "on_line":
        e, r = origin + 0.3 * np.abs(e).max() * w, origin - 0.7 * np.abs(r).max() * w
    elif kind == "same":
        r = e.copy()
    with np.errstate(over="raise", invalid="raise", divide="raise", under="ignore"):
        t = diffraction_point_parameter(e, r, origin, w)
    assert np.isfinite(t)


def normal_floats(bound):
    """Floats of magnitude 0 or between 1e-3 and ``bound``: scaled by 2^-1000 .. 2^1000 they stay
    normal (no input is rounded)."""
    return st.one_of(st.just(0.0), floats(1e-3, bound), floats(-bound, -1e-3))


@SETTINGS
@given(st.tuples(normal_floats(1e3), normal_floats(1e3), normal_floats(1e3)).map(np.array),
       st.tuples(normal_floats(1e3), normal_floats(1e3), normal_floats(1e3)).map(np.array),
       st.tuples(normal_floats(1e3), normal_floats(1e3), normal_floats(1e3)).map(np.array), units,
       st.integers(-1000, 1000))
def test_diffraction_point_scales_exactly_over_the_whole_float64_range(e, r, origin, w, k):
    """The point of the same configuration scaled by 2^k (k from -1000 to 1000: lengths from
    1e-301 to 1e301 m) is the point scaled by 2^k, bit for bit: a power of two scales float64
    exactly, and the rows whose squares would leave the range are recomputed on scaled
    coordinates. (A review found NaN beyond 1e154 and 8 % off at 1e-300, where the squares
    underflow.)"""
    f = 2.0**k
    with np.errstate(under="ignore"):
        got = diffraction_point_parameter(e * f, r * f, origin * f, w)
    assert got == diffraction_point_parameter(e, r, origin, w) * f


@SETTINGS
@given(vectors(1e6), units, floats(-1e6, 1e6))
def test_mirror_is_an_involutive_isometry(x, n, d):
    """Mirroring twice gives the point back, and the mirror image is as far from the plane on
    the other side (32 ulp of the coordinate scale: a few roundings of sums of that size)."""
    scale = max(np.abs(x).max(), abs(d), 1.0)
    m = mirror_points(x, n, np.array(d))
    assert np.abs(mirror_points(m, n, np.array(d)) - x).max() <= 32 * EPS * scale
    assert abs((m @ n - d) + (x @ n - d)) <= 32 * EPS * scale


# ---- FindDihedron (seed §3.3) ----------------------------------------------------------------------
def dihedra_around(w: np.ndarray, face_angles: np.ndarray) -> tuple[Dihedra, np.ndarray, np.ndarray]:
    """One dihedron through the origin along the unit vector ``w``, faces at the given angles."""
    x = np.cross(w, [1.0, 0, 0] if abs(w[0]) < 0.9 else [0, 1.0, 0])
    x /= np.linalg.norm(x)
    y = np.cross(w, x)
    pf = np.cos(face_angles)[:, None] * x + np.sin(face_angles)[:, None] * y
    z = np.zeros(len(face_angles), dtype=np.int64)
    return Dihedra(
        origin=np.zeros((1, 3)), direction=w[None], length=np.ones(1), face_ptr=np.array([0, len(face_angles)]),
        face_triangle=z, face_polygon=np.arange(len(face_angles)), face_direction=pf, face_normal=np.cross(w, pf),
        face_count=np.array([len(face_angles)]), max_sector=np.full(1, 2 * np.pi), diffracting=np.ones(1, bool),
        mesh_edges_ptr=np.arange(2), mesh_edges=np.arange(1), skipped_flat_edges=0,
    ), x, y


angles = floats(0, 2 * np.pi)


@SETTINGS
@given(units, st.lists(angles, min_size=1, max_size=4), angles, angles, floats(-5, 5), floats(-5, 5),
       st.sampled_from(["free", "e_on_face", "e_on_line", "near_faces", "ends_near_faces"]),
       floats(-8.5, -2), floats(-8.5, -2), st.sampled_from([-1.0, 1.0]), st.sampled_from([-1.0, 1.0]))
def test_find_dihedron_is_finite_consistent_and_reciprocal(w, faces, ae, ar, ze, zr, kind, ue, ur, se, sr):
    """For any edge, 1 to 4 faces (possibly within 1e-12 rad of each other) and any end points
    (on a face, on the edge line, or 3e-9 to 1e-2 rad beside a face): finite angles; a valid
    path has 0 <= phi, phi' <= n pi with n pi the gap between the bounding faces; away from the
    faces (1e-9 rad) validity is the independent "same angular sector" test and is symmetric
    in E and R (phi and phi' swap, possibly measured from the other face). A review found the
    ends never nearer a face than 2.5e-3 rad, where a "valid whenever near a face" bug passed:
    ``ends_near_faces`` puts both ends beside faces, on either side."""
    faces = np.array(faces)
    if kind == "near_faces":
        faces = np.concatenate([faces, faces[:1] + 1e-12])
    if kind == "ends_near_faces":
        ae = faces[0] + se * 10.0**ue
        ar = faces[-1] + sr * 10.0**ur
    dih, x, y = dihedra_around(w, faces)
    e = 2 * (np.cos(ae) * x + np.sin(ae) * y) + ze * w
    r = 5 * (np.cos(ar) * x + np.sin(ar) * y) + zr * w
    if kind == "e_on_face":
        e = 2 * (np.cos(faces[0]) * x + np.sin(faces[0]) * y) + ze * w
    if kind == "e_on_line":
        e = ze * w
    with np.errstate(over="raise", invalid="raise", divide="raise", under="ignore"):
        res = find_dihedron(dih, np.array([0]), np.zeros((1, 3)), e[None], r[None])
    for v in (res.phi, res.phi_prime, res.wedge_angle):
        assert np.isfinite(v).all()
    if res.valid[0]:
        assert 0 < res.wedge_angle[0] <= 2 * np.pi + 1e-12
        for ang in (res.phi[0], res.phi_prime[0]):
            assert -1e-9 <= ang <= res.wedge_angle[0] + 1e-9
    if kind in ("free", "near_faces", "ends_near_faces"):
        f = np.mod(faces, 2 * np.pi)
        gap = lambda a: np.min(np.abs((np.mod(a, 2 * np.pi) - f + np.pi) % (2 * np.pi) - np.pi))  # noqa: E731
        assume(gap(ae) > 1e-9 and gap(ar) > 1e-9)
        fs = np.sort(f)
        sector = lambda a: (np.searchsorted(fs, np.mod(a, 2 * np.pi), side="right") - 1) % len(fs)  # noqa: E731
        assert bool(res.valid[0]) == bool(sector(ae) == sector(ar))
        back = find_dihedron(dih, np.array([0]), np.zeros((1, 3)), r[None], e[None])
        assert back.valid[0] == res.valid[0]
        if res.valid[0]:
            assert abs(back.wedge_angle[0] - res.wedge_angle[0]) <= 1e-9
            # the seed's construction takes its angles from cosines: arccos near 0 and pi is
            # exact only to eps / sin(angle), and to sqrt(2 eps) at 0 and pi (the fields
            # recompute phi, phi' with atan2)
            dirs = np.concatenate([f, f + np.pi, [ar]])
            sin_min = min(np.abs(np.sin(ae - dirs)).min(), np.abs(np.sin(ar - dirs[:-1])).min())
            tol = 1e-12 + min(16 * EPS / max(sin_min, 1e-300), 8 * np.sqrt(EPS))
            npi = res.wedge_angle[0]
            same = abs(back.phi[0] - res.phi_prime[0]) + abs(back.phi_prime[0] - res.phi[0])
            mirrored = abs(back.phi[0] - (npi - res.phi_prime[0])) + abs(back.phi_prime[0] - (npi - res.phi[0]))
            assert min(same, mirrored) <= tol


# ---- UTD coefficients --------------------------------------------------------------------------------
BOUNDARIES = ("shadow, phi' + pi", "shadow, phi' - pi", "0-face reflection", "n-face reflection")


@st.composite
def wedge_args(draw):
    """Inputs over the whole documented domain, most of them aimed at a shadow or reflection
    boundary (exactly on it, or 1e-15 to 1e-2 rad off; clipped to the faces), where the
    coefficients' terms diverge and cancel: a review found that uniform draws never came
    within 1e-2 rad of one. L is drawn on a log scale (0 about one time in sixteen), since a
    uniform draw gave L = 0, a zero coefficient, in most examples. Of the 150 examples, 57
    lie within 1e-2 rad of a boundary, 53 of them with L > 0 (/tmp probe, thirtieth session)."""
    n = draw(floats(1.0 + 1e-9, 2.0))
    phi_prime = draw(floats(0, n * np.pi))
    near = draw(st.sampled_from(("anywhere",) + BOUNDARIES))
    if near == "anywhere":
        phi = draw(floats(0, n * np.pi))
    else:
        b = {BOUNDARIES[0]: phi_prime + np.pi, BOUNDARIES[1]: phi_prime - np.pi, BOUNDARIES[2]: np.pi - phi_prime,
             BOUNDARIES[3]: (2 * n - 1) * np.pi - phi_prime}[near]
        scale = draw(floats(-16, -2))  # below -15: exactly on the boundary
        offset = 0.0 if scale < -15 else draw(st.sampled_from([-1.0, 1.0])) * 10.0**scale
        phi = min(max(b + offset, 0.0), n * np.pi)
    e = draw(floats(-7, 9))
    L = 0.0 if e < -6 else 10.0**e
    return dict(n=n, phi=phi, phi_prime=phi_prime, beta_0=draw(floats(0, np.pi)), k=draw(floats(1e-2, 1e6)), L=L)


complex_r = st.tuples(floats(-1, 1), floats(-1, 1)).map(lambda c: complex(*c) / max(1.0, abs(complex(*c))))


@SETTINGS
@given(wedge_args(), st.lists(complex_r, min_size=4, max_size=4), st.sampled_from(["utd", "gtd", "sionna"]))
def test_wedge_coefficients_are_finite_over_their_whole_domain(a, rs, model):
    """Every documented input (0 <= phi, phi' <= n pi, 1 < n <= 2, 0 <= beta_0 <= pi,
    k > 0, L >= 0 up to 1e9 m, |R| <= 1): a finite Jones matrix, no floating-point warning."""
    with np.errstate(over="raise", invalid="raise", divide="raise", under="ignore"):
        J = diffraction_jones(a["phi"], a["phi_prime"], a["beta_0"], a["n"], a["k"], a["L"], model, *rs)
    assert np.isfinite(J).all()
    off = boundary_offsets(a["phi"], a["phi_prime"], a["n"])
    for eps in off:
        assert abs(eps) <= a["n"] * np.pi * (1 + 1e-12)


@SETTINGS
@given(wedge_args())
def test_kp_coefficient_is_reciprocal(a):
    """Kouyoumjian-Pathak is symmetric in phi <-> phi' (reciprocity): D(phi, phi') = D(phi', phi)
    to rounding (1e-12 relative, plus 1e-300 for exact zeros)."""
    d1 = kp_coefficients(a["phi"], a["phi_prime"], a["beta_0"], a["n"], a["k"], a["L"])
    d2 = kp_coefficients(a["phi_prime"], a["phi"], a["beta_0"], a["n"], a["k"], a["L"])
    for x, y in zip(d1, d2):
        assert abs(x - y) <= 1e-12 * max(abs(x), abs(y)) + 1e-300


@SETTINGS
@given(floats(1.05, 2.0), floats(0.05, 1.0), st.sampled_from([1, 2, 3, 4]), floats(0.05, np.pi - 0.05),
       floats(-2, 4), floats(0.1, 100.0), st.sampled_from(["soft", "hard"]))
def test_utd_jump_across_each_boundary_cancels_the_geometrical_optics_jump(n, frac, which, beta_0, log_kl, L, pol):
    """Across each shadow or reflection boundary (1e-10 rad either side, phi increasing) the
    coefficient jumps by ``sqrt(L) / sin(beta_0)`` times minus the jump of the GO field there,
    which makes the total field continuous (KP 1974). Going up in phi, the GO field gains the
    incident wave at ``phi' - pi`` (jump +1, so z = -1), loses it at ``phi' + pi`` (z = +1),
    gains the n-face reflection at ``(2n - 1) pi - phi'`` (z = -R) and loses the 0-face one at
    ``pi - phi'`` (z = +R), with R = -1 soft and +1 hard on a perfect conductor. Tolerance 1e-6
    (the smooth part moves by ~1e-10 sqrt(kL))."""
    npi = n * np.pi
    phi_p = frac * npi
    phi_b = {1: phi_p - np.pi, 2: phi_p + np.pi, 3: (2 * n - 1) * np.pi - phi_p, 4: np.pi - phi_p}[which]
    others = [phi_p - np.pi, phi_p + np.pi, (2 * n - 1) * np.pi - phi_p, np.pi - phi_p]
    others.remove(phi_b)
    assume(0.02 < phi_b < npi - 0.02 and min(abs(phi_b - o) for o in others) > 0.02)
    k = 10.0**log_kl / L
    d = 1e-10
    lo = kp_coefficients(phi_b - d, phi_p, beta_0, n, k, L)
    hi = kp_coefficients(phi_b + d, phi_p, beta_0, n, k, L)
    i = 0 if pol == "soft" else 1
    z = (hi[i] - lo[i]) * np.sin(beta_0) / np.sqrt(L)
    r = -1.0 if pol == "soft" else 1.0
    expected = {1: -1.0, 2: 1.0, 3: -r, 4: r}[which]
    assert abs(z - expected) <= 1e-6, (z, expected)


@SETTINGS
@given(floats(-8, 3))
def test_transition_function_matches_the_fresnel_integrals(log_x):
    """KP's F(x) = 2j sqrt(x) e^{jx} int_sqrt(x)^inf e^{-j t^2} dt, from scipy's Fresnel
    integrals C, S (an independent float64 path): int_u^inf e^{-j t^2} dt =
    sqrt(pi/2) [(1/2 - C(v)) - j (1/2 - S(v))], v = u sqrt(2/pi). Tolerance 1e-9 relative."""
    x = 10.0**log_x
    s, c = fresnel(np.sqrt(2 * x / np.pi))
    ref = 2j * np.sqrt(x) * np.exp(1j * x) * np.sqrt(np.pi / 2) * ((0.5 - c) - 1j * (0.5 - s))
    assert abs(transition_function(x) / ref - 1) <= 1e-9


@SETTINGS
@given(st.one_of(floats(0, 1e308), st.just(0.0), st.just(100.0), floats(100 * (1 - 1e-9), 100 * (1 + 1e-9))))
def test_transition_function_is_finite_bounded_and_continuous(x):
    """Finite for every x >= 0, |F| < 1 (it tends to 1 from below, |F|^2 ~ 1 - 5 / (4 x^2)), and seamless
    where the implementation switches from the Faddeeva form to the asymptotic series (100):
    within 1e-13 of 1 + j / (2x) - 3 / (4x^2) from 1e7 on, and within 2e-14 across the switch."""
    f = complex(transition_function(x))
    assert np.isfinite(f) and abs(f) <= 1 + 1e-12
    if x >= 1e7:
        assert abs(f - (1 + 0.5j / x - 0.75 / x / x)) <= 1e-13
    if 100 * (1 - 1e-9) <= x <= 100 * (1 + 1e-9):
        # |F'(x)| ~ 1 / (2 x^2) = 5e-5 here: beyond that slope, the two forms differ by rounding
        assert abs(f - complex(transition_function(100.0))) <= 1e-4 * abs(x - 100) + 2e-14


S11 = (
    "BUG S11: FindDihedron decides with cosines (u_e . P_f, u_e . u_r), which round to 1 within "
    "~1.5e-8 rad of a face: end points 1e-9 rad from the face of a free edge are rejected (wrapping "
    "around the edge) or accepted one way only (same side), though sector_of (atan2, tolerance "
    "1e-12 rad) passes them as sources"
)


@pytest.mark.parametrize(
    "delta", [1e-4, 1e-6, 1e-8] + [pytest.param(d, marks=()) for d in (1e-9, 1e-10)]
)
@pytest.mark.parametrize("layout", ["around_the_edge", "same_side"])
def test_find_dihedron_resolves_directions_next_to_a_face(delta, layout):
    """A free edge (one face at angle 0, a half-plane): E at +delta from the face and R at
    -delta (on the other side, around the edge) or at +2 delta (same side) lie in its single
    2 pi sector, so the path is valid both ways round, as the independent sector test says."""
    dih, x, y = dihedra_around(np.array([0.0, 0.0, 1.0]), np.array([0.0]))
    ar = -delta if layout == "around_the_edge" else 2 * delta
    e = 2 * (np.cos(delta) * x + np.sin(delta) * y) + 0.3 * np.array([0, 0, 1.0])
    r = 5 * (np.cos(ar) * x + np.sin(ar) * y) - 0.2 * np.array([0, 0, 1.0])
    zero = np.zeros((1, 3))
    assert find_dihedron(dih, np.array([0]), zero, e[None], r[None]).valid[0]
    assert find_dihedron(dih, np.array([0]), zero, r[None], e[None]).valid[0]
