"""Model adequacy from a recording's own residue (estimator/adequacy.py; issue 22 item 5).

The records are the closed-loop plant of test_validation.py (the model itself, 10 kHz, round trip at
70 rad/s) with one sensor per quantity, and three unmodelled effects built from it:

* a commanded voltage through a nonlinear amplifier, ``u_eff = 0.0041 V^2 + 0.68 V - 0.096``: the record
  holds the command V (the drive is rescaled so that the command stays within +-20 V, see ``S``);
* a gravity torque ``m g l cos(theta / 50 + 0.3)`` (1 N.m at the motor, a 50:1 gear) that the speed loop
  compensates: the same speed, the current and voltage carry the load;
* a current that drifts with speed at constant torque: the sensor reads ``i (1 - 0.1 |w| / 70)``.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from feeddrive.estimator.adequacy import check_adequacy, check_motion
from feeddrive.estimator.errors import EstimatorInputError
from feeddrive.estimator.motion import EstimationOptions, MotionData

_spec = importlib.util.spec_from_file_location("validation_plant", Path(__file__).parent / "test_validation.py")
plant = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(plant)
H = plant.H
NOMINAL = plant.NOMINAL
#: voltage scale of the amplifier case: u / S, i * S with R / S^2, L / S^2, K / S obeys the same model
S = 8.0
AMPLIFIER = (0.0041, 0.68, -0.096)


def record(seed: int, true: dict | None = None) -> dict:
    """One sensor per quantity: ``u`` [V], ``i`` [A], ``w`` [rad/s] of the plant (or of ``true``)."""
    m = plant.measure(true if true is not None else plant.plant_motion(), seed)
    return {"u": m["u"], "i": m["Im1"], "w": m["w_tach"]}


def amplifier_record(seed: int) -> dict:
    """The command V of a nonlinear amplifier whose output is the (rescaled) drive's terminal voltage."""
    r = record(seed)
    a, b, c = AMPLIFIER
    u_eff = r["u"] / S
    command = (-b + np.sqrt(b * b - 4 * a * (c - u_eff))) / (2 * a)
    assert np.all(np.isfinite(command)) and np.abs(command).max() < 20
    return {"u": command, "i": r["i"] * S, "w": r["w"]}


def gravity_record(seed: int) -> dict:
    true = dict(plant.plant_motion())
    load = 1.0 * np.cos(true["theta"] / 50.0 + 0.3) / NOMINAL["K"]  # [A]: m g l cos(theta_link) / K
    true["i"] = true["i"] + load
    true["u"] = true["u"] + NOMINAL["R"] * load + NOMINAL["L"] * np.gradient(load, H)
    return record(seed, true)


def drift_record(seed: int) -> dict:
    r = record(seed)
    true = plant.plant_motion()
    r["i"] = r["i"] - 0.1 * np.abs(true["w"]) / 70.0 * true["i"]
    return r


@pytest.fixture(scope="module")
def healthy():
    return [check_adequacy(H, **record(seed)) for seed in range(100)]


def test_healthy_records_pass_at_the_stated_level(healthy):
    """False alarms: p > 0.05 on at least 95 of 100 seeds (measured: 97), and no verdict is a mismatch
    (the few significant lacks of fit are below 1 % of the output)."""
    p = np.array([r.p_value for r in healthy])
    assert np.all(np.isfinite(p))
    assert (p > 0.05).sum() >= 95
    assert all(r.verdict == "adequate" for r in healthy)


@pytest.mark.parametrize("build, equation, term", [
    (amplifier_record, "electrical", ("amplifier nonlinearity (u^2)", "offset (constant)")),
    (gravity_record, "mechanical", None),
    (drift_record, "mechanical", None),
])
def test_unmodelled_effects_are_a_mismatch(build, equation, term):
    for seed in (1, 2, 3):
        res = check_adequacy(H, **build(seed))
        assert res.verdict == "model mismatch" and res.p_value < 0.01, res.line()
        assert res.equations[equation].p_value < 0.01 / 2
        assert res.equations[equation].effect >= 0.01
        if term:  # the amplifier's map has both a square and an offset
            assert res.equations[equation].strongest in term
        assert "MODEL MISMATCH" in res.line() and "nan" not in res.line().lower()


def test_too_little_excitation_is_not_a_mismatch():
    """The constant-speed plateau alone (no acceleration): Jt is not determined, the check has no power;
    it says so and never "mismatch" (10 seeds)."""
    w = plant.plant_motion()["w"]
    fast = np.flatnonzero(w > 69.9)
    part = slice(fast[0] + 200, fast[-1] - 200)
    for seed in range(10):
        r = {k: v[part] for k, v in record(seed).items()}
        res = check_adequacy(H, **r)
        assert res.verdict == "not enough excitation", res.line()
        assert "Jt" in res.equations["mechanical"].undetermined
        assert "not enough excitation" in res.line() and "MISMATCH" not in res.line()


def test_torque_only_and_known_parameters():
    """A torque signal and a speed: only the mechanical equation is tested. A wrong known K is a mismatch
    (the logged command taken for the terminal voltage is the same situation: quanser_aero2)."""
    r = record(4)
    res = check_adequacy(H, w=r["w"], torque=NOMINAL["K"] * r["i"])
    assert set(res.equations) == {"mechanical"} and res.verdict == "adequate"
    assert res.equations["mechanical"].output == "torque"
    assert check_adequacy(H, **r, known={"R": NOMINAL["R"], "K": NOMINAL["K"]}).verdict == "adequate"
    wrong = check_adequacy(H, **r, known={"R": NOMINAL["R"], "K": 1.1 * NOMINAL["K"]})
    assert wrong.verdict == "model mismatch" and wrong.equations["electrical"].p_value < 1e-6


def test_check_motion_takes_the_estimators_data():
    r = record(5)
    data = MotionData(H, u=r["u"], i=r["i"], w=r["w"])
    res = check_motion(data, EstimationOptions())
    assert res.verdict == "adequate" and res.alpha == 0.01
    d = res.to_dict()
    assert d["verdict"] == "adequate" and set(d["equations"]) == {"electrical", "mechanical"}


def test_bad_input_and_short_records():
    r = record(6)
    with pytest.raises(EstimatorInputError, match="speed w is required"):
        check_adequacy(H, u=r["u"], i=r["i"])
    with pytest.raises(EstimatorInputError, match="finite"):
        check_adequacy(H, w=np.r_[r["w"][:-1], np.nan], torque=r["i"])
    with pytest.raises(EstimatorInputError, match="alpha"):
        check_adequacy(H, **r, alpha=0.7)
    short = check_adequacy(H, **{k: v[:50] for k, v in r.items()})
    assert short.verdict == "not enough excitation" and short.p_value is None and "too short" in short.reason
