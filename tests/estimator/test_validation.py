"""Measurement validation on the real plant model with injected sensor faults (EQUATIONS.md section 6).

The plant is the closed-loop CasADi feed-drive model (``estimator.design.simulate_closed_loop``: RK4,
1e-5 s substeps, 10 kHz output) following a round-trip trapezoid 0 -> +70 -> 0 -> -70 -> 0 rad/s,
interpolated linearly inside each step; parameter steps during a motion use the same RK4 rollout.
Sensors apply eq. 9 (gain, offset, white noise) to its true signals; the encoder is quantised to
10000 counts/rev and differentiated. ``plant_motion`` and ``measure`` are loaded (by path) by the
other monitor tests.
"""
from __future__ import annotations

import functools

import numpy as np
import pytest

from feeddrive.estimator.design import simulate_closed_loop
from feeddrive.estimator.errors import EstimatorInputError
from feeddrive.estimator.filtering import FilterSpec
from feeddrive.estimator.simulation import rk4_step
from feeddrive.estimator.validation import (
    ValidationOptions,
    gain_ratio,
    model_reference,
    noise_std,
    residue_test,
    validate_measurements,
)
from feeddrive.models import feed_drive

H = 1e-4
ACCEL, W_MAX = 184.0, 70.0
FILTER = FilterSpec(100.0)
NOISE = {"Im1": 0.05, "Im2": 0.05, "u": 0.2, "u_ref": 0.2, "w_tach": 0.05}
COUNTS = 10000  # 2500 lines x 4
MODEL = feed_drive()
NOMINAL = MODEL.nominal()


def speed_reference(plateau: float = 0.8, rest: float = 0.1) -> np.ndarray:
    """Round-trip trapezoid w_ref [rad/s] at 10 kHz: rest, +70 plateau, rest, -70 plateau, rest."""
    ramp = W_MAX / ACCEL
    pieces = [(rest / 2, 0, 0), (ramp, 0, ACCEL), (plateau, W_MAX, 0), (ramp, W_MAX, -ACCEL), (rest, 0, 0),
              (ramp, 0, -ACCEL), (plateau, -W_MAX, 0), (ramp, -W_MAX, ACCEL), (rest / 2, 0, 0)]
    out = []
    for duration, w0, a in pieces:
        k = np.arange(int(round(duration / H)))
        out.append(w0 + a * k * H)
    return np.concatenate(out)


def _with_steps(w_ref: np.ndarray, params: dict, steps: list) -> dict:
    """The closed loop of ``simulate_closed_loop`` with parameter steps during the motion (which it holds
    constant): the same RK4 rollout, one parameter column per sample."""
    names = [v.name for v in MODEL.parameters]
    n = w_ref.size
    P = np.tile(np.array([(NOMINAL | params)[k] for k in names])[:, None], (1, n + 1))
    for name, value, t_change in steps:
        P[names.index(name), int(round(t_change / H)):] = value
    U = np.zeros((len(MODEL.inputs), n + 1))
    U[[v.name for v in MODEL.inputs].index("w_ref")] = np.append(w_ref, w_ref[-1])
    rollout = rk4_step(MODEL.rhs_function(), 10).mapaccum("rollout", n, [0], [0])
    X = np.hstack([np.zeros((len(MODEL.states), 1)),
                   np.asarray(rollout(np.zeros(len(MODEL.states)), np.vstack([U[:, :-1], U[:, 1:]]), P[:, :-1], H))])
    Y = np.asarray(MODEL.output_function().map(n + 1)(X, U, P))
    return {v.name: Y[k] for k, v in enumerate(MODEL.outputs)}


@functools.lru_cache(maxsize=16)
def _plant(changes: tuple, plateau: float) -> dict:
    w_ref = speed_reference(plateau)
    params = {name: value for name, value, t_change in changes if t_change <= 0}
    steps = [c for c in changes if c[2] > 0]
    out = _with_steps(w_ref, params, steps) if steps else simulate_closed_loop(w_ref, H, params)
    y = {k: v[1:] for k, v in out.items()}  # y[k] at (k + 1) h, after the k-th step of the reference
    for v in y.values():
        v.setflags(write=False)
    return y


