"""Redundant sensors: eq. 9 statistics recovered, determinism, encoder quantisation, faults at the event step."""
import math

import numpy as np
import pytest

from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.sensors import BLOCK, SensorsComponent, SensorsConfig

IM1, IM2, U, U_REF, W_TACH, THETA_ENC, W_ENC, X = range(8)
QUIET = {"current": [{"noise": 0}, {"noise": 0}], "voltage": {"noise": 0}, "voltage_ref": {"noise": 0},
         "tachometer": {"noise": 0}}


def run(config, true, h=1e-4, events=None):
    """Drive the sensors in the master's call order with ``true`` (N, 5) inputs; returns (N + 1, 8) outputs.

    ``true[n]`` are the plant outputs at t_{n+1} (the plant is stepped before the sensors);
    ``events`` maps a step n to [(name, value)] applied before ``set_inputs`` of step n.
    """
    s = SensorsComponent("sensors", config)
    s.setup(0.0, h, len(true))
    ys = [list(s.get_outputs())]
    for n, values in enumerate(true.tolist()):
        for name, value in (events or {}).get(n, []):
            s.set_parameter(name, value)
        s.set_inputs(values)
        s.step(n)
        ys.append(list(s.get_outputs()))
    return np.array(ys)


def plant_signals(n, h=1e-4):
    """Smooth true signals (voltage, voltage_ref, current, speed, position) of an out-and-back motion."""
    t = np.arange(1, n + 1) * h
    w = 70 * np.sin(2 * np.pi * t / (n * h))
    current = 20 * np.cos(2 * np.pi * t / (n * h)) + 2
    voltage = 1.05 * w + 0.6 * current
    position = 0.02 / (2 * np.pi) * np.cumsum(w) * h
    return np.column_stack([voltage, voltage + 0.5, current, w, position])


def test_gain_offset_noise_recovered_by_regression():
    n = 3 * BLOCK + 123  # crosses noise blocks
    true = plant_signals(n)
    cfg = {"seed": 7, "current": [{"gain": 1.03, "offset": 0.2, "noise": 0.05}, {"gain": 0.99, "offset": -0.1,
                                                                                  "noise": 0.08}],
           "voltage": {"gain": 0.98, "offset": 1.5, "noise": 0.2}, "voltage_ref": {"noise": 0.1},
           "tachometer": {"gain": 1.01, "offset": -0.3, "noise": 0.05}}
    y = run(cfg, true)[1:]
    checks = [(IM1, 2, 1.03, 0.2, 0.05), (IM2, 2, 0.99, -0.1, 0.08), (U, 0, 0.98, 1.5, 0.2),
              (U_REF, 1, 1.0, 0.0, 0.1), (W_TACH, 3, 1.01, -0.3, 0.05)]
    residuals = []
    for out, inp, gain, offset, noise in checks:
        phi = np.column_stack([true[:, inp], np.ones(n)])
        (g, b), *_ = np.linalg.lstsq(phi, y[:, out], rcond=None)
        r = y[:, out] - phi @ [g, b]
        sigma = r.std(ddof=2)
        se = sigma * np.sqrt(np.diag(np.linalg.inv(phi.T @ phi)))
        assert abs(g - gain) < 5 * se[0] and abs(b - offset) < 5 * se[1], out
        assert abs(sigma - noise) < 5 * noise / np.sqrt(2 * n), out  # std of a sample std
        assert abs(np.corrcoef(r[1:], r[:-1])[0, 1]) < 5 / np.sqrt(n), out  # white
        residuals.append(r)
    assert abs(np.corrcoef(residuals[0], residuals[1])[0, 1]) < 5 / np.sqrt(n)  # independent sensors


def test_deterministic_for_a_seed_and_different_for_another():
    true = plant_signals(BLOCK + 500)
    a, b = run({"seed": 3}, true), run({"seed": 3}, true)
    np.testing.assert_array_equal(a, b)
    c = run({"seed": 4}, true)
    assert np.all(a[:, :W_TACH + 1] != c[:, :W_TACH + 1])
    # the noise sequence does not depend on the levels: doubling a channel's noise doubles its deviation
    loud = run({"seed": 3, "current": [{"noise": 0.1}, {"noise": 0.05}]}, true)
    quiet = run({"seed": 3, "current": [{"noise": 0.0}, {"noise": 0.05}]}, true)
    np.testing.assert_allclose(loud[:, IM1] - quiet[:, IM1], 2 * (a[:, IM1] - quiet[:, IM1]), atol=1e-12)
    np.testing.assert_array_equal(loud[:, IM2], a[:, IM2])


def test_encoder_quantisation_position_and_speed_window():
    lines, pitch, belt, h = 1000, 0.01, 2.0, 1e-4
    q = 2 * math.pi / (4 * lines)
    conv = 2 * math.pi * belt / pitch
    n = 3000
    v = 0.005  # m/s: 6.3 rad/s at the motor, 0.4 counts per step
    position = 0.05 + v * np.arange(1, n + 1) * h
    true = np.zeros((n, 5))
    true[:, 4] = position
    cfg = {**QUIET, "encoder": {"lines": lines, "pitch": pitch, "belt_ratio": belt, "speed_window": 2e-3}}
    y = run(cfg, true, h)[1:]
    theta = conv * position
    counts = y[:, THETA_ENC] / q
    np.testing.assert_allclose(counts, np.round(counts), rtol=0, atol=1e-9)  # whole counts
    assert np.all(np.abs(y[:, THETA_ENC] - theta) <= q / 2 + 1e-12)  # nearest count
    np.testing.assert_allclose(np.diff(np.unique(np.round(counts))), 1.0)  # every count seen: step = q
    np.testing.assert_allclose(y[:, X], y[:, THETA_ENC] / conv, rtol=1e-15)
    w = 20  # 2 ms / 0.1 ms
    np.testing.assert_allclose(y[w:, W_ENC], (y[w:, THETA_ENC] - y[:-w, THETA_ENC]) / (w * h), rtol=1e-12)
    assert np.all(y[:w, W_ENC] == (y[:w, THETA_ENC] - y[0, THETA_ENC]) / (w * h))  # window starts at rest
    assert np.all(np.abs(y[w:, W_ENC] - conv * v) <= q / (w * h) + 1e-9)  # resolution 2 pi / (4 lines W h)


