"""Path-by-path comparison of wavepaths with Sionna RT.

Paths are matched by interaction sequence and geometry, never by order: for each
(transmitter, receiver) pair and each sequence of interaction types, a Sionna path and a
wavepaths path match when every vertex lies within ``vertex_tol`` of the other's. Each
unmatched path gets a reason (:func:`explain_unmatched`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from ..search.paths import InteractionType, Paths
from ..em.constants import SPEED_OF_LIGHT  # noqa: F401 (re-exported)



DUPLICATE_TOL_M = 1e-2
SIONNA_DUPLICATE = ("duplicate: Sionna gives this path twice (the edge or face is shared by two objects, or by two "
                    "blocks of one mesh, and it interacts with each one's own copy); its twin is matched. wavepaths "
                    "has one dihedron with all the faces (seed §3.2)")


@dataclass
class Match:
    """One matched pair of paths and their differences."""

    tx: int
    rx: int
    kinds: str
    wp_index: int
    sn_index: int
    vertex_error_m: float
    delay_rel_error: float
    gain_diff_db: float
    phase_diff_rad: float


@dataclass
class Comparison:
    """The comparison of one case."""

    matches: list[Match] = field(default_factory=list)
    only_wavepaths: list[dict] = field(default_factory=list)
    only_sionna: list[dict] = field(default_factory=list)

    def summary(self) -> dict:
        def stats(values):
            # the extremes over the finite values, and how many were not finite (a path of
            # amplitude 0 on one side only: an infinite gain difference; a NaN amplitude)
            values = np.asarray(list(values), float)
            v = values[np.isfinite(values)]
            bad = int(len(values) - len(v))
            if len(v) == 0:
                return {"max": None, "median": None, "non_finite": bad}
            return {"max": float(np.max(np.abs(v))), "median": float(np.median(np.abs(v))), "non_finite": bad}

        by_kind: dict[str, dict] = {}
        for m in self.matches:
            by_kind.setdefault(m.kinds, []).append(m)
        return {
            "matched": len(self.matches),
            "only_wavepaths": len(self.only_wavepaths),
            "only_sionna": len(self.only_sionna),
            "delay_rel_error": stats([m.delay_rel_error for m in self.matches]),
            "gain_diff_db": stats([m.gain_diff_db for m in self.matches]),
            "vertex_error_m": stats([m.vertex_error_m for m in self.matches]),
            "by_kind": {
                k: {"matched": len(v), "gain_diff_db": stats([m.gain_diff_db for m in v]),
                    "delay_rel_error": stats([m.delay_rel_error for m in v])}
                for k, v in sorted(by_kind.items())
            },
            "only_wavepaths_reasons": _count(r["reason"] for r in self.only_wavepaths),
            "only_sionna_reasons": _count(r["reason"] for r in self.only_sionna),
        }


def _gain_diff_db(gw: float, gs: float) -> float:
    """``20 log10(gw / gs)`` [dB] of two amplitudes' moduli: 0 where both are 0 (the same
    path, no field on either side), +-inf where only one is, NaN where either is NaN, so that
    a coefficient that collapsed to 0 in one engine is a difference, never dropped."""
    if np.isnan(gw) or np.isnan(gs):
        return float("nan")
    if gw == 0.0 and gs == 0.0:
        return 0.0
    if gw == 0.0 or gs == 0.0:
        return float("inf") if gs == 0.0 else float("-inf")
    return float(20 * np.log10(gw / gs))


def _count(items) -> dict:
    out: dict[str, int] = {}
    for i in items:
        out[i] = out.get(i, 0) + 1
    return out


def kinds_string(interactions: np.ndarray, depth: int) -> str:
    letters = {int(InteractionType.REFLECTION): "R", int(InteractionType.DIFFRACTION): "D"}
    return "-".join(letters[int(t)] for t in interactions[:depth]) or "LOS"


def compare_paths(
    wp_paths: Paths,
    wp_a: np.ndarray,
    sn,
    *,
    vertex_tol: float = 0.02,
    explain=None,
) -> Comparison:
    """Match wavepaths paths (with coefficients ``wp_a``) and Sionna paths ``sn`` (SionnaPaths).

    Parameters
    ----------
    wp_paths : Paths
    wp_a : (N,) complex
        wavepaths coefficients in Sionna's normalisation.
    sn : SionnaPaths
    vertex_tol : float
        Largest vertex distance [m] for a match (Sionna's vertices are float32).
    explain : callable, optional
        ``explain(side, index) -> str`` giving the reason an unmatched path is unmatched.
    """
    comp = Comparison()
    wp_kinds = [kinds_string(wp_paths.interactions[i], wp_paths.depth[i]) for i in range(len(wp_paths))]
    sn_kinds = [kinds_string(sn.interactions[i], sn.num_interactions[i]) for i in range(len(sn.tx_index))]
    groups: dict[tuple, tuple[list, list]] = {}
    for i, k in enumerate(wp_kinds):
        groups.setdefault((int(wp_paths.tx_index[i]), int(wp_paths.rx_index[i]), k), ([], []))[0].append(i)
    for j, k in enumerate(sn_kinds):
        groups.setdefault((int(sn.tx_index[j]), int(sn.rx_index[j]), k), ([], []))[1].append(j)
    wp_len = wp_paths.lengths
    for (t, r, k), (wi, sj) in groups.items():
        used_w, used_s = set(), set()
        if wi and sj:
            depth = 0 if k == "LOS" else k.count("-") + 1
            vw = wp_paths.vertices[wi][:, : depth + 2]
            vs = sn.vertices[sj][:, : depth + 2]
            cost = np.linalg.norm(vw[:, None] - vs[None], axis=3).max(axis=2)
            # every pair beyond the tolerance costs the same large amount, so the assignment
            # first maximises the number of matches, then minimises their distances (on raw
            # distances it could split an exact pair to shorten two far ones)
            capped = np.where(cost <= vertex_tol, cost, 1e6 * max(vertex_tol, 1.0))
            rows, cols = linear_sum_assignment(capped)
            for a, b in zip(rows, cols):
                if cost[a, b] > vertex_tol:
                    continue
                i, j = wi[a], sj[b]
                used_w.add(i)
                used_s.add(j)
                length = wp_len[i]
                gw, gs = abs(wp_a[i]), abs(sn.a[j])
                comp.matches.append(
                    Match(
                        t, r, k, i, j, float(cost[a, b]),
                        float((sn.tau[j] * SPEED_OF_LIGHT - length) / length),
                        _gain_diff_db(gw, gs),
                        float(np.angle(wp_a[i] / sn.a[j])) if gw > 0 and gs > 0 else float("nan"),
                    )
                )
        for i in wi:
            if i not in used_w:
                comp.only_wavepaths.append({"tx": t, "rx": r, "kinds": k, "index": i, "length_m": float(wp_len[i]),
                                            "gain_db": float(20 * np.log10(max(abs(wp_a[i]), 1e-300))),
                                            "reason": explain("wavepaths", i) if explain else ""})
        twins = [j2 for j2 in sj if j2 in used_s]
        for j in sj:
            if j not in used_s:
                n = int(sn.num_interactions[j])
                dup = any(np.abs(sn.vertices[j2, : n + 2] - sn.vertices[j, : n + 2]).max() < DUPLICATE_TOL_M
                          and ((sn.objects[j2, :n] != sn.objects[j, :n]).any()
                               or (sn.primitives[j2, :n] != sn.primitives[j, :n]).any()) for j2 in twins)
                comp.only_sionna.append({"tx": t, "rx": r, "kinds": k, "index": j,
                                         "length_m": float(sn.tau[j] * SPEED_OF_LIGHT),
                                         "gain_db": float(20 * np.log10(max(abs(sn.a[j]), 1e-300))),
                                         "reason": SIONNA_DUPLICATE if dup else (explain("sionna", j) if explain else "")})
    return comp


def total_gain_db(tx_index, rx_index, a, tau, frequency_hz, m, n) -> np.ndarray:
    """(m, n) coherent total path gain [dB] from flat coefficients (Sionna's normalisation)."""
    out = np.zeros(m * n, complex)
    np.add.at(out, np.asarray(tx_index) * n + np.asarray(rx_index), a * np.exp(-2j * np.pi * frequency_hz * tau))
    p = np.abs(out) ** 2
    with np.errstate(divide="ignore"):
        return (10 * np.log10(p)).reshape(m, n)