def plant_motion(changes: tuple = (), plateau: float = 0.8) -> dict:
    """True plant signals ``u, u_ref, i, w, theta, ...`` (arrays (n,), read-only) of one motion.

    ``changes``: tuple of ``(parameter, value, time [s])`` parameter steps (value from ``time`` on).
    """
    return _plant(tuple(changes), plateau)


def measure(true: dict, seed: int, **faults: tuple[float, float]) -> dict:
    """Redundant measurements of eq. 9; ``faults``: sensor -> (gain, offset)."""
    rng = np.random.default_rng(seed)
    source = {"Im1": "i", "Im2": "i", "u": "u", "u_ref": "u_ref", "w_tach": "w"}
    out = {}
    for name, sig in source.items():
        a, b = faults.get(name, (1.0, 0.0))
        out[name] = a * true[sig] + b + NOISE[name] * rng.standard_normal(true[sig].size)
    a, b = faults.get("w_enc", (1.0, 0.0))
    theta_enc = np.floor(true["theta"] * COUNTS / (2 * np.pi)) * (2 * np.pi / COUNTS)
    out["w_enc"] = a * np.gradient(theta_enc, H) + b
    out["theta_enc"] = theta_enc
    return out


ELECTRICAL = {k: NOMINAL[k] for k in ("R", "L", "K")}


def validate(meas, electrical=ELECTRICAL):
    return validate_measurements(meas, H, electrical, FILTER)


def test_plant_motion_resembles_the_paper_bench():
    y = plant_motion()
    assert np.max(y["w"]) == pytest.approx(70.0, abs=2) and np.min(y["w"]) == pytest.approx(-70.0, abs=2)
    assert 15 < np.max(y["i"]) < 25 and -25 < np.min(y["i"]) < -10
    assert 70 < np.max(y["u"]) < 100


def test_healthy_sensors_pass_every_check():
    v = validate(measure(plant_motion(), seed=1))
    assert v.valid and v.sensor_faults == [] and v.reference == "last validated"
    for q, pair in v.pairs.items():
        assert pair.residue.kind == "none", q
        assert pair.fits == ()
        assert pair.gain_ratio == pytest.approx(1.0, abs=2e-3), q
    assert abs(v.pairs["current"].residue.offset) < 0.01
    # the passed-on current is the mean of the sensors: noise std 0.05 / sqrt(2)
    assert noise_std(v.i) == pytest.approx(0.05 / np.sqrt(2), rel=0.05)


def test_first_motion_uses_nominal_parameters_and_says_so():
    v = validate_measurements(measure(plant_motion(), seed=2, Im1=(1.0, 0.3)), H, None, FILTER)
    assert v.reference == "nominal" and any("nominal" in n for n in v.notes)
    assert [f.sensor for f in v.sensor_faults] == ["Im1"]


def test_offset_on_current_sensor_1_is_detected_isolated_and_sized():
    v = validate(measure(plant_motion(), seed=3, Im1=(1.0, 0.3)))
    cur = v.pairs["current"]
    assert cur.residue.kind == "offset"
    assert cur.residue.offset_ci95[0] < 0.3 < cur.residue.offset_ci95[1]
    f1, f2 = cur.fits
    assert f1.faulty and f1.kind == "offset" and not f2.faulty
    assert f1.offset_ci95[0] < 0.3 < f1.offset_ci95[1] and f1.offset == pytest.approx(0.3, abs=0.02)
    assert f1.gain == pytest.approx(1.0, abs=2e-3)
    assert cur.trusted == "Im2" and cur.valid and v.valid
    np.testing.assert_array_equal(v.i, measure(plant_motion(), seed=3)["Im2"])
    assert v.pairs["voltage"].residue.kind == "none" and v.pairs["speed"].residue.kind == "none"


def test_gain_on_current_sensor_2_is_detected_isolated_and_sized():
    v = validate(measure(plant_motion(), seed=4, Im2=(1.03, 0.0)))
    cur = v.pairs["current"]
    assert cur.residue.kind == "gain"
    assert cur.residue.gain_diff == pytest.approx(-0.03, abs=2e-3)
    assert cur.relative_gain_error == pytest.approx(1 - 1 / 1.03, abs=1e-3)  # eq. 11, 12
    f1, f2 = cur.fits
    assert f2.faulty and f2.kind == "gain" and not f1.faulty
    assert f2.gain_ci95[0] < 1.03 < f2.gain_ci95[1] and f2.gain == pytest.approx(1.03, abs=3e-3)
    assert cur.trusted == "Im1" and v.valid


