"""The built-in plant FMU against analytic solutions, in Co-Simulation and Model Exchange."""
from __future__ import annotations

import math
from ctypes import c_double, c_int, c_size_t, c_uint, c_void_p

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu
from scipy.linalg import expm

from feeddrive.fmu_build import DEFAULT_CS_SUBSTEP
from feeddrive.models import feed_drive

NOMINAL = feed_drive().nominal()
R, L, K, Jt, ft, Cd = (NOMINAL[n] for n in ("R", "L", "K", "Jt", "ft", "Cd"))
U_STEP = 24.0  # V, well below u_max
OPEN_LOOP = {"bypass": 1.0, "Cd": 0.0, "u_in": U_STEP}
H = 1e-4  # communication step [s]


def open_loop_exact(t: np.ndarray, z0=(0.0, 0.0, 0.0), R: float = R) -> np.ndarray:
    """Exact (i, w, theta) of the linear drive (Cd = 0) under a constant voltage U_STEP; shape (len(t), 3)."""
    A = np.array([[-R / L, -K / L, 0, U_STEP / L],
                  [K / Jt, -ft / Jt, 0, 0],
                  [0, 1, 0, 0],
                  [0, 0, 0, 0]])
    z = np.array([*z0, 1.0])
    return np.array([expm(A * tk) @ z for tk in t])[:, :3]


def simulate(fmu, kind: str, start: dict[str, float], stop: float, dt: float = 1e-3):
    return simulate_fmu(str(fmu), fmi_type=kind, start_values=start, stop_time=stop, output_interval=dt,
                        relative_tolerance=1e-10, output=["i", "w", "theta", "u", "u_ref", "i_ref", "x"])


def max_rel_error(actual: np.ndarray, expected: np.ndarray) -> float:
    return float(np.max(np.abs(actual - expected)) / np.max(np.abs(expected)))


def test_validates_and_declares_the_model_variables(feeddrive_fmu):
    assert validate_fmu(str(feeddrive_fmu)) == []
    md = read_model_description(str(feeddrive_fmu))
    by_causality: dict[str, set[str]] = {}
    for v in md.modelVariables:
        by_causality.setdefault(v.causality, set()).add(v.name)
    assert by_causality["input"] == {"w_ref", "Tl", "u_in"}
    assert by_causality["output"] == {"u", "u_ref", "i", "w", "theta", "x", "i_ref"}
    model = feed_drive()
    assert by_causality["parameter"] == {v.name for v in model.parameters} | {"cs_substep"}
    variables = {v.name: v for v in md.modelVariables}
    for v in model.parameters:  # unit, start and variability straight from models/
        assert variables[v.name].unit == v.unit
        assert float(variables[v.name].start) == v.nominal
        assert variables[v.name].variability == ("tunable" if v.tunable else "fixed")
    assert float(variables["cs_substep"].start) == DEFAULT_CS_SUBSTEP
    assert md.coSimulation.canGetAndSetFMUstate and md.modelExchange.canGetAndSetFMUstate
    assert [variables[f"der({s.name})"].derivative.name for s in model.states] == [s.name for s in model.states]


@pytest.mark.parametrize("kind", ["CoSimulation", "ModelExchange"])
def test_open_loop_voltage_step_matches_matrix_exponential(feeddrive_fmu, kind):
    res = simulate(feeddrive_fmu, kind, OPEN_LOOP, stop=0.3)
    exact = open_loop_exact(res["time"])
    for k, name in enumerate(("i", "w", "theta")):
        assert max_rel_error(res[name], exact[:, k]) < 1e-6, name
    assert np.all(res["u"] == U_STEP)


@pytest.mark.parametrize("kind", ["CoSimulation", "ModelExchange"])
def test_closed_loop_steady_state_balances_both_equations(feeddrive_fmu, kind):
    w_ref = 50.0
    res = simulate(feeddrive_fmu, kind, {"w_ref": w_ref}, stop=3.0)
    i, w, u = res["i"][-1], res["w"][-1], res["u"][-1]
    assert w == pytest.approx(w_ref, rel=1e-6)
    assert i == pytest.approx((ft * w + Cd) / K, rel=1e-6)  # mechanical eq. 2 with dw/dt = 0
    assert u == pytest.approx(R * i + K * w, rel=1e-6)  # electrical eq. 1 with di/dt = 0
    assert res["x"][-1] == pytest.approx(res["theta"][-1] / (2 * math.pi) * NOMINAL["pitch"], rel=1e-12)
    assert np.max(res["i_ref"]) == pytest.approx(NOMINAL["i_max"])  # the speed step saturates the current


