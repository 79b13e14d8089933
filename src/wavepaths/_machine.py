"""The host and the versions every report records (the benchmark's and the validation's)."""

from __future__ import annotations

import os
import platform
import sys


def host_versions() -> dict:
    """wavepaths, Python, numpy and scipy versions, the platform, the CPU count and the CPU
    model (from ``/proc/cpuinfo`` where there is one)."""
    import numpy
    import scipy

    from . import __version__

    out = {"wavepaths": __version__, "python": sys.version.split()[0], "numpy": numpy.__version__,
           "scipy": scipy.__version__, "platform": platform.platform(), "machine": platform.machine(),
           "cpus": os.cpu_count()}
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    out["cpu"] = line.split(":", 1)[1].strip()
                    break
    except OSError:  # pragma: no cover
        pass
    return out
