"""Run one benchmark step in a child process, with a time limit and its own memory peak.

A step that may take too long (a large scene at a high order) or whose peak memory is
wanted (the resident peak of a fresh process, which counts Embree's and Dr.Jit's memory too)
runs here. The child imports the named function, calls it with the keyword arguments,
and sends back its JSON-ready result; on time-out it is killed and the result says so.
"""

from __future__ import annotations

import importlib
import multiprocessing as mp
import os
import signal
import resource
import time
import traceback


def peak_rss_bytes() -> int:
    """This process's resident peak [bytes]: ``VmHWM`` (reset by exec, unlike ``ru_maxrss``,
    which a spawned child inherits from the parent it was forked from)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:  # pragma: no cover - not Linux
        pass
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024


def group_rss_bytes(pgid: int) -> int:
    """Resident memory of every process in process group ``pgid`` [bytes] (Linux ``/proc``;
    0 elsewhere): a step and the pool of workers it started."""
    total = 0
    page = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096
    try:
        pids = [p for p in os.listdir("/proc") if p.isdigit()]
    except OSError:  # pragma: no cover - not Linux
        return 0
    for p in pids:
        try:
            with open(f"/proc/{p}/stat") as f:
                stat = f.read()
            # the fields after the command name (which may hold spaces) in parentheses
            if int(stat[stat.rindex(")") + 2:].split()[2]) != pgid:
                continue
            with open(f"/proc/{p}/statm") as f:
                total += int(f.read().split()[1]) * page
        except (OSError, ValueError, IndexError):
            continue
    return total


class _GroupPeak:
    """Samples :func:`group_rss_bytes` every ``period`` seconds on a thread; ``peak`` [bytes]."""

    def __init__(self, pgid: int, period: float = 0.5) -> None:
        import threading

        self.pgid, self.period, self.peak = pgid, period, 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            self.peak = max(self.peak, group_rss_bytes(self.pgid))
            self._stop.wait(self.period)

    def __enter__(self) -> "_GroupPeak":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(5)


def _child(queue, module: str, name: str, kwargs: dict, memory_limit_bytes: int | None) -> None:
    os.setpgrp()  # its own process group: a time-out ends the child and any pool it started
    if memory_limit_bytes:
        resource.setrlimit(resource.RLIMIT_AS, (memory_limit_bytes, memory_limit_bytes))
    try:
        fn = getattr(importlib.import_module(module), name)
        result = fn(**kwargs)
        queue.put({"ok": True, "result": result, "max_rss_bytes": peak_rss_bytes()})
    except BaseException as exc:  # noqa: BLE001 - reported to the parent
        queue.put({"ok": False, "error": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc()})


def run_isolated(module: str, name: str, kwargs: dict | None = None, timeout_s: float = 600.0,
                 memory_limit_bytes: int | None = 8 << 30) -> dict:
    """Call ``module.name(**kwargs)`` in a fresh process; give up after ``timeout_s``.

    The child's address space is limited to ``memory_limit_bytes`` (a ``MemoryError``
    then ends it cleanly instead of the machine's out-of-memory killer); the machine has
    24 GiB and is shared.

    Returns
    -------
    dict
        ``ok`` (bool), ``result`` (what the function returned) or ``error``,
        ``timed_out`` (bool), ``wall_s`` (child wall time, start-up included),
        ``max_rss_bytes`` (the child's resident peak, ``VmHWM``) and
        ``max_group_rss_bytes`` (the peak of the summed resident memory of the child and the
        processes it started, such as a coverage map's workers, sampled every 0.5 s).
    """
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=_child, args=(queue, module, name, kwargs or {}, memory_limit_bytes), daemon=False)
    t0 = time.perf_counter()
    proc.start()
    out = None
    with _GroupPeak(proc.pid) as group:
        try:
            out = queue.get(timeout=timeout_s)
        except Exception:  # queue.Empty on time-out
            out = None
    wall = time.perf_counter() - t0
    if out is None:
        _kill_group(proc)
        return {"ok": False, "timed_out": True, "error": f"did not finish within {timeout_s:g} s", "wall_s": wall,
                "max_group_rss_bytes": group.peak}
    out["max_group_rss_bytes"] = group.peak
    proc.join(30)
    if proc.is_alive():  # pragma: no cover - the child sent its result and hangs on exit
        _kill_group(proc)
    out["timed_out"] = False
    out["wall_s"] = wall
    return out


def _kill_group(proc) -> None:
    """End the child and the processes it started (its own process group), by its id."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        proc.kill()
    proc.join(5)
