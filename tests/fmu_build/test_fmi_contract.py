"""The wrapper's FMI 2.0 contract: the state machine, FMU-state headers, the substep bounds and
non-finite results. Every refused call is checked for its log message and for changing nothing: the
instance then continues exactly like an untouched one."""
from __future__ import annotations

import math
import struct
from ctypes import c_double, c_int, c_size_t, c_uint, c_void_p

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from test_plant_fmu import OPEN_LOOP, H, _trajectory, open_loop_exact  # same directory, on sys.path

from feeddrive.fmu_build import MAX_SUBSTEPS, MIN_CS_SUBSTEP, FMUBuildInputError, fmu_variables
from feeddrive.models import feed_drive

NOMINAL = feed_drive().nominal()
STATES = ("i", "w", "theta", "xi_w", "xi_i", "w_rf")
U_L = OPEN_LOOP["u_in"] / NOMINAL["L"]  # di/dt at rest in open loop [A/s]


def raw(sim, fn: str, *args) -> int:
    """Status of an fmi2 function that fmpy does not wrap for this interface type."""
    return getattr(sim.fmu.dll, fn)(c_void_p(sim.fmu.component), *args)


def refused(sim, call, message: str) -> None:
    """``call()`` fails with fmi2Error (3) and logs exactly ``message``."""
    n = len(sim.log)
    try:
        status = call()
    except FMICallException as exc:
        status = exc.status
    assert status == 3
    assert sim.log[n:] == [message]


# -- substep bounds --------------------------------------------------------------------------------

def test_cs_substep_has_a_lower_bound_in_the_description_and_the_setter(instance, fmu_dir):
    variables = {v.name: v for v in read_model_description(fmu_dir).modelVariables}
    assert float(variables["cs_substep"].min) == MIN_CS_SUBSTEP == 1e-9
    with pytest.raises(FMUBuildInputError, match="cs_substep must be a positive number of seconds >= 1e-09"):
        fmu_variables(feed_drive(), cs_substep=1e-10)
    sim = instance(init=False)
    refused(sim, lambda: sim.set(cs_substep=1e-300),
            "fmi2SetReal: cs_substep = 1e-300 is out of range (cs_substep >= 1e-09 required)")
    sim.set(cs_substep=MIN_CS_SUBSTEP)  # the bound itself is allowed
    assert len(sim.log) == 1


def test_a_step_beyond_the_substep_cap_is_refused_and_changes_nothing(instance):
    sim, clean = instance(**OPEN_LOOP), instance(**OPEN_LOOP)
    sim.fmu.doStep(0.0, H)
    clean.fmu.doStep(0.0, H)
    h_over = (MAX_SUBSTEPS + 1) * 1e-5  # one substep more than the cap at the default 1e-5 s
    refused(sim, lambda: sim.fmu.doStep(H, h_over),
            f"fmi2DoStep: h = {h_over:g} s with cs_substep = 1e-05 s needs 1e+07 RK4 substeps, more than the cap "
            f"of {MAX_SUBSTEPS} per step; use shorter communication steps or a larger cs_substep")
    refused(sim, lambda: sim.fmu.doStep(H, 1e14),  # overflowed the substep count before: 0 substeps, fmi2OK
            "fmi2DoStep: h = 1e+14 s with cs_substep = 1e-05 s needs 1e+19 RK4 substeps, more than the cap of "
            f"{MAX_SUBSTEPS} per step; use shorter communication steps or a larger cs_substep")
    np.testing.assert_array_equal(sim.get(*STATES), clean.get(*STATES))
    for s in (sim, clean):
        for n in range(1, 1000):
            s.fmu.doStep(n * H, H)
    np.testing.assert_array_equal(sim.get(*STATES), clean.get(*STATES))
    np.testing.assert_allclose(sim.get("i", "w", "theta"), open_loop_exact(np.array([0.1]))[0], rtol=1e-6)


# -- non-finite results ----------------------------------------------------------------------------

def test_a_finite_input_that_overflows_the_outputs_is_an_error(instance):
    """w_ref = 1e308 is finite, but the reference filter's derivative (w_ref - w_rf) / tau_ref overflows."""
    sim = instance(w_ref=1e308)
    refused(sim, lambda: sim.get("der(w_rf)"),
            "fmi2GetReal: der(w_rf) = inf at t = 0 s is not a finite number (inputs or parameters beyond the "
            "model's numeric range)")
    np.testing.assert_array_equal(sim.get("w_rf", "w_ref"), [0.0, 1e308])  # finite values stay readable
    sim.set(w_ref=20.0)
    assert sim.get("der(w_rf)")[0] == pytest.approx(20.0 / NOMINAL["tau_ref"], rel=1e-15)