def test_gain_and_offset_on_both_current_sensors():
    """All four sized; sensor 1 has the smaller error and is trusted, corrected; not valid."""
    a1, b1, a2, b2 = 1.02, 0.2, 0.96, -0.25
    true = plant_motion()
    v = validate(measure(true, seed=5, Im1=(a1, b1), Im2=(a2, b2)))
    cur = v.pairs["current"]
    assert cur.residue.kind == "gain+offset"
    assert cur.residue.gain_diff == pytest.approx(a1 - a2, abs=3e-3)
    assert cur.residue.offset == pytest.approx(b1 - b2, abs=0.03)
    f1, f2 = cur.fits
    for fit, a, b in ((f1, a1, b1), (f2, a2, b2)):
        assert fit.faulty and fit.kind == "gain+offset"
        assert fit.gain == pytest.approx(a, abs=3e-3) and fit.offset == pytest.approx(b, abs=0.03)
        assert fit.gain_ci95[0] < a < fit.gain_ci95[1] and fit.offset_ci95[0] < b < fit.offset_ci95[1]
    assert cur.trusted == "Im1" and not cur.valid and not v.valid
    # the corrected current follows the true one to well within the fault size
    err = (FILTER.apply({"i": v.i - true["i"]}, H)["i"])[200:-200]
    assert np.sqrt(np.mean(err**2)) < 0.1 * f1.error_rms


def test_tachometer_gain_fault_is_isolated_against_the_encoder():
    v = validate(measure(plant_motion(), seed=6, w_tach=(1.02, 0.0)))
    speed = v.pairs["speed"]
    assert speed.residue.kind == "gain" and speed.residue.gain_diff == pytest.approx(0.02, abs=2e-3)
    tach, enc = speed.fits
    assert tach.faulty and tach.kind == "gain" and tach.gain == pytest.approx(1.02, abs=3e-3)
    assert not enc.faulty and speed.trusted == "w_enc" and v.valid
    assert v.pairs["current"].residue.kind == "none"


@pytest.mark.parametrize("sensor", ["w_tach", "Im2"])
def test_a_sensor_mounted_the_other_way_round_is_a_gain_of_minus_one(sensor):
    # the pair's mean cancelled: the residue test saw no level, passed the pair as healthy and the mean (~0)
    # on to the estimator (a reversed tachometer read as "not enough excitation, |speed| < 0.002 rad/s")
    v = validate(measure(plant_motion(), seed=6, **{sensor: (-1.0, 0.0)}))
    pair = v.pairs["speed" if sensor == "w_tach" else "current"]
    assert pair.residue.kind == "gain" and pair.residue.gain_diff == pytest.approx(-2.0, abs=2e-3)
    fit = {f.sensor: f for f in pair.fits}
    assert fit[sensor].faulty and fit[sensor].gain == pytest.approx(-1.0, abs=3e-3)
    assert pair.trusted != sensor and not fit[pair.trusted].faulty and v.valid


def test_noise_alone_is_never_read_as_a_reversed_sensor():
    # a level taken from the pair's half difference would make r = x1 - x2 exactly -2 times it: a certain
    # "gain -1" on every noise-only pair that happens to correlate negatively; only a strong anti-correlation counts
    rng = np.random.default_rng(11)
    for _ in range(20):
        x1, x2 = 0.05 * rng.standard_normal(20000), 0.05 * rng.standard_normal(20000)
        assert residue_test(x1, x2, H).kind == "none" or float(x1 @ x2) >= 0
        assert abs(residue_test(x1, x2, H).gain_diff) < 1.0


