"""Smoke test against the real Sionna RT: free-space line of sight.

Runs ``PathSolver`` through :func:`wavepaths.validation.sionna_runner.run_sionna_paths`
in an empty scene and checks Sionna's normalisation: ``|a| = lambda / (4 pi d)``,
``a`` real and positive (no propagation phase), ``tau = d / c``. Skipped, with
the reason, when sionna-rt or a libLLVM >= 16 is missing
(``bash scripts/install-sionna.sh`` installs both).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from scipy.constants import c

from wavepaths.validation.sionna_env import find_libllvm, sionna_version

pytestmark = pytest.mark.sionna

if importlib.util.find_spec("sionna") is None or sionna_version() is None:
    pytest.skip("sionna-rt is not installed (bash scripts/install-sionna.sh)", allow_module_level=True)
if find_libllvm() is None:
    pytest.skip("no libLLVM >= 16 for Dr.Jit (bash scripts/install-sionna.sh)", allow_module_level=True)

from wavepaths.validation.sionna_runner import NONE, run_sionna_paths  # noqa: E402

FREQUENCY_HZ = 3.5e9


@pytest.fixture(scope="module")
def empty_scene(tmp_path_factory: pytest.TempPathFactory) -> str:
    path = Path(tmp_path_factory.mktemp("sionna")) / "empty.xml"
    path.write_text('<scene version="2.1.0"></scene>\n')
    return str(path)


def test_free_space_los_normalisation(empty_scene: str) -> None:
    tx = np.array([[0.0, 0.0, 10.0], [5.0, -3.0, 2.0]])
    rx = np.array([[100.0, 0.0, 10.0], [37.3, 12.1, 3.3], [5.0, 5.0, 5.0]])
    result = run_sionna_paths(empty_scene, tx, rx, frequency_hz=FREQUENCY_HZ, max_depth=1,
                              diffraction=False, samples_per_src=1000, warmup=False)

    assert result.num_paths == tx.shape[0] * rx.shape[0]
    assert result.excluded == 0
    assert np.all(result.interactions == NONE)
    assert np.all(result.num_interactions == 0)

    d = np.linalg.norm(rx[result.rx_index] - tx[result.tx_index], axis=1)
    lam = c / FREQUENCY_HZ
    np.testing.assert_allclose(np.abs(result.a), lam / (4 * np.pi * d), rtol=1e-5)
    # Paths.a carries no propagation phase: the phase is exp(-2j pi f tau).
    assert np.all(np.abs(result.a.imag) <= 1e-6 * np.abs(result.a))
    assert np.all(result.a.real > 0)
    np.testing.assert_allclose(result.tau, d / c, rtol=1e-6)

    np.testing.assert_allclose(result.vertices[:, 0], tx[result.tx_index], atol=1e-5)
    np.testing.assert_allclose(result.vertices[:, 1], rx[result.rx_index], atol=1e-5)
    assert np.all(np.isnan(result.vertices[:, 2]))
    assert result.elapsed_s >= 0.0
