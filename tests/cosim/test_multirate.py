"""Three rates: the recording step, the plant's oversampling and the NC's cycle; the sensors as an acquisition chain.

Analytic checks: the NC's command is a staircase of the NC cycle whose values are the position loop's
law at the breakpoints; an interval mean of a held-input signal is exact for piecewise-linear signals;
the anti-aliasing filter has the analog Butterworth's step response; events land on the finest grid.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy import signal

from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.master import Master
from feeddrive.cosim.nc import NCConfig, plan_program
from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import scenario_from_dict
from feeddrive.cosim.sensors import SensorsComponent, interval_mean_weights
from feeddrive.models import feed_drive

EXAMPLE = Path(__file__).parents[2] / "examples" / "tool_change.yaml"
TRUTH = feed_drive().nominal()
QUIET = {"noise": 0.0}
U = 2  # the sensors' voltage output


def sensors_run(config: dict, true: np.ndarray, m: int, h: float) -> np.ndarray:
    """Sensors stepped at h/m over ``true`` (N m, 5) fine samples (t_k+1); returns the N + 1 recorded samples."""
    s = SensorsComponent("sensors", config, oversample=m)
    s.setup(0.0, h / m, len(true))
    out = [list(s.get_outputs())]
    for k, row in enumerate(true.tolist()):
        s.set_inputs(row)
        s.step(k)
        if (k + 1) % m == 0:
            out.append(list(s.get_outputs()))
    return np.array(out)


@pytest.mark.parametrize("m", [1, 2, 3, 4, 5, 10])
def test_interval_mean_is_exact_for_held_input_jumps(m):
    """A signal that jumps at every t_n (held inputs) and is a polynomial inside each interval (linear for m = 2,
    quadratic for m = 3, cubic from m = 4): the sample is the exact mean over [t_n, t_(n+1)] (the plain mean of
    the sub-samples would be off by slope h / (2 m))."""
    h, n = 1e-4, 50
    k = np.arange(1, n * m + 1)
    t = k * h / m
    interval = (k - 1) // m  # the sub-sample at t_n + j h/m, j = 1..m, belongs to interval n
    jump = np.sin(interval)  # the value just after t_n
    slope = 3e3 * np.cos(interval)
    tau = t - interval * h
    curve = 2e7 * (m >= 3) * tau ** 2 + 1e11 * (m >= 4) * tau ** 3
    v = jump + slope * tau + curve
    true = np.column_stack([v, v, v, v, np.zeros_like(v)])
    y = sensors_run({"seed": 0, "current": [QUIET, QUIET], "voltage": QUIET, "voltage_ref": QUIET,
                     "tachometer": QUIET}, true, m, h)
    exact = np.sin(np.arange(n)) + 3e3 * np.cos(np.arange(n)) * h / 2 + 2e7 * (m >= 3) * h ** 2 / 3 \
        + 1e11 * (m >= 4) * h ** 3 / 4
    if m == 1:  # one sub-sample: the instantaneous sample at t_(n+1), as before the acquisition chain
        exact = v
    np.testing.assert_allclose(y[1:, U], exact, rtol=0, atol=1e-11)
    assert math.isclose(sum(interval_mean_weights(m)), m)


def test_instant_and_lowpass_sampling():
    """instant: the value at t_(n+1); lowpass: a 2nd-order Butterworth at 1 kHz run at h/m, whose sampled step
    response is the analog filter's within 0.2 % of the step (the first fine sample of the step is at h/m and
    the bilinear discretisation puts the step midway, at h / (2 m))."""
    h, m, n = 1e-4, 10, 40
    true = np.ones((n * m, 5))
    true[:, 0] = np.arange(1, n * m + 1)  # the voltage: a ramp, to see the instant
    cfg = {"seed": 0, "current": [{"noise": 0, "sampling": "lowpass", "cutoff_hz": 1000.0}, QUIET],
           "voltage": {"noise": 0, "sampling": "instant"}, "voltage_ref": QUIET, "tachometer": QUIET}
    y = sensors_run(cfg, true, m, h)
    np.testing.assert_array_equal(y[1:, U], np.arange(1, n + 1) * m)
    b, a = signal.butter(2, 2 * np.pi * 1000.0, analog=True)
    _, analog = signal.step((b, a), T=np.arange(2 * n * m + 2) * h / m / 2)
    analog = analog[2 * m * np.arange(1, n + 1) - 1]  # at t_(n+1) - h / (2 m)
    assert np.abs(y[1:, 0] - analog).max() < 2e-3
    assert y[5, 0] < 0.99  # it is a filter: the step is not there yet after 0.4 ms ...
    np.testing.assert_allclose(y[1:, 1], 1.0)  # ... where the plain mean of a constant is the constant


def test_rate_keys_are_checked(feeddrive_fmu):
    data = yaml.safe_load(EXAMPLE.read_text())
    data["plant"]["oversample"] = 4
    data["nc"]["cycle"] = 3.3e-5  # not a multiple of 2.5e-5
    with pytest.raises(ScenarioError, match=r"nc\.cycle: 3\.3e-05 s is not an integer multiple of the plant's step"):
        scenario_from_dict(data)
    data["nc"]["cycle"] = 2e-3
    assert scenario_from_dict(data).nc_cycle_ticks() == 80
    data["plant"]["oversample"] = 0
    with pytest.raises(ScenarioError, match=r"plant\.oversample"):
        scenario_from_dict(data)
    with pytest.raises(ScenarioError, match=r"cutoff_hz"):
        SensorsComponent("sensors", {"voltage": {"cutoff_hz": 100.0}})


def test_events_land_on_the_finest_grid(feeddrive_fmu):
    """An event at 3.45 ms with a 1 ms recording step and oversample 10 lands on tick 35 (3.5 ms), not on the
    4 ms recording instant: a sensor offset then acts on the sample measured at 4 ms, not on the one at 3 ms."""
    data = yaml.safe_load(EXAMPLE.read_text())
    data.pop("monitor")
    data |= {"stop_time": 0.01, "step": 1e-3}
    data["plant"]["oversample"] = 10
    data["sensors"] = {"seed": 0, "current": [QUIET, QUIET], "voltage": {"noise": 0, "sampling": "instant"},
                       "voltage_ref": QUIET, "tachometer": QUIET}
    data["events"] = [{"time": 3.45e-3, "target": "sensors.u.offset", "value": 5.0}]
    master = Master.from_scenario(scenario_from_dict(data))
    master.setup()
    assert master._events[0][0] == 35  # tick 35 of 1e-4 s
    with master:
        sig = master.run().signals()
    offset = sig["sensors.u"] - sig["plant.voltage"]
    np.testing.assert_allclose(offset[:4], 0.0, atol=1e-12)  # samples at t <= 3 ms
    np.testing.assert_allclose(offset[4:], 5.0, atol=1e-12)  # the sample at 4 ms, after the 3.5 ms event


@pytest.fixture(scope="module")
def cycle_run(tmp_path_factory, feeddrive_fmu):
    """The tool change with a 2 ms NC cycle on the built-in plant (10 kHz recording, default noise)."""
    data = yaml.safe_load(EXAMPLE.read_text())
    data["nc"]["cycle"] = 2e-3
    data["monitor"] = {"db": ":memory:"}
    scenario = scenario_from_dict(data)
    return scenario, run_scenario(scenario, tmp_path_factory.mktemp("cycle"), plots=False)


def test_nc_cycle_is_a_staircase_of_the_position_law(cycle_run):
    """speed_ref over [t_j, t_j + c] is (x_plan(t_j + c) - x_plan(t_j)) / c + kv (x_plan(t_j) - x(t_j)), converted
    to rad/s, with x(t_j) the plant's position at the breakpoint; it is constant between breakpoints."""
    scenario, run = cycle_run
    sig, h, c = run.signals, scenario.step, 20
    w = sig["nc.speed_ref"]
    rows = (len(w) - 1) // c * c
    blocks = w[1:rows + 1].reshape(-1, c)
    np.testing.assert_array_equal(blocks, blocks[:, :1].repeat(c, axis=1))  # held for the whole cycle
    segs = plan_program(scenario.nc)
    starts = np.array([s[0] for s in segs])

    def x_plan(t):
        s = segs[np.searchsorted(starts, t + 1e-12, side="right") - 1]
        tau = t - s[0]
        return s[1] + tau * (s[2] + 0.5 * s[3] * tau)

    cfg: NCConfig = scenario.nc
    conv = 2 * math.pi * cfg.belt_ratio / cfg.pitch
    j = np.arange(blocks.shape[0])
    expected = [((x_plan((k + 1) * c * h) - x_plan(k * c * h)) / (c * h)
                 + cfg.kv * (x_plan(k * c * h) - sig["plant.position"][k * c])) * conv for k in j]
    np.testing.assert_allclose(blocks[:, 0], expected, rtol=1e-9, atol=1e-9 * np.abs(w).max())
    assert np.abs(w).max() > 60  # a real rapid