def test_model_exchange_derivatives_that_overflow_are_an_error(instance):
    sim = instance("me", w_ref=1e308)
    dx = (c_double * 6)()
    refused(sim, lambda: sim.fmu.getDerivatives(dx, 6),
            "fmi2GetDerivatives: der(w_rf) = inf at t = 0 s is not a finite number (inputs or parameters beyond "
            "the model's numeric range)")
    sim.set(w_ref=20.0)  # an input: allowed in continuous-time mode
    sim.fmu.getDerivatives(dx, 6)
    assert dx[5] == pytest.approx(20.0 / NOMINAL["tau_ref"], rel=1e-15) and all(map(math.isfinite, dx))


# -- the FMI 2.0 state machine ---------------------------------------------------------------------

def _enter(sim, mode: str) -> None:
    """Instance made with init=False -> mode 'step' | 'terminated' (CS) or 'event' | 'ct' (ME)."""
    sim.fmu.enterInitializationMode()
    sim.fmu.exitInitializationMode()
    if mode == "ct":
        sim.fmu.enterContinuousTimeMode()
    if mode == "terminated":
        sim.fmu.terminate()


def _ids(cases: list) -> list[str]:
    return [f"{mode}-{message.split(':')[0]}" for mode, _, message in cases]


CS_REFUSALS = [  # (mode, call, message)
    ("instantiated", lambda s: raw(s, "fmi2EnterContinuousTimeMode"),
     "fmi2EnterContinuousTimeMode: a Model Exchange function, this instance is Co-Simulation"),
    ("instantiated", lambda s: s.fmu.doStep(0.0, H),
     "fmi2DoStep: not allowed in the instantiated state (allowed in step mode)"),
    ("instantiated", lambda s: s.fmu.exitInitializationMode(),
     "fmi2ExitInitializationMode: not allowed in the instantiated state (allowed in initialization mode)"),
    ("instantiated", lambda s: s.fmu.terminate(),
     "fmi2Terminate: not allowed in the instantiated state (allowed in step mode, event mode, continuous-time mode)"),
    ("instantiated", lambda s: s.get("u"),
     "fmi2GetReal: not allowed in the instantiated state (allowed in initialization mode, step mode, event mode, "
     "continuous-time mode, the terminated state)"),
    ("step", lambda s: s.fmu.enterInitializationMode(),
     "fmi2EnterInitializationMode: not allowed in step mode (allowed in the instantiated state)"),
    ("step", lambda s: s.fmu.setupExperiment(startTime=5.0),
     "fmi2SetupExperiment: not allowed in step mode (allowed in the instantiated state)"),
    ("step", lambda s: raw(s, "fmi2SetTime", c_double(5.0)),
     "fmi2SetTime: a Model Exchange function, this instance is Co-Simulation"),
    ("terminated", lambda s: s.fmu.enterInitializationMode(),
     "fmi2EnterInitializationMode: not allowed in the terminated state (allowed in the instantiated state)"),
    ("terminated", lambda s: s.fmu.doStep(0.1, H),
     "fmi2DoStep: not allowed in the terminated state (allowed in step mode)"),
    ("terminated", lambda s: s.set(u_in=0.0),
     "fmi2SetReal: not allowed in the terminated state (allowed in the instantiated state, initialization mode, "
     "step mode, event mode, continuous-time mode)"),
    ("terminated", lambda s: s.fmu.setRealInputDerivatives([s.vr["u_in"]], [1], [1.0]),
     "fmi2SetRealInputDerivatives: not allowed in the terminated state (allowed in the instantiated state, "
     "initialization mode, step mode)"),
]


@pytest.mark.parametrize("mode,call,message", CS_REFUSALS, ids=_ids(CS_REFUSALS))
def test_co_simulation_calls_out_of_sequence_are_refused_and_change_nothing(instance, mode, call, message):
    """The instance is then driven to the end of a 0.1 s open-loop run; its states match the matrix
    exponential whatever the refused call tried (revive, skip initialisation, restart the clock)."""
    sim = instance(init=False, **OPEN_LOOP)
    if mode != "instantiated":
        _enter(sim, mode)
    if mode == "step":
        for n in range(500):
            sim.fmu.doStep(n * H, H)
    refused(sim, lambda: call(sim), message)
    if mode == "terminated":  # only fmi2Reset brings it back
        sim.fmu.reset()
        sim.fmu.setupExperiment(startTime=0.0)
        sim.set(**OPEN_LOOP)
    if mode != "step":
        _enter(sim, "step")
    for n in range(500 if mode == "step" else 0, 1000):
        sim.fmu.doStep(n * H, H)
    np.testing.assert_allclose(sim.get("i", "w", "theta"), open_loop_exact(np.array([0.1]))[0], rtol=1e-6)
    assert sim.log == [message]


