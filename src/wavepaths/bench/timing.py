"""Timing and memory helpers shared by the benchmarks.

The machine is shared and noisy (2 cores, other jobs): every comparison of two speeds is
measured in one run, the contenders interleaved round by round, and reported as the
median over rounds (with the spread). Peak memory is measured in a separate run with
``tracemalloc`` (numpy reports its buffers to it), so that tracing does not slow the
timed runs; memory held by Embree's BVH and by Dr.Jit is not seen by it, and the
resident peak of the child process that ran the step
(:func:`wavepaths.bench.isolated.peak_rss_bytes`) is reported beside it.
"""

from __future__ import annotations

import gc
import os
import statistics
import time
import tracemalloc
from dataclasses import dataclass, field
from typing import Callable


@dataclass
class Rounds:
    """Wall times of repeated runs of one contender.

    Attributes
    ----------
    times_s : list of float
        One wall time per round [s].
    """

    times_s: list[float] = field(default_factory=list)

    @property
    def median_s(self) -> float:
        return statistics.median(self.times_s)

    @property
    def min_s(self) -> float:
        return min(self.times_s)

    @property
    def max_s(self) -> float:
        return max(self.times_s)

    def as_dict(self) -> dict:
        return {"median_s": self.median_s, "min_s": self.min_s, "max_s": self.max_s, "rounds": len(self.times_s),
                "times_s": list(self.times_s)}


def interleaved(contenders: dict[str, Callable[[], object]], rounds: int) -> dict[str, Rounds]:
    """Run each contender once per round, in turn, ``rounds`` times; return their wall times.

    Interleaving spreads the machine's load changes over all contenders alike. The order
    turns by one place each round, so that no contender always runs first, or always right
    after the heaviest one (whose freed memory the next run pays for).
    """
    out = {name: Rounds() for name in contenders}
    names = list(contenders)
    for r in range(rounds):
        for name in names[r % len(names):] + names[: r % len(names)]:
            fn = contenders[name]
            gc.collect()
            t0 = time.perf_counter()
            fn()
            out[name].times_s.append(time.perf_counter() - t0)
    return out


def peak_python_memory(fn: Callable[[], object]) -> tuple[object, int]:
    """(result, peak bytes allocated through Python and numpy during ``fn``)."""
    gc.collect()
    was = tracemalloc.is_tracing()
    if not was:
        tracemalloc.start()
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    try:
        result = fn()
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        if not was:
            tracemalloc.stop()
    return result, int(peak)


def load_average() -> list[float]:
    """The 1, 5 and 15 minute load averages (other jobs on the machine)."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:  # pragma: no cover
        return []
