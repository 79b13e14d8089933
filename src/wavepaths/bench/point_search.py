"""Benchmark 1: the seed's micro-benchmark of the diffraction point search (seed §4, fig. 7).

The seed took 10,000 random pairs of points E, R and an edge, solved each 1,000 times,
and found its closed form (§2.3) 2.6-5.8x faster than the numerical search it replaced,
at under 1.15 us per point on an SGI Origin 200 (R10000, 1999).

Here both searches run on numpy arrays of all the pairs at once, so that the ratio
compares algorithms rather than Python loops:

* **closed form**: the seed's formula from the 3-D points E, R, A and w,
  :func:`wavepaths.search.geometry.diffraction_point_parameter`, followed by the
  on-edge test ``0 <= t <= |AB|``. This is the kernel as the seed timed it (projections
  and distances of both end points for every pair). The engine's diffraction search
  (:mod:`wavepaths.search.tile`) no longer calls it: it evaluates the same formula from
  the reduced coordinates ``(t, d)`` of each end point, computed once per (end point,
  dihedron) and shared by all the pairs that use them, so its cost per candidate is the
  last step of this kernel only;
* **engine step** (``engine_candidate_ns``): that last step as the engine runs it,
  :func:`wavepaths.search.geometry.diffraction_point_reduced` and the on-edge test on the
  pairs' precomputed ``t_e, d_e, t_r, d_r`` (the projections are not timed: the engine
  pays them once per end point and edge, not per pair);
* **numerical**, the approach the seed replaced: the point of the edge segment AB that
  minimises the path length ``L(t) = |P(t) - E| + |P(t) - R|``, ``P(t) = A + t w``.
  ``L`` is convex, so three variants are timed:

  - ``golden``: golden-section search on ``L`` over ``[0, |AB|]`` (the textbook
    minimisation; it cannot locate the minimum better than about ``sqrt(eps)`` of the
    scale because ``L`` is flat there, which the accuracy figures show);
  - ``newton``: Newton's method on ``dL/dt = 0`` safeguarded by bisection on
    ``[0, |AB|]``, evaluating distances and derivatives in 3-D at each iterate (the
    seed's "distance and its first derivative expressed with the parametric coordinates
    of P");
  - ``newton_reduced``: the same iteration after reducing each pair to the four scalars
    ``t_e, d_e, t_r, d_r`` (the projections the closed form also computes), the fastest
    numerical variant we found.

  A pair leaves the Newton iteration when its step falls below ``tol`` (1e-11 m; the
  arrays are compacted); a pair whose derivative has the same sign at both ends of the
  segment has no diffraction point on the edge (the numerical search's own on-edge
  test).

The speed-up reported as ``point_search_speedup`` is against the fastest numerical
variant. Each method is timed on the same arrays, in interleaved rounds (``rounds``
rounds of ``repeats / rounds`` calls each); the figure is the median over rounds of the
time per call divided by the number of pairs. The per-call scalar cost (one pair per
call, numpy and pure Python) is reported for context.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..search.geometry import diffraction_point_parameter, diffraction_point_reduced
from .timing import interleaved

SEED_NS_PER_POINT = 1150.0  # seed §4: "less than 1.15 us" per solution (SGI Origin 200, R10000)
SEED_SPEEDUP = (2.6, 5.8)  # seed §4, fig. 7
GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


@dataclass(frozen=True)
class EdgeInstances:
    """Random point pairs and edges.

    Attributes
    ----------
    e, r : (n, 3) float64 [m]
        End points.
    origin : (n, 3) float64 [m]
        Edge start A.
    direction : (n, 3) float64
        Unit edge vector w = (B - A) / |B - A|.
    length : (n,) float64 [m]
        |B - A|.
    """

    e: np.ndarray
    r: np.ndarray
    origin: np.ndarray
    direction: np.ndarray
    length: np.ndarray

    def __len__(self) -> int:
        return len(self.length)


def random_instances(n: int, seed: int = 0, box: float = 10.0) -> EdgeInstances:
    """``n`` pairs E, R and edges AB with all four points uniform in ``[-box, box]^3`` [m].

    About 72 % of the pairs have their diffraction point on the segment (0.724 of 10,000 in
    the benchmark's draw); the others test the on-edge rejection.
    """
    rng = np.random.default_rng(seed)
    e, r, a, b = (rng.uniform(-box, box, (n, 3)) for _ in range(4))
    ab = b - a
    length = np.linalg.norm(ab, axis=1)
    return EdgeInstances(e, r, a, ab / length[:, None], length)


# ---- closed form -------------------------------------------------------------------------
def closed_form(inst: EdgeInstances) -> tuple[np.ndarray, np.ndarray]:
    """(t, on_edge): the closed-form point from 3-D points (seed §2.3) and the on-edge test."""
    t = diffraction_point_parameter(inst.e, inst.r, inst.origin, inst.direction)
    return t, (t >= 0.0) & (t <= inst.length)


@dataclass(frozen=True)
class ReducedInstances:
    """The pairs' reduced coordinates, as the engine holds them (computed once per end and edge)."""

    te: np.ndarray
    de: np.ndarray
    tr: np.ndarray
    dr: np.ndarray
    length: np.ndarray


def reduce_instances(inst: EdgeInstances) -> ReducedInstances:
    """``t_e, d_e, t_r, d_r`` of every pair (not timed: the engine amortises them)."""
    def proj(p):
        v = p - inst.origin
        t = np.einsum("ij,ij->i", v, inst.direction)
        return t, np.linalg.norm(v - t[:, None] * inst.direction, axis=1)

    te, de = proj(inst.e)
    tr, dr = proj(inst.r)
    return ReducedInstances(te, de, tr, dr, inst.length)


def engine_step(red: ReducedInstances) -> tuple[np.ndarray, np.ndarray]:
    """(t, on_edge): the engine's per-candidate step, the closed form from reduced coordinates
    (:func:`wavepaths.search.geometry.diffraction_point_reduced`) and the on-edge test."""
    t = diffraction_point_reduced(red.te, red.de, red.tr, red.dr)
    return t, (t >= 0.0) & (t <= red.length)


def closed_form_scalar(e, r, a, w, length) -> tuple[float, bool]:
    """The same closed form for one pair, in pure Python (``math``), for the per-call figure."""
    vex, vey, vez = e[0] - a[0], e[1] - a[1], e[2] - a[2]
    vrx, vry, vrz = r[0] - a[0], r[1] - a[1], r[2] - a[2]
    te = vex * w[0] + vey * w[1] + vez * w[2]
    tr = vrx * w[0] + vry * w[1] + vrz * w[2]
    if (te < 0.0 and tr < 0.0) or (te > length and tr > length):  # the seed's early exit
        return 0.5 * (te + tr), False
    de = math.sqrt(max(vex * vex + vey * vey + vez * vez - te * te, 0.0))
    dr = math.sqrt(max(vrx * vrx + vry * vry + vrz * vrz - tr * tr, 0.0))
    s = de + dr
    t = (te * dr + tr * de) / s if s > 0 else 0.5 * (te + tr)
    return t, 0.0 <= t <= length


# ---- numerical searches ------------------------------------------------------------------
def _path_length(inst: EdgeInstances, t: np.ndarray, idx=slice(None)) -> np.ndarray:
    p = inst.origin[idx] + t[:, None] * inst.direction[idx]
    return np.linalg.norm(p - inst.e[idx], axis=1) + np.linalg.norm(p - inst.r[idx], axis=1)


def _slope_3d(inst: EdgeInstances, t: np.ndarray, idx=slice(None)) -> tuple[np.ndarray, np.ndarray]:
    """dL/dt and d2L/dt2 at ``t``, from the 3-D vectors P(t) - E and P(t) - R (rows ``idx``)."""
    w = inst.direction[idx]
    p = inst.origin[idx] + t[:, None] * w
    ue = p - inst.e[idx]
    ur = p - inst.r[idx]
    le = np.sqrt(np.einsum("ij,ij->i", ue, ue))
    lr = np.sqrt(np.einsum("ij,ij->i", ur, ur))
    ce = np.einsum("ij,ij->i", ue, w) / le
    cr = np.einsum("ij,ij->i", ur, w) / lr
    return ce + cr, (1.0 - ce * ce) / le + (1.0 - cr * cr) / lr


def golden_section(inst: EdgeInstances, tol: float = 1e-11, max_iter: int = 200) -> tuple[np.ndarray, np.ndarray, int]:
    """(t, on_edge, iterations): golden-section minimisation of ``L`` on ``[0, |AB|]``.

    ``on_edge`` comes from the sign of ``dL/dt`` at the two ends of the segment (a
    stationary point inside it exists when the slope goes from negative to positive).
    The bracket shrinks by the golden ratio per step until it is ``tol`` wide for every
    pair (about 60 steps for a 20 m edge).
    """
    lo = np.zeros(len(inst))
    hi = inst.length.copy()
    on = (_slope_3d(inst, lo)[0] < 0.0) & (_slope_3d(inst, hi)[0] > 0.0)
    x1 = hi - GOLDEN * (hi - lo)
    x2 = lo + GOLDEN * (hi - lo)
    f1 = _path_length(inst, x1)
    f2 = _path_length(inst, x2)
    it = 0
    while it < max_iter and (hi - lo).max() > tol:
        it += 1
        left = f1 < f2  # the minimum lies in [lo, x2]
        hi = np.where(left, x2, hi)
        lo = np.where(left, lo, x1)
        x_new = np.where(left, hi - GOLDEN * (hi - lo), lo + GOLDEN * (hi - lo))
        f_new = _path_length(inst, x_new)
        x1, f1, x2, f2 = (np.where(left, x_new, x2), np.where(left, f_new, f2),
                          np.where(left, x1, x_new), np.where(left, f1, f_new))
    return 0.5 * (lo + hi), on, it


def _safeguarded_newton(slope, lo, hi, t0, tol: float, max_iter: int):
    """Newton on ``slope(t, idx) = 0`` kept inside ``[lo, hi]`` by bisection, vectorised.

    Pairs leave the iteration as soon as their own step falls below ``tol`` (the arrays are
    compacted), so a few slow pairs (an end point almost on the edge line, where ``L`` has
    a kink and bisection takes over) do not hold the others back.
    """
    g_lo, _ = slope(lo, slice(None))
    g_hi, _ = slope(hi, slice(None))
    on = (g_lo < 0.0) & (g_hi > 0.0)
    t = np.where(on, np.clip(t0, lo, hi), np.where(g_lo >= 0.0, lo, hi))
    idx = np.nonzero(on)[0]
    lo_a, hi_a, t_a = lo[idx], hi[idx], t[idx]
    it = 0
    while it < max_iter and len(idx):
        it += 1
        g, h = slope(t_a, idx)
        lo_a = np.where(g < 0.0, t_a, lo_a)
        hi_a = np.where(g > 0.0, t_a, hi_a)
        new = t_a - g / np.where(h > 0.0, h, 1.0)
        bad = (h <= 0.0) | (new <= lo_a) | (new >= hi_a)
        new = np.where(bad, 0.5 * (lo_a + hi_a), new)
        going = np.abs(new - t_a) > tol
        t[idx] = new
        idx, lo_a, hi_a, t_a = idx[going], lo_a[going], hi_a[going], new[going]
    return t, on, it


def newton_3d(inst: EdgeInstances, tol: float = 1e-11, max_iter: int = 100) -> tuple[np.ndarray, np.ndarray, int]:
    """(t, on_edge, iterations): safeguarded Newton on dL/dt, distances evaluated in 3-D.

    Starts from the middle of the segment.
    """
    lo = np.zeros(len(inst))
    return _safeguarded_newton(lambda t, idx: _slope_3d(inst, t, idx), lo, inst.length, 0.5 * inst.length,
                               tol, max_iter)


def newton_reduced(inst: EdgeInstances, tol: float = 1e-11, max_iter: int = 100) -> tuple[np.ndarray, np.ndarray, int]:
    """(t, on_edge, iterations): the same iteration on the projected scalars.

    ``L(t) = sqrt((t - t_e)^2 + d_e^2) + sqrt((t - t_r)^2 + d_r^2)``, started from the
    middle of the two projections (the point lies between them, seed §2.3).
    """
    ve = inst.e - inst.origin
    vr = inst.r - inst.origin
    te = np.einsum("ij,ij->i", ve, inst.direction)
    tr = np.einsum("ij,ij->i", vr, inst.direction)
    de2 = np.maximum(np.einsum("ij,ij->i", ve, ve) - te * te, 0.0)
    dr2 = np.maximum(np.einsum("ij,ij->i", vr, vr) - tr * tr, 0.0)

    def slope(t, idx):
        xe = t - te[idx]
        xr = t - tr[idx]
        a = de2[idx]
        b = dr2[idx]
        le = np.sqrt(xe * xe + a)
        lr = np.sqrt(xr * xr + b)
        return xe / le + xr / lr, a / (le * le * le) + b / (lr * lr * lr)

    return _safeguarded_newton(slope, np.zeros(len(inst)), inst.length, 0.5 * (te + tr), tol, max_iter)


def newton_scalar(e, r, a, w, length, tol: float = 1e-11, max_iter: int = 100) -> tuple[float, bool]:
    """The reduced Newton search for one pair in pure Python (per-call figure)."""
    vex, vey, vez = e[0] - a[0], e[1] - a[1], e[2] - a[2]
    vrx, vry, vrz = r[0] - a[0], r[1] - a[1], r[2] - a[2]
    te = vex * w[0] + vey * w[1] + vez * w[2]
    tr = vrx * w[0] + vry * w[1] + vrz * w[2]
    de2 = max(vex * vex + vey * vey + vez * vez - te * te, 0.0)
    dr2 = max(vrx * vrx + vry * vry + vrz * vrz - tr * tr, 0.0)

    def slope(t):
        le = math.sqrt((t - te) ** 2 + de2)
        lr = math.sqrt((t - tr) ** 2 + dr2)
        return (t - te) / le + (t - tr) / lr, de2 / le**3 + dr2 / lr**3

    lo, hi = 0.0, length
    if slope(lo)[0] >= 0.0 or slope(hi)[0] <= 0.0:
        return (lo if slope(lo)[0] >= 0.0 else hi), False
    t = 0.5 * (lo + hi)
    for _ in range(max_iter):
        g, h = slope(t)
        if g < 0:
            lo = t
        elif g > 0:
            hi = t
        new = t - g / h if h > 0 else 0.5 * (lo + hi)
        if not lo < new < hi:
            new = 0.5 * (lo + hi)
        done = abs(new - t) <= tol
        t = new
        if done:
            break
    return t, True


NUMERICAL = {"golden": golden_section, "newton": newton_3d, "newton_reduced": newton_reduced}


# ---- the benchmark -----------------------------------------------------------------------
def _agreement(inst: EdgeInstances, t_ref: np.ndarray, on_ref: np.ndarray, t: np.ndarray, on: np.ndarray) -> dict:
    both = on_ref & on
    dp = np.abs(t_ref[both] - t[both])  # |P - P'| = |t - t'| along a unit direction
    return {
        "pairs_on_edge_both": int(both.sum()),
        "on_edge_disagreements": int((on_ref != on).sum()),
        "max_point_distance_m": float(dp.max()) if len(dp) else 0.0,
        "median_point_distance_m": float(np.median(dp)) if len(dp) else 0.0,
        "path_length_excess_max_m": float(np.max(_path_length(inst, t)[both] - _path_length(inst, t_ref)[both]))
        if both.any() else 0.0,
    }


def _compiled_contenders(inst: EdgeInstances, per_round: int, num_per_round: int) -> dict | None:
    """The closed form and the reduced Newton search as compiled loops
    (:mod:`wavepaths.bench.point_search_compiled`), warmed up, for the same interleaved
    rounds: ``{"contenders", "calls", "results"}``, or None without numba."""
    from ..search import kernels

    if not kernels.available():
        return None
    from .point_search_compiled import closed_form_compiled, newton_reduced_compiled, run_compiled

    results = run_compiled(inst)  # compiles (or loads the cache) before any timing
    n = len(inst)
    t, on = np.empty(n), np.empty(n, dtype=np.bool_)
    args = (inst.e, inst.r, inst.origin, inst.direction, inst.length)

    def cf():
        for _ in range(per_round):
            closed_form_compiled(*args, t, on)

    def newton():
        for _ in range(num_per_round):
            newton_reduced_compiled(*args, 1e-11, 100, t, on)

    return {"contenders": {"closed_form_compiled": cf, "newton_reduced_compiled": newton},
            "calls": {"closed_form_compiled": per_round, "newton_reduced_compiled": num_per_round},
            "results": results}


def _scalar_ns(fn, inst: EdgeInstances, count: int, repeats: int = 3) -> float:
    """Median over ``repeats`` of the mean time of one scalar call [ns]."""
    rows = [(inst.e[i].tolist(), inst.r[i].tolist(), inst.origin[i].tolist(), inst.direction[i].tolist(),
             float(inst.length[i])) for i in range(count)]
    best = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for row in rows:
            fn(*row)
        best.append((time.perf_counter() - t0) / count * 1e9)
    return float(np.median(best))


def _numpy_one_pair_ns(inst: EdgeInstances, count: int) -> float:
    one = [EdgeInstances(inst.e[i : i + 1], inst.r[i : i + 1], inst.origin[i : i + 1], inst.direction[i : i + 1],
                         inst.length[i : i + 1]) for i in range(count)]
    t0 = time.perf_counter()
    for x in one:
        closed_form(x)
    return (time.perf_counter() - t0) / count * 1e9


def run_point_search(n_pairs: int = 10_000, repeats: int = 1_000, rounds: int = 10, seed: int = 0,
                     numerical_repeats: int | None = None, scalar_pairs: int = 2_000) -> dict:
    """Run benchmark 1; return its JSON-ready figures.

    Parameters
    ----------
    n_pairs : int
        Pairs (E, R, edge) solved together in one vectorised call (the seed: 10,000).
    repeats : int
        Calls of the closed form over all pairs (the seed: 1,000).
    rounds : int
        The calls are split into this many interleaved rounds; the median round is reported.
    numerical_repeats : int, optional
        Calls of each numerical search (default ``repeats``).
    scalar_pairs : int
        Pairs for the one-pair-per-call figures.
    """
    inst = random_instances(n_pairs, seed)
    rounds = max(1, min(rounds, repeats))
    per_round = max(1, repeats // rounds)
    num_per_round = max(1, (numerical_repeats or repeats) // rounds)

    t_cf, on_cf = closed_form(inst)
    results = {name: fn(inst) for name, fn in NUMERICAL.items()}

    def loop(fn, k):
        def run():
            for _ in range(k):
                fn(inst)
        return run

    red = reduce_instances(inst)
    t_eng, on_eng = engine_step(red)

    def engine_loop():
        for _ in range(per_round):
            engine_step(red)

    contenders = {"closed_form": loop(closed_form, per_round), "engine_step": engine_loop}
    contenders.update({name: loop(fn, num_per_round) for name, fn in NUMERICAL.items()})
    calls = {"closed_form": per_round, "engine_step": per_round, **{name: num_per_round for name in NUMERICAL}}
    compiled = _compiled_contenders(inst, per_round, num_per_round)
    if compiled is not None:
        contenders.update(compiled["contenders"])
        calls.update(compiled["calls"])
    times = interleaved(contenders, rounds)
    ns = {name: [t / calls[name] / n_pairs * 1e9 for t in r.times_s] for name, r in times.items()}
    med = {name: float(np.median(v)) for name, v in ns.items()}
    fastest = min(NUMERICAL, key=lambda k: med[k])

    methods = {}
    for name in ["closed_form", "engine_step", *NUMERICAL]:
        entry = {"ns_per_point_median": med[name], "ns_per_point_min": float(min(ns[name])),
                 "ns_per_point_max": float(max(ns[name])), "calls": calls[name] * rounds,
                 "total_s": float(sum(times[name].times_s))}
        if name == "engine_step":
            entry["agreement_with_closed_form"] = _agreement(inst, t_cf, on_cf, t_eng, on_eng)
        elif name != "closed_form":
            t, on, iters = results[name]
            entry["iterations"] = int(iters)
            entry["agreement_with_closed_form"] = _agreement(inst, t_cf, on_cf, t, on)
            entry["speedup_of_closed_form"] = med[name] / med["closed_form"]
        methods[name] = entry

    both_compiled = None
    if compiled is not None:
        (t_c, on_c), (t_n, on_n, iters_c) = compiled["results"]
        both_compiled = {
            "closed_form_ns_per_point": med["closed_form_compiled"],
            "newton_reduced_ns_per_point": med["newton_reduced_compiled"],
            "speedup": med["newton_reduced_compiled"] / med["closed_form_compiled"],
            "newton_iterations": iters_c,
            "closed_form_agreement_with_numpy": _agreement(inst, t_cf, on_cf, t_c, on_c),
            "newton_agreement_with_closed_form": _agreement(inst, t_cf, on_cf, t_n, on_n),
        }
    scalar_pairs = min(scalar_pairs, n_pairs)
    scalar = {
        "closed_form_python_ns": _scalar_ns(closed_form_scalar, inst, scalar_pairs),
        "newton_python_ns": _scalar_ns(newton_scalar, inst, scalar_pairs),
        "closed_form_numpy_one_pair_ns": _numpy_one_pair_ns(inst, min(scalar_pairs, 500)),
    }
    scalar["speedup_python"] = scalar["newton_python_ns"] / scalar["closed_form_python_ns"]
    cf_ok = np.array([closed_form_scalar(inst.e[i], inst.r[i], inst.origin[i], inst.direction[i], inst.length[i])[1]
                      for i in range(scalar_pairs)])
    return {
        "n_pairs": n_pairs,
        "repeats": repeats,
        "rounds": rounds,
        "fraction_on_edge": float(on_cf.mean()),
        "scalar_python_on_edge_agrees": bool((cf_ok == on_cf[:scalar_pairs]).all()),
        "methods": methods,
        "fastest_numerical": fastest,
        "point_search_ns": med["closed_form"],
        "point_search_speedup": med[fastest] / med["closed_form"],
        "engine_candidate_ns": med["engine_step"],
        # both searches as compiled loops (numba; None without it): the algorithms' own ratio
        "both_compiled": both_compiled,
        "point_search_speedup_compiled": both_compiled["speedup"] if both_compiled else None,
        "point_search_max_point_distance_m": methods[fastest]["agreement_with_closed_form"]["max_point_distance_m"],
        "scalar_per_call": scalar,
        "seed": {"ns_per_point": SEED_NS_PER_POINT, "speedup": list(SEED_SPEEDUP),
                 "hardware": "SGI Origin 200, one MIPS R10000 (1999)"},
        "targets": {"point_search_ns_max": 50.0, "point_search_speedup_min": 5.0},
    }


# ---- the kernel against other formulations -----------------------------------------------
def _closed_form_einsum_norm(e, r, origin, direction, length):
    """:func:`diffraction_point_parameter` before its rewrite: ``einsum`` projections,
    ``np.linalg.norm`` distances."""
    ve = e - origin
    vr = r - origin
    te = np.einsum("...j,...j->...", ve, direction)
    tr = np.einsum("...j,...j->...", vr, direction)
    de = np.linalg.norm(ve - te[..., None] * direction, axis=-1)
    dr = np.linalg.norm(vr - tr[..., None] * direction, axis=-1)
    s = de + dr
    ok = s > 0
    t = np.where(ok, (te * dr + tr * de) / np.where(ok, s, 1.0), 0.5 * (te + tr))
    return t, (t >= 0.0) & (t <= length)


def _closed_form_dots(e, r, origin, direction, length):
    """The closed form with row-wise dot products only, ``d^2 = v.v - (v.w)^2``.

    Cancels when a point is close to the edge line (absolute error of ``d`` about
    ``eps |v|^2 / d`` instead of ``eps |v|``); timed for comparison only.
    """
    ve = e - origin
    vr = r - origin
    te = np.einsum("ij,ij->i", ve, direction)
    tr = np.einsum("ij,ij->i", vr, direction)
    de = np.sqrt(np.maximum(np.einsum("ij,ij->i", ve, ve) - te * te, 0.0))
    dr = np.sqrt(np.maximum(np.einsum("ij,ij->i", vr, vr) - tr * tr, 0.0))
    t = (te * dr + tr * de) / (de + dr)
    return t, (t >= 0.0) & (t <= length)


def _closed_form_soa(e, r, origin, direction, length):
    """The kernel's formula (distances from ``v - t w``) on coordinate rows ``(3, n)``
    (struct of arrays), in place where possible. Nothing calls it: the search keeps its
    points as ``(n, 3)`` rows, and converting them costs more than the layout saves."""
    wx, wy, wz = direction
    out = []
    for p in (e, r):
        vx, vy, vz = p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]
        t = vx * wx
        q = vy * wy
        t += q
        np.multiply(vz, wz, out=q)
        t += q
        for vc, wc in ((vx, wx), (vy, wy), (vz, wz)):
            np.multiply(t, wc, out=q)
            vc -= q
        vx *= vx
        vy *= vy
        vz *= vz
        vx += vy
        vx += vz
        np.sqrt(vx, out=vx)
        out += [t, vx]
    te, de, tr, dr = out
    t = te * dr
    t += tr * de
    de += dr
    t /= de
    return t, (t >= 0.0) & (t <= length)


def variant_timings(n_pairs: int = 10_000, repeats: int = 300, rounds: int = 5, seed: int = 0) -> dict:
    """ns per point of :func:`closed_form` and of other formulations of it (same pairs, one run).

    Only the first entry is the figure of ``point_search_ns`` (the same call): the others
    are the kernel before its rewrite (``einsum`` and ``np.linalg.norm``), the cancelling
    ``d^2 = v.v - (v.w)^2`` form, and the kernel's formula on coordinate rows ``(3, n)``,
    which nothing calls. All are checked against the kernel to 1e-9 m on these pairs
    (random pairs rarely come close to the edge line, where the ``d^2`` form loses digits).
    """
    inst = random_instances(n_pairs, seed)
    soa = tuple(np.ascontiguousarray(x.T) for x in (inst.e, inst.r, inst.origin, inst.direction))
    t_ref, _ = closed_form(inst)
    for t, _ in (_closed_form_einsum_norm(inst.e, inst.r, inst.origin, inst.direction, inst.length),
                 _closed_form_dots(inst.e, inst.r, inst.origin, inst.direction, inst.length),
                 _closed_form_soa(*soa, inst.length)):
        if np.abs(t - t_ref).max() > 1e-9:
            raise AssertionError("a closed-form variant disagrees with diffraction_point_parameter")
    per = max(1, repeats // rounds)

    def loop(fn):
        def run():
            for _ in range(per):
                fn()
        return run

    times = interleaved({
        "closed form, diffraction_point_parameter (AoS, projection, column ufuncs)": loop(lambda: closed_form(inst)),
        "diffraction_point_parameter before its rewrite (AoS, einsum + norm)": loop(
            lambda: _closed_form_einsum_norm(inst.e, inst.r, inst.origin, inst.direction, inst.length)),
        "AoS, einsum dot products only (d^2 = v.v - (v.w)^2, cancels near the line)": loop(
            lambda: _closed_form_dots(inst.e, inst.r, inst.origin, inst.direction, inst.length)),
        "SoA (3, n) rows, same formula, in place (no caller)": loop(
            lambda: _closed_form_soa(*soa, inst.length)),
    }, rounds)
    return {k: v.median_s / per / n_pairs * 1e9 for k, v in times.items()}