def test_voltage_reference_offset_is_isolated():
    v = validate(measure(plant_motion(), seed=7, u_ref=(1.0, 2.0)))
    volt = v.pairs["voltage"]
    assert volt.residue.kind == "offset" and volt.residue.offset == pytest.approx(-2.0, abs=0.05)
    u, u_ref = volt.fits
    assert u_ref.faulty and u_ref.kind == "offset" and u_ref.offset == pytest.approx(2.0, abs=0.1)
    assert u_ref.offset_ci95[0] < 2.0 < u_ref.offset_ci95[1]
    assert not u.faulty and volt.trusted == "u" and v.valid


def test_model_reference_reconstructs_each_quantity_from_the_two_others():
    y = plant_motion()
    f = FILTER.apply({"u": y["u"], "i": y["i"], "w": y["w"]}, H)
    edge = slice(200, -200)
    for q, s in (("current", "i"), ("voltage", "u"), ("speed", "w")):
        err = model_reference(q, f, H, ELECTRICAL)[edge] - f[s][edge]
        assert np.max(np.abs(err)) < 0.005 * np.max(np.abs(f[s])), q


def test_no_false_alarm_on_noise_only_residues():
    """60 seeds of two healthy noisy sensors. With the size tolerances out of the way (1e-12), the tests
    alone decide: their p-values are calibrated (about uniform) and at alpha = 1e-3 at most one of the
    60 x 2 tests rejects; with the default tolerances, no alarm at all."""
    level = plant_motion()["i"]
    bare = ValidationOptions(gain_tol=1e-12, offset_tol=1e-12)
    p_values, alarms = [], 0
    for seed in range(60):
        rng = np.random.default_rng(seed)
        x1, x2 = (level + 0.05 * rng.standard_normal(level.size) for _ in range(2))
        assert residue_test(x1, x2, H).kind == "none"
        res = residue_test(x1, x2, H, bare)
        p_values += [res.p_gain, res.p_offset]
        alarms += res.kind != "none"
    assert alarms <= 1
    below = np.mean(np.array(p_values) < 0.2)  # 24 of 120 expected; binomial sd ~4.4
    assert 0.08 < below < 0.35, below


def test_gain_ratio_is_eq_12():
    x = np.sin(np.linspace(0, 20, 5000)) * 10 + 3
    assert gain_ratio(0.99 * x + 0.5, x) == pytest.approx(0.99, rel=1e-12)


def test_bad_input_is_named():
    meas = measure(plant_motion(), seed=8)
    with pytest.raises(EstimatorInputError, match="Im1 and Im2"):
        validate_measurements({**meas, "Im2": meas["Im2"][:-1]}, H, ELECTRICAL, FILTER)
    with pytest.raises(EstimatorInputError, match="'u'"):
        validate_measurements({k: v for k, v in meas.items() if k != "u"}, H, ELECTRICAL, FILTER)
    with pytest.raises(EstimatorInputError, match="windows"):
        residue_test(np.ones(100), np.ones(100), H)
    with pytest.raises(EstimatorInputError, match="alpha"):
        ValidationOptions(alpha=0.7)


def test_missing_redundancy_passes_the_sensor_on_with_a_note():
    meas = measure(plant_motion(), seed=9)
    v = validate_measurements({**meas, "u_ref": None}, H, ELECTRICAL, FILTER)
    volt = v.pairs["voltage"]
    assert volt.residue is None and volt.trusted == "u" and volt.valid and "unchecked" in volt.notes[0]
    np.testing.assert_array_equal(v.u, meas["u"])


def test_gain_ratio_is_the_mean_of_the_kept_quotients_bit_for_bit():
    """Eq. 12's ratio from every quotient gathered once: the bits of ``mean(d1[keep] / d2[keep])``, also with
    samples of the second signal at its mean (a quotient by zero, left out)."""
    rng = np.random.default_rng(8)
    for step in (1, 3):
        x2 = np.sin(np.linspace(0, 9, 3001)) + 0.01 * rng.standard_normal(3001)
        x2[::7] = x2[::step].mean()  # d2 == 0 there
        x1 = 1.02 * x2 + 0.01 * rng.standard_normal(3001)
        a, b = x1[::step], x2[::step]
        d1, d2 = a - a.mean(), b - b.mean()
        keep = np.abs(d2) > 0.2 * np.max(np.abs(d2))
        assert gain_ratio(x1, x2, step) == float(np.mean(d1[keep] / d2[keep]))
