"""The coverage map's tolerance (``TraceOptions.tolerance_db``): which held-back diffracted
candidates a cell keeps, by the bound of docs/coverage.md ("A tolerance in dB").

:func:`tolerance_keep` bounds each candidate's power with the UTD bound times the antennas'
peak pattern amplitudes (:func:`peak_pattern_amplitude`) and drops, per (transmitter, cell),
the weakest while their sum stays within the tolerance of the cell's line-of-sight and
reflected power; :func:`tolerance_drop_numpy` is the reference of the compiled drop
(``wavepaths.search._numba_tolerance.tolerance_drop``). :func:`warn_unbounded` says when a
map's pruning (``tolerance_db``, ``prune_db``) relies on a bound that does not hold for it.
"""

from __future__ import annotations

from collections import Counter
from functools import lru_cache

import numpy as np

from ..fields import FieldConfig
from ..search import kernels
from ..search.context import TxContext
from ..search.options import TraceOptions


def warn_unbounded(opts: TraceOptions, cfg: FieldConfig, coherent: bool) -> None:
    """A :class:`~wavepaths.scene.WavepathsWarning` for each bound a map's pruning relies on that
    does not hold for this map: ``tolerance_db`` on a ``coherent`` map (its bound is on the power
    sum; the coherent total can move by much more where paths cancel), and ``prune_db`` pruning
    diffracted paths (``prune_frequency_hz`` given) by the UTD bound, which holds at
    ``prune_frequency_hz`` and above, and not for Keller's GTD, whose coefficient diverges at the
    boundaries (:attr:`TraceOptions.prune_db`). Only the map knows both the options and the
    fields: :func:`wavepaths.trace` has no fields, :func:`wavepaths.compute_fields` no options.
    ``stacklevel`` points at the caller of :func:`~wavepaths.coverage.coverage`."""
    import warnings

    from ..scene import WavepathsWarning

    if opts.tolerance_db is not None and coherent:
        warnings.warn(f"`tolerance_db` ({opts.tolerance_db:g} dB, --tolerance-db) bounds the power sum (--incoherent), "
                      "the total of `CoverageOptions(coherent=False)`; the coherent total, this map's default, can "
                      "move by much more where paths cancel (a review measured 10.8 dB in a cell of the street "
                      "canyon at 0.1 dB, 26 dB at 1 dB)", WavepathsWarning, stacklevel=3)
    if opts.prune_db is None or opts.prune_frequency_hz is None or not opts.diffraction:
        return
    if cfg.model == "gtd":
        warnings.warn(f"`prune_db` prunes diffracted paths by the UTD's bound, which does not hold for the "
                      f"fields' model 'gtd': dropped paths may exceed -{opts.prune_db:g} dB", WavepathsWarning,
                      stacklevel=3)
    elif opts.prune_frequency_hz > cfg.frequency_hz:
        warnings.warn(f"`prune_frequency_hz` ({opts.prune_frequency_hz:g} Hz) is above the map's frequency "
                      f"({cfg.frequency_hz:g} Hz): the diffraction bound of `prune_db` holds only at that "
                      f"frequency and above, so dropped paths may exceed -{opts.prune_db:g} dB", WavepathsWarning,
                      stacklevel=3)


@lru_cache(maxsize=64)
def peak_pattern_amplitude(antenna, port: int = 0, samples: int = 181) -> float:
    """The largest ``sqrt(|C_theta|^2 + |C_phi|^2)`` of an antenna port over all directions.

    Sampled on a ``samples x 2 samples`` grid of the sphere (1 degree by default) and raised
    by 1 % (the patterns are smooth: between samples they cannot rise more than that).
    A pure function of the (frozen) antenna, kept per antenna: the sampling (65,000
    directions, about 10 ms) was paid twice per coverage tile, which made the street canyon's
    R2+D1 map with ``tolerance_db=0.1`` slower than without it.
    """
    from ..em.antennas import antenna_field

    th, ph = np.meshgrid(np.linspace(0, np.pi, samples), np.linspace(-np.pi, np.pi, 2 * samples))
    d = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], axis=-1).reshape(-1, 3)
    c = antenna_field(antenna, d)[:, port, :]
    return 1.01 * float(np.sqrt((np.abs(c) ** 2).sum(axis=1)).max())


