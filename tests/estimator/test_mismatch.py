"""Model validation (paper IV.B.3): healthy motions pass, a fault appearing during the motion fails.

Plant data from the closed-loop CasADi model (see test_validation.py), parameters from the
estimator on the validated signals, as the monitor does.
"""
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from estimator.errors import EstimatorInputError
from estimator.estimate import MotionData, estimate_motion
from estimator.mismatch import check_model, residue_check

# the plant data of test_validation.py, loaded by path (test folders are not packages)
_spec = importlib.util.spec_from_file_location("validation_plant", Path(__file__).with_name("test_validation.py"))
_plant = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_plant)
FILTER, H, measure, plant_motion, validate = (_plant.FILTER, _plant.H, _plant.measure, _plant.plant_motion,
                                             _plant.validate)


def checked(changes=(), seed=1):
    v = validate(measure(plant_motion(changes), seed))
    est = estimate_motion(MotionData(H, v.u, v.i, v.w))
    return est, check_model(v.u, v.i, v.w, H, {k: p.value for k, p in est.parameters.items()}, FILTER)


def test_healthy_motion_passes():
    _, res = checked()
    assert res.passed and res.test == "ljung-box"
    assert res.checks["speed"].rms_relative < 1e-3 and res.checks["current"].rms_relative < 1e-3
    d = res.to_dict()
    assert set(d) >= {"test", "statistic", "p_value", "passed"} and d["passed"] is True


def test_friction_step_during_the_motion_is_a_mismatch():
    """Cd doubles at 1.6 s (between the two plateaus): one model cannot explain both halves."""
    est, res = checked((("Cd", 2.4, 1.6),))
    assert not res.passed
    speed = res.checks["speed"]
    assert not speed.passed and speed.p_value < 1e-3 and speed.rms_relative > 0.03
    assert res.checks["current"].passed  # the electrical part is unaffected
    assert res.p_value == speed.p_value and res.statistic == speed.statistic
    # the residue grows after the step: far larger in the second half than in the first
    r = speed.residue
    assert np.sqrt(np.mean(r[r.size // 2:] ** 2)) > 2 * np.sqrt(np.mean(r[: r.size // 2] ** 2))
    # parameters are still estimated and reported
    assert set(est.parameters) == {"R", "L", "K", "Jt", "ft", "Cd"}
    assert all(np.isfinite(p.value) for p in est.parameters.values())


def test_whiteness_and_size_rules():
    rng = np.random.default_rng(0)
    w = 70 * np.sin(np.linspace(0, 6, 40000))
    white = residue_check("speed", w + 0.05 * rng.standard_normal(w.size), w, H, 1e-3, 50.0, 10, 0.01)
    assert white.p_value > 1e-3 and white.passed
    slow = 3.0 * np.sin(np.linspace(0, 30, w.size))  # coloured and 1.5 % of the range
    coloured = residue_check("speed", w + slow, w, H, 1e-3, 50.0, 10, 0.01)
    assert coloured.p_value < 1e-6
    assert coloured.rms_relative == pytest.approx(np.sqrt(np.mean(slow**2)) / np.ptp(w + slow), rel=1e-12)
    assert not coloured.passed
    assert residue_check("speed", w + 0.1 * slow, w, H, 1e-3, 50.0, 10, 0.01).passed  # coloured but small


def test_bad_input_is_named():
    y = plant_motion()
    with pytest.raises(EstimatorInputError, match="Cd"):
        check_model(y["u"], y["i"], y["w"], H, {"R": 0.6, "L": 4e-3, "K": 1.05, "Jt": 0.1, "ft": 0.02}, FILTER)
    with pytest.raises(EstimatorInputError, match="blocks"):
        residue_check("speed", np.ones(1000), np.zeros(1000), H, 1e-3, 50.0, 10, 0.01)