def test_nc_cycle_motion_is_validated_with_every_ci_covering_the_truth(cycle_run):
    _, run = cycle_run
    (motion,) = run.report["motions"]
    assert motion["validated"], motion["notes"]
    for name in ("R", "L", "K", "Jt", "ft", "Cd"):
        lo, hi = motion["parameters"][name]["ci95"]
        assert lo <= TRUTH[name] <= hi, (name, motion["parameters"][name])


def test_model_exchange_interval_means_are_exact(feeddrive_fmu):
    """interface me with oversample > 1: the plant's ``current_mean`` and ``speed_mean`` are the exact means over
    each step (CVode integrates them with the states): loops bypassed, Cd = 0, a held voltage staircase, against
    the matrix exponential of the linear ODE augmented with the integrals."""
    from scipy.linalg import expm

    from feeddrive.cosim.fmu_adapter import FMUComponent
    from feeddrive.cosim.scenario import MapEntry, PlantConfig

    R, L, K, J, ft = (TRUTH[n] for n in ("R", "L", "K", "Jt", "ft"))
    h, n = 1e-4, 400
    cfg = PlantConfig(fmu=str(feeddrive_fmu), interface="me", oversample=2, input_hold="zoh",
                      parameters={"bypass": 1.0, "Cd": 0.0},
                      map={"speed_ref": MapEntry(var="u_in"), "current": MapEntry(var="i"), "speed": MapEntry(var="w")})
    plant = FMUComponent("plant", cfg)
    plant.setup(0.0, h, n)
    try:
        names = plant.output_names
        assert names[-2:] == ("current_mean", "speed_mean")
        got = []
        for k in range(n):
            plant.set_inputs([24.0 + 3.0 * math.sin(k / 7)])
            plant.step(k)
            y = plant.get_outputs()
            got.append([y[names.index("current_mean")], y[names.index("speed_mean")]])
    finally:
        plant.terminate()
    M = np.zeros((5, 5))  # x = [i, w, Qi, Qw, u]
    M[:2, :2] = [[-R / L, -K / L], [K / J, -ft / J]]
    M[0, 4] = 1 / L
    M[2, 0] = M[3, 1] = 1.0
    step, x, exact = expm(M * h), np.zeros(5), []
    for k in range(n):
        x = step @ np.array([x[0], x[1], 0.0, 0.0, 24.0 + 3.0 * math.sin(k / 7)])
        exact.append(x[2:4] / h)
    exact = np.array(exact)
    np.testing.assert_allclose(np.array(got), exact, rtol=0, atol=2e-5 * np.abs(exact).max())


