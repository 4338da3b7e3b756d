"""A slow, poorly exciting but healthy tool change through the whole co-simulation: validated, no mismatch.

At 0.02 m/s (6.3 rad/s, 10.5 s of motion; the standard tool change runs at 70 rad/s) viscous and dry
friction are hard to tell apart, so ft and Cd come out with wide intervals, and the open-loop speed
simulation of the model check integrates their error over seconds. The check must accept it: the
estimate's sensitivities are nuisance regressors of its tests (estimator/mismatch.py).
The motion is replayed through ``MonitorPipeline`` on the recorded sensor signals (what ``cosim monitor``
does with a recording) to compare the band with the effect of the actual parameter error.
"""
from __future__ import annotations

import numpy as np
import pytest

from feeddrive.cosim.monitor import MEASUREMENTS, MonitorConfig, MonitorPipeline, centred_speed
from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import scenario_from_dict
from feeddrive.estimator.history import History
from feeddrive.estimator.mismatch import check_model, check_signals

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
    """Validated with the 95 % CIs of the given parameters covering the plant's values; friction poorly
    determined: ft (its interval was +-40 % or more when the monitor gave every parameter) is refused with
    its reason, the model check runs on the model as fitted; neither the independence nor the size test
    rejects."""
    m, _ = slow_run
    assert m["error"] is None and m["measurements_valid"] and m["sensor_faults"] == []
    assert m["end"] - m["start"] == pytest.approx(10.5, abs=0.01)
    assert m["validated"] and m["diagnosis"] == []
    assert not any("mismatch" in n for n in m["notes"])
    p = m["parameters"]
    assert set(m["refused"]) == {"ft", "Cd"} and set(p) | set(m["refused"]) == set(TRUTH), m["refused"]
    assert m["refused"]["ft"].startswith("too narrow a speed range: |w| within [6.2"), m["refused"]
    for name, value in TRUTH.items():
        if name in p:
            assert p[name]["ci95"][0] <= value <= p[name]["ci95"][1], (name, p[name])
    mm = m["mismatch"]
    assert mm["passed"] and mm["p_value"] >= mm["alpha"] == 0.01
    assert "Bonferroni over 5 tests" in mm["rule"]
    assert mm["checks"]["speed"]["peak"]["p_value"] > 0.002
    for check in mm["checks"].values():
        assert check["independence"]["p_value"] > 0.002 and check["size"]["p_value"] > 0.002
        assert check["rms"] < check["noise_std"]


def test_replay_reproduces_the_run_and_the_true_model_passes(slow_run):
    """``MonitorPipeline`` on the recorded signals gives the run's numbers; the plant's true parameters
    pass the same check."""
    m, trace = slow_run
    assert trace.result["parameters"] == m["parameters"]
    assert trace.result["mismatch"] == m["mismatch"]
    v = trace.validation
    inputs, instruments, noise = check_signals(v, trace.signals)
    # the first sensors against the second as instruments; the measured noise is the sensors' own
    assert set(instruments) == {"u", "i", "w"} and inputs["i"] is not v.i
    assert noise["current"] == pytest.approx(0.05, rel=0.05) and noise["speed"] == pytest.approx(0.05, rel=0.05)
    truth = check_model(inputs["u"], inputs["i"], inputs["w"], H, TRUTH, MonitorConfig().filter, 0.01,
                        noise=noise, noise_dof=v.i.size, instruments=instruments)
    assert truth.passed, truth.to_dict()
    # the validated speed (the mean with the differentiated encoder) carries the encoder's quantisation,
    # aliased by the sampling into the filter's band: a structured error the test rightly rejects
    averaged = check_model(v.u, v.i, v.w, H, TRUTH, MonitorConfig().filter, 0.01, noise=noise, noise_dof=v.i.size)
    assert averaged.checks["speed"].tests["independence"].p_value < 1e-6