def test_co_simulation_and_model_exchange_agree(feeddrive_fmu):
    """A 60 rad/s step saturates both loops; the saturation corners inside an RK4 substep lower its
    order (3.7e-5 relative at the default 1e-5 s substep), so CS runs at 1e-6 s substeps here."""
    start = {"w_ref": 60.0, "Tl": 2.0}
    cs = simulate(feeddrive_fmu, "CoSimulation", {**start, "cs_substep": 1e-6}, stop=1.0)
    me = simulate(feeddrive_fmu, "ModelExchange", start, stop=1.0)
    np.testing.assert_array_equal(cs["time"], me["time"])
    for name in ("i", "w", "u"):
        assert max_rel_error(cs[name], me[name]) < 1e-5, name


def test_substep_count_is_robust_to_grid_rounding(instance):
    """h = (n+1) dt - n dt in floating point must not add a substep: the result equals one clean step."""
    a, b = instance(**OPEN_LOOP), instance(**OPEN_LOOP)
    t1, t2 = 0.3, 0.3 + 1e-4
    a.fmu.doStep(0.0, t1)
    b.fmu.doStep(0.0, t1)
    a.fmu.doStep(t1, t2 - t1)  # 1.0000000000000286e-4
    b.fmu.doStep(t1, 1e-4)
    np.testing.assert_allclose(a.get("i", "w"), b.get("i", "w"), rtol=1e-12)


def test_cs_substep_sets_the_number_of_rk4_substeps(instance):
    """One step of 1e-4 s with cs_substep 5e-5 is two RK4 substeps: the same as two steps of one substep."""
    two_in_one = instance(init=False, cs_substep=5e-5, w_ref=30.0)
    one_each = instance(init=False, cs_substep=1.0, w_ref=30.0)
    for sim in (two_in_one, one_each):
        sim.fmu.enterInitializationMode()
        sim.fmu.exitInitializationMode()
    two_in_one.fmu.doStep(0.0, 1e-4)
    one_each.fmu.doStep(0.0, 5e-5)
    one_each.fmu.doStep(5e-5, 5e-5)
    np.testing.assert_array_equal(two_in_one.get("i", "w", "xi_w", "xi_i"), one_each.get("i", "w", "xi_w", "xi_i"))
    assert two_in_one.get("i")[0] > 0.1


def test_resistance_step_mid_run_takes_effect_at_that_time(instance):
    sim = instance(**OPEN_LOOP)
    n1, n2 = 500, 1500  # R changes at t1 = n1 H; compared up to t2 = n2 H
    for n in range(n1):
        sim.fmu.doStep(n * H, H)
    z1 = sim.get("i", "w", "theta")
    di_before = sim.get("der(i)")[0]
    sim.set(R=2 * R)
    di_after = sim.get("der(i)")[0]
    assert di_after - di_before == pytest.approx(-R * z1[0] / L, rel=1e-12)  # slope jump -dR i / L
    rows = []
    for n in range(n1, n2):
        sim.fmu.doStep(n * H, H)
        rows.append(sim.get("i", "w", "theta"))
    exact = open_loop_exact(np.arange(1, n2 - n1 + 1) * H, z0=z1, R=2 * R)
    for k in range(3):
        assert max_rel_error(np.array(rows)[:, k], exact[:, k]) < 1e-6


@pytest.mark.parametrize("serialize", [False, True])
def test_fmu_state_round_trip_continues_bit_identically(instance, serialize):
    sim = instance(w_ref=40.0, Tl=1.0)
    for n in range(300):
        sim.fmu.doStep(n * H, H)
    state = sim.fmu.getFMUstate()
    if serialize:
        state = sim.fmu.deSerializeFMUstate(sim.fmu.serializeFMUstate(state))

    def run() -> np.ndarray:
        rows = []
        for n in range(300, 600):
            sim.fmu.doStep(n * H, H)
            rows.append(sim.get("i", "w", "theta", "u", "i_ref"))
        return np.array(rows)

    first = run()
    sim.fmu.setFMUstate(state)
    np.testing.assert_array_equal(run(), first)
    sim.fmu.freeFMUstate(state)


