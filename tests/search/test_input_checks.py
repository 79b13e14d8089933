"""Bad inputs to the public API and the command line give a WavepathsError or exit 2 with a
message, never a raw TypeError or ValueError from deep inside."""

from __future__ import annotations

import subprocess
import sys

import pytest

import wavepaths as wp
from wavepaths import TraceOptions, WavepathsError
from wavepaths.fields import FieldConfig


@pytest.mark.parametrize("kwargs", [{"max_reflections": 2.5}, {"diffraction_reflections": "1"},
                                    {"max_reflections": True}])
def test_integer_options_must_be_integers(kwargs):
    with pytest.raises(WavepathsError, match="must be an integer"):
        TraceOptions(**kwargs)


def test_frequency_must_be_a_number():
    with pytest.raises(WavepathsError, match="must be a number"):
        FieldConfig(frequency_hz="3.5e9")


def test_positions_must_be_numbers():
    with pytest.raises(WavepathsError, match="`tx` must be numbers"):
        wp.trace(wp.load_scene("street_canyon"), [["a", 0, 10]], [[0, 0, 1.5]])


def test_python_dash_m_runs_the_command_line():
    r = subprocess.run([sys.executable, "-m", "wavepaths", "info", "street_canyon", "--json"], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert '"triangles": 98' in r.stdout