def test_states_and_fixed_parameters_cannot_change_mid_run(instance):
    """The reviewer's sequence: re-enter initialization mode from step mode, set w and the fixed
    parameters, exit. Every call is refused; the run continues like an untouched one."""
    sim, clean = instance(**OPEN_LOOP), instance(**OPEN_LOOP)
    for s in (sim, clean):
        for n in range(100):
            s.fmu.doStep(n * H, H)
    for call in (sim.fmu.enterInitializationMode, lambda: sim.set(w=1000.0), lambda: sim.set(bypass=0.0),
                 lambda: sim.set(cs_substep=1e-3), sim.fmu.exitInitializationMode):
        with pytest.raises(FMICallException):
            call()
    assert [m.split(":")[0] for m in sim.log] == ["fmi2EnterInitializationMode", "fmi2SetReal", "fmi2SetReal",
                                                 "fmi2SetReal", "fmi2ExitInitializationMode"]
    for s in (sim, clean):
        for n in range(100, 200):
            s.fmu.doStep(n * H, H)
    np.testing.assert_array_equal(sim.get(*STATES), clean.get(*STATES))


ME_REFUSALS = [
    ("ct", lambda s: raw(s, "fmi2DoStep", c_double(0.0), c_double(1e-3), c_int(1)),
     "fmi2DoStep: a Co-Simulation function, this instance is Model Exchange"),
    ("ct", lambda s: s.set(R=2 * NOMINAL["R"]),
     "fmi2SetReal: R is a parameter: continuous-time mode takes inputs only (call fmi2EnterEventMode first)"),
    ("ct", lambda s: s.fmu.newDiscreteStates(),
     "fmi2NewDiscreteStates: not allowed in continuous-time mode (allowed in event mode)"),
    ("ct", lambda s: s.fmu.enterContinuousTimeMode(),
     "fmi2EnterContinuousTimeMode: not allowed in continuous-time mode (allowed in event mode)"),
    ("event", lambda s: s.fmu.setContinuousStates((c_double * 6)(*[1.0] * 6), 6),
     "fmi2SetContinuousStates: not allowed in event mode (allowed in continuous-time mode)"),
    ("event", lambda s: s.fmu.completedIntegratorStep(),
     "fmi2CompletedIntegratorStep: not allowed in event mode (allowed in continuous-time mode)"),
    ("event", lambda s: s.fmu.enterInitializationMode(),
     "fmi2EnterInitializationMode: not allowed in event mode (allowed in the instantiated state)"),
    ("event", lambda s: raw(s, "fmi2SetRealInputDerivatives", (c_uint * 1)(s.vr["u_in"]), c_size_t(1),
                            (c_int * 1)(1), (c_double * 1)(1.0)),
     "fmi2SetRealInputDerivatives: a Co-Simulation function, this instance is Model Exchange"),
]


@pytest.mark.parametrize("mode,call,message", ME_REFUSALS, ids=_ids(ME_REFUSALS))
def test_model_exchange_calls_out_of_sequence_are_refused_and_change_nothing(instance, mode, call, message):
    """Before: the doStep on a Model Exchange instance integrated, and R changed in continuous-time mode."""
    sim = instance("me", init=False, **OPEN_LOOP)
    _enter(sim, mode)
    refused(sim, lambda: call(sim), message)
    if mode == "event":
        sim.fmu.enterContinuousTimeMode()
    x0 = (c_double * 6)()
    sim.fmu.getContinuousStates(x0, 6)
    dx = (c_double * 6)()
    sim.fmu.getDerivatives(dx, 6)
    assert list(x0) == [0.0] * 6
    assert dx[0] == U_L and dx[1:] == [0.0] * 5  # di/dt = u_in / L at rest with the nominal R
    sim.fmu.enterEventMode()  # the paper's way to change a parameter in Model Exchange
    sim.set(R=2 * NOMINAL["R"])
    assert sim.log == [message]


# -- FMU states ------------------------------------------------------------------------------------

