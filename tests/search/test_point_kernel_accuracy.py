"""Accuracy of the closed-form diffraction point kernel (seed §2.3).

:func:`wavepaths.search.geometry.diffraction_point_parameter` is compared with a
straightforward reference written here from the formula

    t = (t_e d_r + t_r d_e) / (d_e + d_r),  t_x = (X - A) . w,  d_x = |(X - A) x w|,

evaluated in ``np.longdouble`` (80-bit on x86-64) with cross-product distances and the
direction renormalised, on random inputs and on near-degenerate ones: end points at
1e-3..1e-12 relative distance from the edge line, both end points near it or on it,
coordinates offset by 1e6 m, very short (1 mm) and very long (10 km) edges.

Tolerance. An error ``eps |v|`` in ``t_e``, ``t_r``, ``d_e``, ``d_r`` moves ``t`` by
about ``eps |v| (1 + |t_r - t_e| / (d_e + d_r))``, so the test asks for

    |t - t_ref| <= K eps S kappa,  S = max(|E - A|, |R - A|),
    kappa = 1 + |t_r - t_e| / (d_e + d_r),

with ``K = 8`` (the kernel reaches ``K`` of about 2.4 on these families, as did the
kernel before its rewrite; the cancelling form ``d^2 = v.v - (v.w)^2`` exceeds it by up
to 1e8 near the line). ``K`` is doubled where ``longdouble`` is only float64.
Keller's law is checked at ``P = A + t w``: the angle of ``P - E`` with ``w`` equals the
angle of ``R - P`` with ``w``, to the residual that the tolerated error in ``t`` allows.
"""

from __future__ import annotations

import numpy as np
import pytest

from wavepaths.search.geometry import diffraction_point_parameter

LD = np.longdouble
EPS = np.finfo(np.float64).eps
K = 8.0 if np.finfo(LD).eps < EPS else 16.0
N = 20_000


def _reference(e, r, origin, direction):
    """(t, S, kappa, P - E, R - P, unit w, d_e, d_r) in longdouble, from the formula with cross products."""
    e, r, a, w = (np.asarray(x, dtype=LD) for x in (e, r, origin, direction))
    w = w / np.sqrt((w * w).sum(-1))[..., None]
    ve, vr = e - a, r - a
    te, tr = (ve * w).sum(-1), (vr * w).sum(-1)
    de = np.sqrt((np.cross(ve, w) ** 2).sum(-1))
    dr = np.sqrt((np.cross(vr, w) ** 2).sum(-1))
    s = de + dr
    ok = s > 0
    t = np.where(ok, (te * dr + tr * de) / np.where(ok, s, 1), (te + tr) / 2)
    S = np.maximum(np.sqrt((ve * ve).sum(-1)), np.sqrt((vr * vr).sum(-1)))
    kappa = 1 + np.abs(tr - te) / np.where(ok, s, np.inf)
    return t, S, kappa, te, tr, de, dr, w