def _trajectory(sim, steps: int = 200) -> np.ndarray:
    rows = []
    for n in range(steps):
        sim.fmu.doStep(n * H, H)
        rows.append(sim.get("i", "w", "u"))
    return np.array(rows)


BAD_SETS = [
    ("R", 0.0, "R = 0 is out of range (R > 0 required)"),
    ("L", -1.0, "L = -1 is out of range (L > 0 required)"),
    ("Jt", 0.0, "Jt = 0 is out of range (Jt > 0 required)"),
    ("u_in", math.nan, "u_in = nan is not a finite number"),
    ("w_ref", math.inf, "w_ref = inf is not a finite number"),
]


@pytest.mark.parametrize("name,value,message", BAD_SETS)
def test_bad_value_is_rejected_with_a_log_message_and_no_effect(instance, name, value, message):
    clean, sim = instance(**OPEN_LOOP), instance(**OPEN_LOOP)
    with pytest.raises(FMICallException, match="fmi2SetReal failed with status 3"):
        sim.set(**{name: value})
    assert sim.log == [f"fmi2SetReal: {message}"]
    after = _trajectory(sim)
    assert np.all(np.isfinite(after))
    np.testing.assert_array_equal(after, _trajectory(clean))


def test_fixed_parameter_is_checked_and_set_before_initialisation(instance):
    sim = instance(init=False)
    with pytest.raises(FMICallException):
        sim.set(bypass=2.0)
    assert sim.log == ["fmi2SetReal: bypass = 2 is out of range (bypass <= 1 required)"]
    sim.set(**OPEN_LOOP)
    sim.fmu.enterInitializationMode()
    sim.fmu.exitInitializationMode()
    sim.fmu.doStep(0.0, 0.1)
    np.testing.assert_allclose(sim.get("i", "w", "theta"), open_loop_exact(np.array([0.1]))[0], rtol=1e-6)


def test_every_strict_lower_bound_of_the_model_is_enforced(instance):
    sim = instance()
    strict = [v for v in feed_drive().parameters if v.lower_strict]
    assert {"R", "L", "K", "Jt"} <= {v.name for v in strict}
    for v in strict:
        with pytest.raises(FMICallException):
            sim.set(**{v.name: v.lower})
    assert len(sim.log) == len(strict)
    np.testing.assert_array_equal(sim.get(*[v.name for v in strict]), [v.nominal for v in strict])


def test_unknown_value_reference_and_misuse_are_errors(instance):
    sim = instance()
    with pytest.raises(FMICallException):
        sim.fmu.setReal([9999], [1.0])
    with pytest.raises(FMICallException):
        sim.fmu.getReal([9999])
    with pytest.raises(FMICallException):
        sim.set(bypass=1.0)  # fixed parameter after initialisation
    with pytest.raises(FMICallException):
        sim.set(u=1.0)  # calculated output
    n = len(sim.vr)
    assert sim.log == [
        f"fmi2SetReal: unknown value reference 9999 (this FMU has 0..{n - 1})",
        f"fmi2GetReal: unknown value reference 9999 (this FMU has 0..{n - 1})",
        "fmi2SetReal: bypass can only be set before the end of initialisation (fixed parameter)",
        "fmi2SetReal: u is calculated by the FMU and cannot be set",
    ]
    assert np.all(np.isfinite(_trajectory(sim, 10)))


def test_a_step_that_would_produce_nan_is_rolled_back(instance):
    """Jt = 1e-300 is inside the model's bounds (Jt > 0) but makes dw/dt overflow to inf."""
    sim = instance(w_ref=10.0)
    sim.fmu.doStep(0.0, H)
    before = sim.get("i", "w", "theta", "xi_w", "xi_i")
    sim.set(Jt=1e-300)
    with pytest.raises(FMICallException, match="fmi2DoStep"):
        sim.fmu.doStep(H, H)
    assert sim.log == [f"fmi2DoStep: the state became non-finite in [{H:g}, {2 * H:g}] s; step rejected, "
                       "state unchanged"]
    np.testing.assert_array_equal(sim.get("i", "w", "theta", "xi_w", "xi_i"), before)