@pytest.mark.parametrize("interface, rtol", [("cs", 1e-12), ("me", 2e-5)])
def test_first_order_hold_ramps_over_the_whole_nc_cycle(feeddrive_fmu, interface, rtol):
    """Inputs changing every 5 plant steps (an NC cycle): with foh the plant sees the ramp with the slope of the
    last two cycle values over the whole cycle, so u_in = a + b t_j set at the cycle starts t_j is the ramp
    a + b t itself (from the second cycle on) and the current is the exact solution of the linear ODE."""
    from scipy.linalg import expm

    from feeddrive.cosim.fmu_adapter import FMUComponent
    from feeddrive.cosim.scenario import MapEntry, PlantConfig

    R, L, K, J, ft = (TRUTH[n] for n in ("R", "L", "K", "Jt", "ft"))
    h, n, r, a, b = 1e-4, 1000, 5, 24.0, 20.0
    cfg = PlantConfig(fmu=str(feeddrive_fmu), interface=interface, parameters={"bypass": 1.0, "Cd": 0.0},
                      map={"speed_ref": MapEntry(var="u_in"), "current": MapEntry(var="i"),
                           "speed": MapEntry(var="w")}, input_hold="foh")
    plant = FMUComponent("plant", cfg, input_period=r)
    plant.setup(0.0, h, n)
    try:
        got = []
        for k in range(n):
            plant.set_inputs([a + b * (k - k % r) * h])  # held between the cycle starts, as the master does
            plant.step(k)
            got.append(plant.get_outputs()[:2])
    finally:
        plant.terminate()
    M = np.zeros((4, 4))
    M[:2, :2] = [[-R / L, -K / L], [K / J, -ft / J]]
    M[0, 2], M[2, 3] = 1 / L, 1.0
    step, x, exact = expm(M * h), np.zeros(4), []
    for k in range(n):  # the first cycle has slope 0 (no previous value): the held a
        x = step @ np.array([x[0], x[1], a + b * k * h if k >= r else a, 0.0 if k < r else b])
        exact.append(x[:2])
    exact = np.array(exact)
    assert np.all(np.abs(np.array(got) - exact).max(axis=0) <= rtol * np.abs(exact).max(axis=0))