def _unit(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _near_line(rng, origin, w, rho, half_length=20.0):
    """Points ``A + s w + rho |s| u`` (``u`` perpendicular to ``w``): relative distance ``rho``."""
    n = len(origin)
    u = np.cross(w, _unit(rng, n))
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    s = rng.uniform(-half_length, half_length, n)
    return origin + s[:, None] * w + (rho * np.abs(s))[:, None] * u


def _families():
    rng = np.random.default_rng(20240611)
    a = rng.uniform(-10, 10, (N, 3))
    w = _unit(rng, N)
    box = lambda: rng.uniform(-10, 10, (N, 3))  # noqa: E731
    fam = {"random": (box(), box(), a, w)}
    for rho in (1e-3, 1e-6, 1e-9, 1e-12):
        fam[f"E near the line, rho={rho:g}"] = (_near_line(rng, a, w, rho), box(), a, w)
        fam[f"R near the line, rho={rho:g}"] = (box(), _near_line(rng, a, w, rho), a, w)
        fam[f"both near the line, rho={rho:g}"] = (_near_line(rng, a, w, rho), _near_line(rng, a, w, rho), a, w)
    fam["both on the line (to rounding)"] = (_near_line(rng, a, w, 0.0), _near_line(rng, a, w, 0.0), a, w)
    far = a + 1e6
    fam["offset 1e6 m"] = (far + box(), far + box(), far, w)
    fam["offset 1e6 m, E near the line"] = (_near_line(rng, far, w, 1e-9), far + box(), far, w)
    for length in (1e-3, 1e4):  # the edge AB, w from B - A as the scene computes it
        b = a + length * _unit(rng, N)
        ww = (b - a) / np.linalg.norm(b - a, axis=-1, keepdims=True)
        mid = a + 0.5 * length * ww
        fam[f"edge of {length:g} m"] = (mid + box(), mid + box(), a, ww)
    return fam


FAMILIES = _families()


@pytest.mark.parametrize("name", list(FAMILIES))
def test_kernel_matches_longdouble_reference(name):
    e, r, a, w = FAMILIES[name]
    t = diffraction_point_parameter(e, r, a, w)
    assert t.shape == (N,) and t.dtype == np.float64
    assert np.isfinite(t).all()
    t_ref, S, kappa, te, tr, _, _, _ = _reference(e, r, a, w)
    err = np.abs(t.astype(LD) - t_ref)
    bound = K * EPS * S * kappa
    worst = int(np.argmax(err / bound))
    assert (err <= bound).all(), f"{name}: error {float(err[worst]):.3e} m > {float(bound[worst]):.3e} m"
    # the point lies between the two projections (a convex combination of t_e and t_r)
    lo, hi = np.minimum(te, tr), np.maximum(te, tr)
    assert ((t >= lo - 4 * EPS * S) & (t <= hi + 4 * EPS * S)).all()


@pytest.mark.parametrize("name", list(FAMILIES))
def test_keller_equal_angle_law(name):
    """cos(angle(P - E, w)) == cos(angle(R - P, w)) at P = A + t w (the incident and the
    diffracted ray on the same Keller cone), to the residual allowed by the error in t."""
    e, r, a, w = FAMILIES[name]
    t = diffraction_point_parameter(e, r, a, w)
    t_ref, S, kappa, _, _, de, dr, wl = _reference(e, r, a, w)
    # P - E and R - P from the differences of the inputs (exact in longdouble), not from P
    # itself, so that a 1e6 m offset does not cost the reference its digits
    tw = t.astype(LD)[:, None] * wl
    pe = (np.asarray(a, LD) - np.asarray(e, LD)) + tw
    rp = (np.asarray(r, LD) - np.asarray(a, LD)) - tw
    le = np.sqrt((pe * pe).sum(-1))
    lr = np.sqrt((rp * rp).sum(-1))
    ok = (le > 0) & (lr > 0)
    cos_in = (pe * wl).sum(-1)[ok] / le[ok]
    cos_out = (rp * wl).sum(-1)[ok] / lr[ok]
    residual = np.abs(cos_in - cos_out)
    # d cos / dt = d^2 / |P - X|^3 on each leg; the tolerated error in t is K eps S kappa
    allowed = (K * EPS * S * kappa)[ok] * (de[ok] ** 2 / le[ok] ** 3 + dr[ok] ** 2 / lr[ok] ** 3) + 4 * EPS
    assert np.isfinite(residual).all()
    worst = int(np.argmax(residual / allowed))
    assert (residual <= allowed).all(), f"{name}: {float(residual[worst]):.3e} > {float(allowed[worst]):.3e}"
    if name in ("random", "offset 1e6 m", "edge of 0.001 m"):
        # well-conditioned pairs (legs over 1 mm): the two angles agree to 1e-12 rad
        def angle(x):
            return np.arctan2(np.sqrt((np.cross(x, wl[ok]) ** 2).sum(-1)), (x * wl[ok]).sum(-1))

        far = (le[ok] > 1e-3) & (lr[ok] > 1e-3)
        assert np.abs(angle(pe[ok]) - angle(rp[ok]))[far].max() < 1e-12


def test_both_points_exactly_on_the_line_give_the_midpoint():
    a = np.array([[1.0, 2.0, 3.0]] * 4)
    w = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    e = a + np.array([[2.0], [-3.0], [0.5], [4.0]]) * w
    r = a + np.array([[6.0], [5.0], [-1.5], [4.0]]) * w  # the last pair: E == R
    t = diffraction_point_parameter(e, r, a, w)
    assert np.array_equal(t, [4.0, 1.0, -0.5, 4.0])


def test_one_point_on_the_line_gives_its_projection():
    a = np.zeros((2, 3))
    w = np.array([[0.0, 1.0, 0.0]] * 2)
    e = np.array([[0.0, 3.0, 0.0], [0.0, 0.0, 0.0]])  # on the line; the second at A itself
    r = np.array([[5.0, 9.0, 1.0], [2.0, -4.0, 0.0]])
    assert np.array_equal(diffraction_point_parameter(e, r, a, w), [3.0, 0.0])


def test_shapes_broadcasting_and_nan():
    rng = np.random.default_rng(1)
    e, r, a = (rng.uniform(-5, 5, (4, 6, 3)) for _ in range(3))
    w = _unit(rng, 24).reshape(4, 6, 3)
    t = diffraction_point_parameter(e, r, a, w)
    assert t.shape == (4, 6)
    t_ref = _reference(e, r, a, w)[0]
    assert np.allclose(t, t_ref.astype(float), rtol=0, atol=1e-12)
    one = diffraction_point_parameter(e[1, 2], r[1, 2], a[1, 2], w[1, 2])
    assert np.shape(one) == () and one == t[1, 2]
    # one edge for many pairs, and one end point for many edges
    assert np.allclose(diffraction_point_parameter(e, r, a[0, 0], w[0, 0]),
                       _reference(e, r, np.broadcast_to(a[0, 0], e.shape), np.broadcast_to(w[0, 0], e.shape))[0]
                       .astype(float), rtol=0, atol=1e-12)
    assert diffraction_point_parameter(e[0, 0], r, a, w).shape == (4, 6)
    assert diffraction_point_parameter(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), w[0, :0]).shape == (0,)
    # float32 inputs are computed in float64; a NaN row stays NaN and does not spoil the others
    assert diffraction_point_parameter(e.astype(np.float32), r, a, w).dtype == np.float64
    e2 = e.reshape(-1, 3).copy()
    e2[3] = np.nan
    t2 = diffraction_point_parameter(e2, r.reshape(-1, 3), a.reshape(-1, 3), w.reshape(-1, 3))
    assert np.isnan(t2[3]) and np.isfinite(np.delete(t2, 3)).all()