def _offset(state: bytes, value: float) -> int:
    """Byte offset of the one double equal to ``value`` in a serialised state."""
    packed = struct.pack("d", value)
    assert state.count(packed) == 1
    return state.index(packed)


def test_serialised_state_has_a_header_that_is_checked(instance, fmu_dir):
    cs, me = instance(**OPEN_LOOP), instance("me", **OPEN_LOOP)
    guid = read_model_description(fmu_dir).guid
    good = cs.fmu.serializeFMUstate(cs.fmu.getFMUstate())
    assert good.startswith(b"FDFMU2S\0" + guid.encode() + b"\0")
    size = len(good)
    refused(cs, lambda: cs.fmu.deSerializeFMUstate(good[:-8]),
            f"fmi2DeSerializeFMUstate: {size - 8} bytes were not serialised by this FMU (its states have {size} bytes)")
    refused(cs, lambda: cs.fmu.deSerializeFMUstate(b"\0" * size),
            "fmi2DeSerializeFMUstate: not an FMU state of this wrapper (bad header)")
    other = good.replace(guid.encode(), guid.replace(guid[1], "f" if guid[1] != "f" else "e", 1).encode())
    refused(cs, lambda: cs.fmu.deSerializeFMUstate(other),
            f"fmi2DeSerializeFMUstate: the state belongs to model {other[8:8 + len(guid)].decode()}, this FMU is {guid}")
    refused(me, lambda: me.fmu.deSerializeFMUstate(good),
            "fmi2DeSerializeFMUstate: a Co-Simulation state cannot be restored into a Model Exchange instance")
    in_memory = cs.fmu.getFMUstate()  # the same check on fmi2SetFMUstate, for states never serialised
    refused(me, lambda: me.fmu.setFMUstate(in_memory),
            "fmi2SetFMUstate: a Co-Simulation state cannot be restored into a Model Exchange instance")
    cs.fmu.freeFMUstate(in_memory)
    np.testing.assert_array_equal(_trajectory(cs), _trajectory(instance(**OPEN_LOOP)))


@pytest.mark.parametrize("name,value,message", [
    ("w", math.nan, "w = nan is not a finite number"),
    ("Jt", -5.0, "Jt = -5 is out of range (Jt > 0 required)"),
    ("u_in", math.inf, "u_in = inf is not a finite number"),
])
def test_a_state_with_bad_values_is_refused(instance, name, value, message):
    sim = instance(**{**OPEN_LOOP, "u_in": 12.345})
    good = sim.fmu.serializeFMUstate(sim.fmu.getFMUstate())
    base, vr = _offset(good, 12.345), sim.vr[name] - sim.vr["u_in"]
    bad = bytearray(good)
    bad[base + 8 * vr: base + 8 * vr + 8] = struct.pack("d", value)
    refused(sim, lambda: sim.fmu.deSerializeFMUstate(bytes(bad)), "fmi2DeSerializeFMUstate: " + message)


def test_a_state_from_initialization_restores_values_and_keeps_step_mode(instance):
    """fmi2SetFMUstate restores values and time, not the mode: rewinding a running instance to a state
    taken in initialization mode replays the run bit-identically, and it matches the analytic solution."""
    sim = instance(init=False, **OPEN_LOOP)
    sim.fmu.enterInitializationMode()
    start = sim.fmu.getFMUstate()
    sim.fmu.exitInitializationMode()
    first = _trajectory(sim, 1000)
    sim.fmu.setFMUstate(start)
    np.testing.assert_array_equal(_trajectory(sim, 1000), first)
    np.testing.assert_allclose(first[-1, :2], open_loop_exact(np.array([0.1]))[0, :2], rtol=1e-6)
    assert sim.log == []
    sim.fmu.freeFMUstate(start)


def test_a_state_with_other_fixed_parameters_is_refused_after_initialisation(instance):
    sim, clean = instance(init=False, **OPEN_LOOP), instance(init=False, **OPEN_LOOP)
    before = sim.fmu.getFMUstate()  # cs_substep = 1e-5
    for s in (sim, clean):
        s.set(cs_substep=5e-5)
        _enter(s, "step")
    refused(sim, lambda: sim.fmu.setFMUstate(before),
            "fmi2SetFMUstate: the state has cs_substep = 1e-05, this run fixed it at 5e-05 in initialisation "
            "(fmi2Reset to change it)")
    np.testing.assert_array_equal(_trajectory(sim), _trajectory(clean))
    sim.fmu.freeFMUstate(before)