def test_lowpass_cutoff_is_checked_against_the_plant_step(tmp_path, feeddrive_fmu):
    path = tmp_path / "s.yaml"
    data = yaml.safe_load(EXAMPLE.read_text())
    data["plant"]["oversample"] = 2
    data["sensors"]["voltage"] = {"sampling": "lowpass", "cutoff_hz": 9.5e3}
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    from feeddrive.cosim.scenario import load_scenario

    with pytest.raises(ScenarioError, match=r"s\.yaml:\d+: sensors\.voltage\.cutoff_hz: 9500 Hz: expected a cut-off "
                                            r"below 9000 Hz"):
        load_scenario(path)


def test_model_exchange_sensors_sample_the_exact_interval_mean(feeddrive_fmu):
    """interface me, oversample 4, loops bypassed (the NC's command drives u_in, held over each recording
    step), Cd = 0: the sensors' mean current over each 1 ms recording interval is the exact mean of the
    linear ODE's current (matrix exponential), through the master's wiring of ``current_mean``."""
    from scipy.linalg import expm

    data = yaml.safe_load(EXAMPLE.read_text())
    data.pop("monitor")
    data |= {"step": 1e-3, "stop_time": 0.1}
    data["plant"] = {"fmu": "builtin", "interface": "me", "oversample": 4, "input_hold": "zoh",
                     "parameters": {"bypass": 1.0, "Cd": 0.0},
                     # the NC's command drives the voltage on purpose: 1 V per rad/s, stated (u_in is in V)
                     "map": {"speed_ref": {"var": "u_in", "unit": "1", "scale": 1.0}}}
    data["nc"]["program"] = [{"rapid": {"to": 0.01}}]
    data["sensors"] = {"seed": 0, "current": [QUIET, QUIET], "voltage": QUIET, "voltage_ref": QUIET,
                       "tachometer": QUIET}
    with Master.from_scenario(scenario_from_dict(data)) as master:
        sig = master.run().signals()
    assert "plant.current_mean" in sig
    R, L, K, J, ft = (TRUTH[n] for n in ("R", "L", "K", "Jt", "ft"))
    h = 1e-3
    M = np.zeros((5, 5))  # x = [i, w, Qi, Qw, u]
    M[:2, :2] = [[-R / L, -K / L], [K / J, -ft / J]]
    M[0, 4] = 1 / L
    M[2, 0] = M[3, 1] = 1.0
    step, x, exact = expm(M * h), np.zeros(5), []
    for u in sig["nc.speed_ref"][1:]:  # the command over [t_n, t_(n+1)], shown at t_(n+1)
        x = step @ np.array([x[0], x[1], 0.0, 0.0, u])
        exact.append(x[2] / h)
    exact = np.array(exact)
    assert np.abs(exact).max() > 1.0  # the current moves (A)
    np.testing.assert_allclose(sig["sensors.Im1"][1:], exact, rtol=0, atol=2e-5 * np.abs(exact).max())
    assert np.abs(sig["plant.current"][1:] - exact).max() > 100 * 2e-5 * np.abs(exact).max()  # not the instant
