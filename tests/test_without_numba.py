"""The package without numba (it is optional: the ``fast`` extra): every search mode, the
fields and a coverage map run in a process where importing numba fails, and give the
compiled process's paths and gains. A review found launched candidates raising
ImportError there."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("numba")  # the reference side of the comparison runs compiled

SCRIPT = r'''
import json, sys
if sys.argv[1] == "block":
    class Block:
        def find_spec(self, name, path=None, target=None):
            if name == "numba" or name.startswith("numba."):
                raise ImportError("numba is blocked for this test")
    sys.meta_path.insert(0, Block())
import warnings
warnings.simplefilter("error")
import numpy as np
import wavepaths as wp
from wavepaths.coverage import CoverageOptions, PlanarGrid, coverage
from wavepaths.fields import FieldConfig, compute_fields
from wavepaths.search import kernels

scene = wp.load_scene("street_canyon")
tx = [[-60.0, 0.5, 10.0]]
rx = np.array([[20.0, 0.3, 1.5], [60.0, 5.0, 1.5], [-20.0, 6.0, 1.5], [0.0, 8.0, 2.0]])
out = {"compiled": kernels.available(), "numba_imported": "numba" in sys.modules}
for name, opts in (("exhaustive", wp.TraceOptions()),
                   ("launched", wp.TraceOptions(diffraction_candidates="launched", reflection_candidates="launched"))):
    p = wp.trace(scene, tx, rx, opts)
    out[name] = {"keys": sorted([int(p.rx_index[i]), list(map(int, p.interactions[i])), list(map(int, p.primitive[i]))]
                                for i in range(len(p))),
                 "gain_db": compute_fields(scene, p, FieldConfig(3.5e9)).path_gain_db(True)[0].tolist()}
grid = PlanarGrid(center=[-37.3, 2.2], size=[28, 20], cell_size=[7, 5], height=1.5)
m = coverage(scene, tx, grid, wp.TraceOptions(), settings=CoverageOptions(workers=1))
out["map_db"] = np.nan_to_num(m.path_gain_db(), neginf=-999.0).ravel().tolist()
print(json.dumps(out))
'''


def run(mode: str) -> dict:
    r = subprocess.run([sys.executable, "-c", SCRIPT, mode], capture_output=True, text=True, timeout=600,
                       env={**os.environ, "PYTHONWARNINGS": "error"})
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_every_search_mode_fields_and_maps_run_without_numba_and_agree_with_the_compiled_kernels():
    plain, fast = run("block"), run("allow")
    assert not plain["compiled"] and not plain["numba_imported"]
    assert fast["compiled"]
    for mode in ("exhaustive", "launched"):
        assert plain[mode]["keys"] == fast[mode]["keys"], mode
        assert len(plain[mode]["keys"]) > 20
        np.testing.assert_allclose(plain[mode]["gain_db"], fast[mode]["gain_db"], atol=1e-9)
    np.testing.assert_allclose(plain["map_db"], fast["map_db"], atol=1e-9)