def test_model_exchange_derivatives_are_the_paper_equations(instance):
    sim = instance("me", w_ref=30.0, Tl=0.5, T0=0.3)
    x = (c_double * 6)(2.0, 10.0, 1.0, 0.4, 3.0, 30.0)  # i, w, theta, xi_w, xi_i, w_rf
    sim.fmu.setContinuousStates(x, 6)
    dx = (c_double * 6)()
    sim.fmu.getDerivatives(dx, 6)
    i, w = 2.0, 10.0
    u = sim.get("u")[0]
    assert dx[0] == pytest.approx((u - R * i - K * w) / L, rel=1e-12)  # eq. 1
    assert dx[1] == pytest.approx((K * i - ft * w - Cd * math.tanh(w / NOMINAL["w_eps"]) - 0.5 - 0.3) / Jt,
                                  rel=1e-12)  # eq. 2 with Tl and T0
    assert dx[2] == w
    assert list(sim.get("der(i)", "der(w)")) == [dx[0], dx[1]]
    x[1] = math.nan
    with pytest.raises(FMICallException):
        sim.fmu.setContinuousStates(x, 6)
    assert sim.log == ["fmi2SetContinuousStates: a state is not a finite number"]


# -- input interpolation (Co-Simulation): fmi2SetRealInputDerivatives --------------------------------

U_SLOPE = 200.0  # V/s: u_in ramps from U_STEP to 84 V over 0.3 s


def open_loop_ramp_exact(t: np.ndarray) -> np.ndarray:
    """Exact (i, w, theta) of the linear drive under u_in = U_STEP + U_SLOPE t; shape (len(t), 3).
    The ramp is the augmented state (1, t): d(1)/dt = 0, dt/dt = 1."""
    A = np.zeros((5, 5))
    A[:3, :3] = [[-R / L, -K / L, 0], [K / Jt, -ft / Jt, 0], [0, 1, 0]]
    A[0, 3:] = U_STEP / L, U_SLOPE / L
    A[4, 3] = 1.0
    return np.array([expm(A * tk) @ [0, 0, 0, 1, 0] for tk in t])[:, :3]


def _ramp(sim, steps: int, derivative_every_step: bool = True, foh: bool = True) -> np.ndarray:
    """Set u_in = U_STEP + U_SLOPE t_n before every step n (and its slope if ``foh``); rows (i, w, theta)."""
    rows = []
    for n in range(steps):
        sim.set(u_in=U_STEP + U_SLOPE * n * H)
        if foh and (derivative_every_step or n == 0):
            sim.fmu.setRealInputDerivatives([sim.vr["u_in"]], [1], [U_SLOPE])
        sim.fmu.doStep(n * H, H)
        rows.append(sim.get("i", "w", "theta"))
    return np.array(rows)


def test_input_derivative_makes_a_ramp_exact(instance, feeddrive_fmu):
    """u_in given by value + slope at each step: the analytic solution of the linear ODE with a ramp input
    to 1e-6; the same values held over each step (no derivative) are off by the staircase, ~U_SLOPE h / 2."""
    assert read_model_description(str(feeddrive_fmu)).coSimulation.canInterpolateInputs
    steps = 3000
    exact = open_loop_ramp_exact(np.arange(1, steps + 1) * H)
    foh, zoh = _ramp(instance(**OPEN_LOOP), steps), _ramp(instance(**OPEN_LOOP), steps, foh=False)
    for k, name in enumerate(("i", "w", "theta")):
        assert max_rel_error(foh[:, k], exact[:, k]) < 1e-6, name
        assert max_rel_error(zoh[:, k], exact[:, k]) > 1e-4, name