def test_channels_measure_their_own_true_signal():
    true = np.array([[50.0, 51.0, 10.0, 40.0, 0.1]])
    cfg = {"current": [{"gain": 2.0, "noise": 0}, {"gain": 3.0, "noise": 0}], "voltage": {"gain": 5.0, "noise": 0},
           "voltage_ref": {"gain": 7.0, "noise": 0}, "tachometer": {"gain": 11.0, "noise": 0}}
    y = run(cfg, true)
    np.testing.assert_allclose(y[1, :W_TACH + 1], [20.0, 30.0, 250.0, 357.0, 440.0], rtol=1e-15)
    assert y[1, X] == pytest.approx(0.1, abs=0.02 / 10000)  # 2500 lines on the model's 20 mm pitch
    np.testing.assert_array_equal(y[0], [0.0] * 8)  # t0: nothing measured yet


def test_fault_takes_effect_at_the_event_step():
    n, k = 2000, 1234
    true = plant_signals(n)
    events = {k: [("Im1.gain", 1.03), ("Im2.offset", 0.25), ("w_tach.noise", 0.1)]}
    y = run({**QUIET, "seed": 5}, true, events=events)
    healthy = run({**QUIET, "seed": 5}, true)
    noisy = run({**QUIET, "seed": 5, "tachometer": {"noise": 0.1}}, true)
    # outputs at t_0..t_k are measured before the event; from t_{k+1} (inputs of step k) on, after it
    np.testing.assert_array_equal(y[:k + 1], healthy[:k + 1])
    np.testing.assert_allclose(y[k + 1:, IM1], 1.03 * true[k:, 2], rtol=1e-15)
    np.testing.assert_allclose(y[k + 1:, IM2], true[k:, 2] + 0.25, rtol=1e-15)
    np.testing.assert_array_equal(y[k + 1:, W_TACH], noisy[k + 1:, W_TACH])
    s = SensorsComponent("sensors", {})
    s.setup(0.0, 1e-4, 1)
    s.set_parameter("encoder.offset", 0.5)
    assert s.report()["channels"]["encoder"]["offset"] == 0.5


@pytest.mark.parametrize("name, value, message", [
    ("Im3.gain", 1.0, "sensors.Im3.gain: expected <channel>.<field> with channel in Im1, Im2, u, u_ref"),
    ("Im1.slope", 1.0, "sensors.Im1.slope: expected <channel>.<field>"),
    ("Im1.noise", -0.1, "sensors.Im1.noise: expected a finite number >= 0"),
    ("u.offset", "high", "sensors.u.offset: expected a number, got 'high'"),
    ("u.gain", float("inf"), "sensors.u.gain: expected a finite number"),
])
def test_bad_event_names_the_target(name, value, message):
    s = SensorsComponent("sensors", None)
    s.setup(0.0, 1e-4, 10)
    with pytest.raises(ScenarioError, match="^" + message.replace(".", r"\.")):
        s.set_parameter(name, value)


@pytest.mark.parametrize("section, message", [
    ({"current": [{"noise": 0.1}]}, "sensors.current[1]: required key is missing"),
    ({"current": [{}, {}, {}]}, "sensors.current: Tuple should have at most 2 items"),
    ({"voltage": {"noise": -0.2}}, "sensors.voltage.noise: must be >= 0"),
    ({"tachometer": {"gain": float("nan")}}, "sensors.tachometer.gain: Input should be a finite number"),
    ({"encoder": {"lines": 0}}, "sensors.encoder.lines: must be > 0"),
    ({"encoder": {"pitch": -0.02}}, "sensors.encoder.pitch: must be > 0"),
    ({"tacho": {}}, "sensors.tacho: unknown key"),
    ({"seed": "one"}, "sensors.seed: Input should be a valid integer"),
    ({"seed": -1}, "sensors.seed: must be >= 0"),
])
def test_bad_config_names_the_key(section, message):
    with pytest.raises(ScenarioError) as info:
        SensorsComponent("sensors", section)
    assert str(info.value).startswith(message)


def test_defaults_documented():
    cfg = SensorsConfig.parse(None, "sensors")
    assert [c.noise for c in cfg.channels().values()] == [0.05, 0.05, 0.2, 0.2, 0.05, 0.0]
    partial = SensorsConfig.parse({"current": [{"gain": 1.03}, {}], "voltage": {"offset": 1.0}}, "sensors")
    assert partial.channels() == {**cfg.channels(), "Im1": partial.current[0], "u": partial.voltage}
    assert (partial.current[0].noise, partial.voltage.noise) == (0.05, 0.2)  # omitted keys keep their default
    assert (cfg.encoder.lines, cfg.encoder.pitch, cfg.encoder.belt_ratio) == (2500, 0.02, 1.0)