def tolerance_keep(ctx: TxContext, config: FieldConfig, pending: list, go_power: np.ndarray, k: int,
                    stats: Counter) -> list[np.ndarray]:
    """Which held-back diffracted candidates a map with ``tolerance_db`` keeps (one mask per entry).

    Per (transmitter, cell), the candidates are taken weakest bound first and dropped while
    the sum of their power bounds stays at most ``(10^(tol/10) - 1)`` times the power of the
    cell's line-of-sight and reflected paths ``go_power`` (m * k,). Dropped paths carry at
    most that power, so the cell's power-sum total changes by at most ``tol`` dB.
    """
    eps = 10 ** (ctx.options.tolerance_db / 10) - 1
    scale = (config.wavelength / (4 * np.pi) * peak_pattern_amplitude(config.tx_antenna)
             * peak_pattern_amplitude(config.rx_antenna)) ** 2
    sizes = [len(p) for p in pending]
    pair = np.concatenate([p.tx * k + p.rx for p in pending])
    bound = np.concatenate([np.full(len(p), np.inf) if p.amp is None else p.amp for p in pending]) ** 2 * scale
    if ctx.options.compiled and kernels.available():
        from ..search import _numba_tolerance

        drop = _numba_tolerance.tolerance_drop(pair.astype(np.int64), bound, np.ascontiguousarray(go_power, dtype=np.float64),
                                     float(eps), int(len(go_power)))
    else:
        drop = tolerance_drop_numpy(pair, bound, go_power, eps)
    stats["tolerance_dropped_candidates"] += int(drop.sum())
    return np.split(~drop, np.cumsum(sizes)[:-1])


def tolerance_drop_numpy(pair: np.ndarray, bound: np.ndarray, go_power: np.ndarray, eps: float) -> np.ndarray:
    """(k,) bool: the candidates :func:`tolerance_keep` drops, from their (transmitter, cell)
    pairs ``pair``, power bounds ``bound`` and the pairs' geometrical-optics powers
    ``go_power`` (the reference of ``wavepaths.search._numba_tolerance.tolerance_drop``).

    Per pair, its candidates by bound (weakest first; ties in their order) and a running sum
    of its own, started at 0, an infinite bound counted as 0 and never dropped (it sorts
    last); a candidate is dropped while its pair's sum stays at most ``eps * go_power[pair]``.
    The sums are added rank by rank (the pairs' first candidates, then their second, ...),
    so each pair's sum is added in the kernel's order, from 0, and never differenced out of
    a sum over other pairs (which loses a bound below ~1e-16 of those pairs' total).
    """
    order = np.lexsort((bound, pair))
    sp, sb = pair[order], bound[order]
    finite = np.isfinite(sb)
    val = np.where(finite, sb, 0.0)
    first = np.searchsorted(sp, sp, side="left")
    rank = np.arange(len(sp)) - first  # position within its pair
    by_rank = np.argsort(rank, kind="stable")
    edges = np.searchsorted(rank[by_rank], np.arange(rank.max(initial=-1) + 2))
    cum = np.zeros(len(go_power))  # each pair's running sum
    within = np.empty(len(sp))
    for r in range(len(edges) - 1):  # one pass per rank (at most one candidate of a pair each)
        at = by_rank[edges[r]:edges[r + 1]]
        cum[sp[at]] += val[at]
        within[at] = cum[sp[at]]
    drop = np.zeros(len(pair), dtype=bool)
    drop[order] = finite & (within <= eps * go_power[sp])
    return drop
