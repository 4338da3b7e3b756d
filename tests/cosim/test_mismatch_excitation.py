"""A slow, poorly exciting but healthy tool change through the whole co-simulation: validated, no mismatch.

At 0.02 m/s (6.3 rad/s, 10.5 s of motion; the standard tool change runs at 70 rad/s) viscous and dry
friction are hard to tell apart, so ft and Cd come out with wide intervals, and the open-loop speed
simulation of the model check integrates their error over seconds. The check must accept it: the
residue is judged against rms_tol plus the band the estimate's covariance allows (estimator/mismatch.py).
The motion is replayed through ``MonitorPipeline`` on the recorded sensor signals (what ``cosim monitor``
does with a recording) to compare the band with the effect of the actual parameter error.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from feeddrive.cosim.monitor import MEASUREMENTS, MonitorConfig, MonitorPipeline, centred_speed
from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import scenario_from_dict
from feeddrive.estimator.history import History
from feeddrive.estimator.mismatch import check_model, window_rms

pytestmark = pytest.mark.slow

TRUTH = {"R": 0.6, "L": 4.0e-3, "K": 1.05, "Jt": 0.1, "ft": 0.02, "Cd": 1.2}
H = 1e-4
WINDOW = 500  # 50 ms
SPEED_THRESHOLD = 2.0  # [rad/s]


@pytest.fixture(scope="module")
def slow_run(tmp_path_factory, feeddrive_fmu):
    """examples/tool_change.yaml out to 0.1 m at 0.02 m/s, 0.2 m/s^2: its report and the replayed trace."""
    scenario = scenario_from_dict({
        "name": "slow-tool-change", "axis": "X", "step": H,
        "plant": {"fmu": "builtin", "parameters": TRUTH},
        "sensors": {"seed": 1, "current": [{"noise": 0.05}, {"noise": 0.05}]},
        "nc": {"program": [{"dwell": {"time": 0.2}},
                           {"tool_change": {"position": 0.1, "v_max": 0.02, "accel": 0.2, "time": 0.3}}]},
        # the former absolute speed threshold (2 rad/s of this 6.3 rad/s motion): it keeps friction poorly
        # determined, which is what this test is about; the default (3 % of the peak speed) gives ft +-30 %
        "monitor": {"db": ":memory:", "speed_threshold": SPEED_THRESHOLD}})
    run = run_scenario(scenario, tmp_path_factory.mktemp("slow") / "run", plots=False)
    (motion,) = run.report["motions"]
    rows = np.flatnonzero(run.signals["nc.state"] == 1)
    signals = {k: run.signals[f"sensors.{k}"][rows] for k in MEASUREMENTS}
    signals["w_enc"] = centred_speed(signals["theta_enc"], signals["w_enc"], H, MonitorConfig().encoder_window_s)
    with History(":memory:") as history:
        trace = MonitorPipeline(MonitorConfig(speed_threshold=SPEED_THRESHOLD), history, "X").process(signals, H, motion["start"], 1, 0.0)
    return motion, trace


def test_slow_healthy_motion_is_validated(slow_run):
    """Validated with the 95 % CIs of all six parameters covering the plant's values; friction poorly
    determined (ft +-48 %); the speed residue is coloured (Ljung-Box rejects it) but within the band."""
    m, _ = slow_run
    assert m["error"] is None and m["measurements_valid"] and m["sensor_faults"] == []
    assert m["end"] - m["start"] == pytest.approx(10.5, abs=0.01)
    assert m["validated"] and m["diagnosis"] == []
    assert not any("mismatch" in n for n in m["notes"])
    p = m["parameters"]
    for name, value in TRUTH.items():
        assert p[name]["ci95"][0] <= value <= p[name]["ci95"][1], (name, p[name])
    ft = p["ft"]
    assert (ft["ci95"][1] - ft["ci95"][0]) / 2 > 0.4 * ft["value"]
    mm = m["mismatch"]
    assert mm["passed"] and mm["test"] == "size" and mm["p_value"] < 1e-3
    assert mm["band_factor"] == {"speed": pytest.approx(np.sqrt(stats.chi2.isf(1e-3, 4))),
                                 "current": pytest.approx(np.sqrt(stats.chi2.isf(1e-3, 3)))}
    assert mm["statistic"] == max(mm["excess_relative"].values()) < 0.5 * 0.01
    # the worst speed window is of the order of rms_tol; beyond the band, a small fraction of it is left
    assert mm["excess_relative"]["speed"] < 0.1 * mm["peak_rms_relative"]["speed"]


def test_band_covers_the_parameter_error(slow_run):
    """The replay reproduces the run's numbers, and the speed the plant's true parameters give differs from
    the estimate's by at most c = 4.30 times the band's RMS in every 50 ms window (the simultaneous bound
    of estimator/mismatch.py; 1.6 times here) while that difference reaches 0.95 % of the range: the band,
    not rms_tol, accepts it. The true parameters' own residue stays below 0.3 % of the range (0.23 %)."""
    m, trace = slow_run
    assert trace.result["parameters"] == m["parameters"]
    assert trace.result["mismatch"] == m["mismatch"]
    v, speed = trace.validation, trace.mismatch.checks["speed"]
    truth = check_model(v.u, v.i, v.w, H, TRUTH, MonitorConfig().filter).checks["speed"]
    inner = slice(WINDOW, -WINDOW)
    span = np.ptp(speed.simulated + speed.residue)
    effect = window_rms((truth.simulated - speed.simulated)[inner], WINDOW)
    assert np.max(effect / window_rms(speed.band[inner], WINDOW)) < speed.band_factor
    assert np.max(effect) / span > 0.006
    assert truth.peak_rms_relative < 0.003