def test_a_derivative_stays_set_until_the_next_derivative_call(instance):
    """fmi2SetReal keeps the input's derivative (FMI 2.0: a value stays until its setter is called again):
    one slope set before the first step gives the same run as setting it before every step."""
    every, once = instance(**OPEN_LOOP), instance(**OPEN_LOOP)
    np.testing.assert_array_equal(_ramp(once, 200, derivative_every_step=False), _ramp(every, 200))


@pytest.mark.parametrize("serialize", [False, True])
def test_fmu_state_holds_the_input_derivatives(instance, serialize):
    sim = instance(**OPEN_LOOP)
    _ramp(sim, 100)
    state = sim.fmu.getFMUstate()
    if serialize:
        state = sim.fmu.deSerializeFMUstate(sim.fmu.serializeFMUstate(state))

    def run() -> np.ndarray:  # value only: the slope comes from the state
        rows = []
        for n in range(100, 200):
            sim.set(u_in=U_STEP + U_SLOPE * n * H)
            sim.fmu.doStep(n * H, H)
            rows.append(sim.get("i", "w", "theta", "u"))
        return np.array(rows)

    first = run()
    sim.fmu.setRealInputDerivatives([sim.vr["u_in"]], [1], [-5 * U_SLOPE])
    sim.fmu.setFMUstate(state)
    np.testing.assert_array_equal(run(), first)
    sim.fmu.freeFMUstate(state)
    np.testing.assert_allclose(first[:, 0], open_loop_ramp_exact(np.arange(101, 201) * H)[:, 0], rtol=1e-6)


def test_reset_clears_the_input_derivatives(instance):
    sim, clean = instance(**OPEN_LOOP), instance(**OPEN_LOOP)
    sim.fmu.setRealInputDerivatives([sim.vr["u_in"], sim.vr["w_ref"]], [1, 1], [U_SLOPE, 3.0])
    for s in (sim, clean):
        s.fmu.reset()
        s.fmu.setupExperiment(startTime=0.0)
        s.set(**OPEN_LOOP)
        s.fmu.enterInitializationMode()
        s.fmu.exitInitializationMode()
    np.testing.assert_array_equal(_trajectory(sim), _trajectory(clean))


BAD_DERIVATIVES = [
    ("u_in", 2, 1.0, "order 2 for u_in; this FMU interpolates inputs linearly (order 1 only)"),
    ("u_in", 0, 1.0, "order 0 for u_in; this FMU interpolates inputs linearly (order 1 only)"),
    ("R", 1, 1.0, "R is not an input"),
    ("u", 1, 1.0, "u is not an input"),
    ("w_ref", 1, math.nan, "der(w_ref) = nan is not a finite number"),
    ("Tl", 1, -math.inf, "der(Tl) = -inf is not a finite number"),
    (9999, 1, 1.0, "unknown value reference 9999 (this FMU has 0..{last})"),
]


@pytest.mark.parametrize("name,order,value,message", BAD_DERIVATIVES)
def test_bad_input_derivative_is_rejected_with_a_log_message_and_no_effect(instance, name, order, value, message):
    clean, sim = instance(**OPEN_LOOP), instance(**OPEN_LOOP)
    good = [sim.vr["u_in"]]  # all or nothing: the good entry before the bad one is not applied either
    vr = name if isinstance(name, int) else sim.vr[name]
    with pytest.raises(FMICallException, match="fmi2SetRealInputDerivatives failed with status 3"):
        sim.fmu.setRealInputDerivatives(good + [vr], [1, order], [U_SLOPE, value])
    assert sim.log == ["fmi2SetRealInputDerivatives: " + message.format(last=len(sim.vr) - 1)]
    np.testing.assert_array_equal(_trajectory(sim), _trajectory(clean))


def test_model_exchange_has_no_input_derivatives(instance):
    sim = instance("me")  # fmpy's FMU2Model has no wrapper for this Co-Simulation function: call the symbol
    status = sim.fmu.dll.fmi2SetRealInputDerivatives(c_void_p(sim.fmu.component), (c_uint * 1)(sim.vr["u_in"]),
                                                     c_size_t(1), (c_int * 1)(1), (c_double * 1)(1.0))
    assert status == 3  # fmi2Error
    assert sim.log == ["fmi2SetRealInputDerivatives: a Co-Simulation function, this instance is Model Exchange"]
