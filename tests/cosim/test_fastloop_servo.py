"""The servo sensors in the compiled fine loop (cosim/fastloop/servo.py): the Python loop's outputs bit for bit.

Every servo sampling (interval means and low-pass filters stepped at the plant's rate, instant samples), events
on servo channels off the recording grid, noise blocks crossed (the block shortened to 97 draws, in both loops),
no second current sensor; and the cases the compiled loop leaves to Python.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from feeddrive.cosim import sensors_servo

sys.path.insert(0, str(Path(__file__).parent))
from test_fastloop import assert_identical, run_both  # noqa: E402
from test_monitor_pmsm import vendor_scenario  # noqa: E402

WITH_SERVO = "compiled fine loop (NC, plant FMU, sensors, servo sensors, monitor's buffering)"
#: a tool change at once (the example's starts with a dwell of 0.1 s): the axis moves within a short record
MOVE = [{"tool_change": {"position": 0.02, "v_max": 0.1, "accel": 3.0, "time": 0.01}}]


@pytest.fixture
def short_blocks(monkeypatch):
    """The servo sensors' noise drawn 97 rows at a time (4096 by default): a short run crosses blocks."""
    monkeypatch.setattr(sensors_servo, "BLOCK", 97)


def test_vendor_pmsm_oversampled_every_sampling_and_events(monkeypatch, vendor_pmsm_fmu, short_blocks):
    """The vendor PMSM at 4 plant steps per sample: the phase currents averaged, the voltages low-pass filtered
    (orders 3 and 8: one and four sections), the second sensor instant; gain, offset and noise events on phase V,
    the encoder and the scale between recording instants."""
    data = vendor_scenario(vendor_pmsm_fmu, 4)
    data["nc"] = {"program": MOVE}
    data["stop_time"] = 0.03
    data["components"][0]["config"] |= {
        "seed": 3, "second": {"sampling": "instant"}, "voltage": {"sampling": "lowpass", "order": 3},
        "voltage_ref": {"sampling": "lowpass", "order": 8, "cutoff_hz": 1500.0}}
    data["events"] = [{"time": 0.00617, "target": "servo.I_V.gain", "value": 1.05},
                      {"time": 0.01234, "target": "servo.encoder.offset", "value": 0.001},
                      {"time": 0.01851, "target": "servo.scale.noise", "value": 1e-6},
                      {"time": 0.02468, "target": "servo.I_V.offset", "value": 0.3}]
    py, fast = run_both(monkeypatch, data)
    assert fast["loop"] == WITH_SERVO
    assert_identical(py, fast)
    names, x = fast["names"], fast["data"]
    i_u, i_v, i_w = (x[:, names.index(f"servo.I_{p}")] for p in "UVW")
    assert np.abs(i_u).max() > 1.0  # a real motion's currents went through both loops (A)
    before = x[:, 0] < 0.0061
    # the three phases sum to the sensors' noise alone before the gain fault on V (0.05 A each; 6 sigma)
    assert np.abs(i_u + i_v + i_w)[before].max() < 6 * 0.05 * np.sqrt(3)
    assert fast["reports"]["servo"]["channels"]["I_V"] == {"gain": 1.05, "offset": 0.3, "noise": 0.05}


def test_at_the_recording_rate_without_second_sensor(monkeypatch, vendor_pmsm_fmu, short_blocks):
    """The servo sensors at the recording rate (no oversampling) without a second current sensor: ``I_2``
    repeats ``I_U``, in both loops."""
    data = vendor_scenario(vendor_pmsm_fmu, 1)
    data |= {"stop_time": 0.03, "nc": {"program": MOVE}}
    data["components"][0]["config"] |= {"second_sensor_on": None}
    py, fast = run_both(monkeypatch, data)
    assert fast["loop"] == WITH_SERVO
    assert_identical(py, fast)
    names, x = fast["names"], fast["data"]
    np.testing.assert_array_equal(x[:, names.index("servo.I_2")], x[:, names.index("servo.I_U")])
    assert np.abs(x[:, names.index("servo.I_U")]).max() > 1.0  # the motion's currents (A)


def test_servo_sensors_feeding_the_nc_stay_in_python(monkeypatch, vendor_pmsm_fmu):
    """The NC's position loop closed on the linear scale: the NC holds its inputs over a compiled block, so the
    servo sensors step in Python (the loop says so) and the results are still the Python loop's."""
    data = vendor_scenario(vendor_pmsm_fmu, 1)
    data |= {"stop_time": 0.02, "nc": {"program": MOVE}, "connections": {"nc.position": "servo.x_lin"}}
    py, fast = run_both(monkeypatch, data)
    assert fast["loop"] == "compiled fine loop (plant FMU, sensors)"
    assert_identical(py, fast)
