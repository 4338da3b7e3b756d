"""The built-in plant as an FMI 3.0 FMU: the same model code and wrapper core as FMI 2.0, so the same
numbers; fmpy's validation; the contract (bad values refused with a message, instance still usable);
the cache; ``cosim build-fmu --fmi-version 3``; and the estimates through the master."""
from __future__ import annotations

import math
import re
import subprocess
import zipfile
from collections.abc import Callable, Iterator
from ctypes import c_double
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Model, FMU3Slave
from fmpy.validation import validate_fmu
from test_plant_fmu import OPEN_LOOP, U_STEP, open_loop_exact  # same directory, on sys.path

from feeddrive.cosim.cli import main as cosim_main
from feeddrive.fmu_build import MAX_SUBSTEPS, FMUBuildInputError, build_fmu, builtin_fmu, fmu_variables
from feeddrive.fmu_build.build import FMI_HEADERS, compiler
from feeddrive.fmu_build.codegen import generate
from feeddrive.fmu_build.model_description import base_unit
from feeddrive.models import feed_drive

NOMINAL = feed_drive().nominal()
R, K, ft, Cd = (NOMINAL[n] for n in ("R", "K", "ft", "Cd"))
H = 1e-4  # communication step [s]
OUTPUTS = ["i", "w", "theta", "u", "u_ref", "i_ref", "x"]
STATES = ("i", "w", "theta", "xi_w", "xi_i", "w_rf")
TL = 2.0  # load torque step of the input profile [N.m]


@pytest.fixture(scope="session")
def fmi3_fmu(fmu_cache_dir: Path) -> Path:
    return builtin_fmu(fmu_cache_dir, fmi_version=3)


def profile() -> np.ndarray:
    """Speed reference 0 -> 20 rad/s at 0.05 s -> -10 rad/s at 0.45 s, load torque 0 -> 2 N.m at 0.25 s:
    piecewise constant (repeated time points), so held and interpolated inputs agree at every step."""
    rows = [(0.0, 0.0, 0.0), (0.05, 0.0, 0.0), (0.05, 20.0, 0.0), (0.25, 20.0, 0.0), (0.25, 20.0, TL),
            (0.45, 20.0, TL), (0.45, -10.0, TL), (0.7, -10.0, TL)]
    return np.array(rows, dtype=[("time", float), ("w_ref", float), ("Tl", float)])


def run(fmu: Path, kind: str, stop: float, dt: float = H, **kw) -> np.ndarray:
    return simulate_fmu(str(fmu), fmi_type=kind, stop_time=stop, output_interval=dt, relative_tolerance=1e-10,
                        output=OUTPUTS, **kw)


def scaled_error(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


# -- the description ------------------------------------------------------------------------------

def test_validates_and_declares_the_same_variables_as_fmi2(fmi3_fmu, feeddrive_fmu):
    assert validate_fmu(str(fmi3_fmu)) == []
    md3, md2 = read_model_description(str(fmi3_fmu)), read_model_description(str(feeddrive_fmu))
    assert md3.fmiVersion == "3.0" and md3.coSimulation and md3.modelExchange
    assert md3.coSimulation.canHandleVariableCommunicationStepSize
    assert not md3.coSimulation.hasEventMode and not md3.coSimulation.providesIntermediateUpdate
    with zipfile.ZipFile(fmi3_fmu) as z:  # defaults false, as in FMI 2.0: no directional derivatives, no clocks
        xml = z.read("modelDescription.xml").decode()
    assert "Derivatives=" not in xml and "Clock" not in xml
    (time,) = [v for v in md3.modelVariables if v.causality == "independent"]
    assert (time.name, time.type, time.unit) == ("time", "Float64", "s")
    v3 = {v.name: v for v in md3.modelVariables if v.name != "time"}
    assert time.valueReference == len(v3)  # after the flat array, which FMI 2.0 shares
    for v in md2.modelVariables:  # same value reference, unit, causality, variability, start, bounds
        w = v3.pop(v.name)
        assert w.type == "Float64"
        for attr in ("valueReference", "unit", "causality", "variability", "initial", "start", "min", "max"):
            assert getattr(w, attr) == getattr(v, attr), (v.name, attr)
        assert (w.derivative and w.derivative.name) == (v.derivative and v.derivative.name)
    assert v3 == {}
    assert {u.name for u in md3.unitDefinitions} == {v.unit for v in md3.modelVariables}
    with zipfile.ZipFile(fmi3_fmu) as z:
        assert sorted(z.namelist()) == ["binaries/x86_64-linux/FeedDrive.so", "modelDescription.xml"]


def test_unit_definitions_carry_si_base_units_consistent_with_the_equations(fmi3_fmu, feeddrive_fmu):
    """Each unit has its SI exponents (rad counted, as FMI does); with them, every term of the paper's
    electrical equation u = R i + L di/dt + K w is in volts and every torque of the mechanical one
    Jt dw/dt = K i - ft w - Cd - Tl in N.m, up to the radian exponent (SI's rad is 1: K is in N.m/A,
    the same number as V.s/rad, and kg.m2 rad/s2 is N.m). Both versions declare the same units."""
    md3, md2 = read_model_description(str(fmi3_fmu)), read_model_description(str(feeddrive_fmu))
    exps = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")

    def base(md) -> dict[str, tuple]:
        return {u.name: (tuple(getattr(u.baseUnit, e) for e in exps), u.baseUnit.factor) for u in md.unitDefinitions}

    units = base(md3)
    assert units == base(md2)
    unit_of = {v.name: units[v.unit][0] for v in md3.modelVariables}
    assert all(factor == 1.0 for _, factor in units.values())  # the model is in SI throughout

    def times(*names: str) -> tuple[int, ...]:  # exponents of a product, without rad
        return tuple(map(sum, zip(*(unit_of[n] for n in names))))[:7]

    assert unit_of["R"] == (1, 2, -3, -2, 0, 0, 0, 0) and unit_of["w"] == (0, 0, -1, 0, 0, 0, 0, 1)
    assert unit_of["u"] == (1, 2, -3, -1, 0, 0, 0, 0)
    assert times("R", "i") == times("L", "der(i)") == times("K", "w") == times("u")
    assert unit_of["Tl"] == unit_of["Cd"] == (1, 2, -2, 0, 0, 0, 0, 0)
    assert times("Jt", "der(w)") == times("K", "i") == times("ft", "w") == times("Tl")


@pytest.mark.parametrize("unit,attrs", [
    ("V/(A.s)", {"kg": "1", "m": "2", "s": "-4", "A": "-2"}),
    ("rad/s/s", {"s": "-2", "rad": "1"}),  # left to right
    ("1/s", {"s": "-1"}), ("1", {}), ("mm", {"m": "1", "factor": "0.001"}),
    ("rpm", {"s": "-1", "rad": "1", "factor": repr(math.pi / 30)}),
])
def test_base_unit_reads_products_quotients_and_powers(unit, attrs):
    assert base_unit(unit) == attrs


@pytest.mark.parametrize("unit", ["furlong", "V/(A.s", "N m", "m^2", "m..s"])
def test_base_unit_refuses_what_it_cannot_read(unit):
    with pytest.raises(FMUBuildInputError, match=f"unit '{re.escape(unit)}': expected products and quotients"):
        base_unit(unit)


def test_cached_beside_fmi2_and_reused(fmu_cache_dir, fmi3_fmu, feeddrive_fmu):
    assert fmi3_fmu.parent != feeddrive_fmu.parent and fmi3_fmu.name == feeddrive_fmu.name  # hash covers the version
    stamp = fmi3_fmu.stat().st_mtime_ns
    assert builtin_fmu(fmu_cache_dir, fmi_version=3) == fmi3_fmu and fmi3_fmu.stat().st_mtime_ns == stamp
    assert builtin_fmu(fmu_cache_dir, fmi_version=2) == feeddrive_fmu


@pytest.mark.parametrize("version", [1, 4, "3", True])
def test_other_versions_are_bad_input(tmp_path, version):
    with pytest.raises(FMUBuildInputError, match=f"fmi_version must be 2 or 3, got {version!r}"):
        build_fmu(out=tmp_path / "x.fmu", fmi_version=version)
    assert not list(tmp_path.iterdir())


def test_cli_builds_fmi3(tmp_path, capsys):
    out = tmp_path / "FeedDrive3.fmu"
    assert cosim_main(["build-fmu", "--fmi-version", "3", "--out", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == str(out)
    assert lines[1].startswith("FeedDrive: FMI 3.0 Co-Simulation + Model Exchange, 6 states, 3 inputs, 7 outputs")
    assert validate_fmu(str(out)) == [] and read_model_description(str(out)).fmiVersion == "3.0"
    with pytest.raises(SystemExit) as exc:  # argparse's own one-line refusal, exit 2
        cosim_main(["build-fmu", "--fmi-version", "1", "--out", str(tmp_path / "one.fmu")])
    assert exc.value.code == 2 and "invalid choice: 1 (choose from 2, 3)" in capsys.readouterr().err
    assert not (tmp_path / "one.fmu").exists()


def test_both_versions_compile_the_same_generated_code_and_core():
    """Only the API layer and the XML differ; the header differs by the GUID it carries."""
    two, three = generate(feed_drive(), fmi_version=2), generate(feed_drive(), fmi_version=3)
    assert set(two.files) - set(three.files) == {"fmi2_wrapper.c"}
    assert set(three.files) - set(two.files) == {"fmi3_wrapper.c"}
    for name in set(two.files) & set(three.files) - {"modelDescription.xml"}:
        assert two.files[name].replace(two.guid, "@") == three.files[name].replace(three.guid, "@"), name
    assert two.guid != three.guid


@pytest.mark.parametrize("version", [2, 3])
def test_wrapper_and_core_compile_without_warnings(tmp_path, version):
    """-Wall -Wextra -Wpedantic as errors (unused parameters excepted: the API fixes the signatures);
    a mismatched pointer between a layer and the core compiles otherwise, with a warning only."""
    sources = generate(feed_drive(), fmi_version=version)
    for name, text in sources.files.items():
        (tmp_path / name).write_text(text)
    command = [*compiler(), "-std=c99", "-Wall", "-Wextra", "-Wpedantic", "-Werror", "-Wno-unused-parameter",
               "-fsyntax-only", f"-I{FMI_HEADERS}", f"-I{tmp_path}", f"fmi{version}_wrapper.c", "fmu_core.c"]
    done = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


# -- the same numbers as FMI 2.0 ------------------------------------------------------------------

def test_co_simulation_trajectories_equal_fmi2(fmi3_fmu, feeddrive_fmu):
    """Speed and load steps through fmpy's input table, same step: every output of every step agrees
    to 1e-9 of its range (measured: bit-identical, the same generated code and core)."""
    res = {v: run(f, "CoSimulation", 0.7, input=profile()) for v, f in ((2, feeddrive_fmu), (3, fmi3_fmu))}
    assert len(res[3]) == len(res[2]) == 7001
    np.testing.assert_array_equal(res[3]["time"], res[2]["time"])
    for name in OUTPUTS:
        assert scaled_error(res[3][name], res[2][name]) <= 1e-9, name
    # the inputs took effect: the speed follows both reference steps, the current carries the load
    k = np.searchsorted(res[3]["time"], 0.44)
    w, i = res[3]["w"][k], res[3]["i"][k]
    assert w == pytest.approx(20.0, rel=1e-3)
    assert K * i == pytest.approx(ft * w + Cd + TL, rel=1e-2)  # mechanical balance with the load
    assert res[3]["w"][-1] == pytest.approx(-10.0, rel=1e-2)


@pytest.mark.parametrize("kind", ["CoSimulation", "ModelExchange"])
def test_closed_loop_steady_state_equals_fmi2_and_balances_the_equations(fmi3_fmu, feeddrive_fmu, kind):
    res = {v: run(f, kind, 3.0, dt=1e-3, start_values={"w_ref": 50.0}) for v, f in ((2, feeddrive_fmu), (3, fmi3_fmu))}
    i, w, u = (res[3][n][-1] for n in ("i", "w", "u"))
    assert w == pytest.approx(50.0, rel=1e-6)
    assert i == pytest.approx((ft * w + Cd) / K, rel=1e-6)  # mechanical equation with dw/dt = 0
    assert u == pytest.approx(R * i + K * w, rel=1e-6)  # electrical equation with di/dt = 0
    tolerance = 1e-9 if kind == "CoSimulation" else 1e-8  # ME: CVode with rtol 1e-10 on both
    for name in ("i", "w", "u", "theta"):
        assert res[3][name][-1] == pytest.approx(res[2][name][-1], rel=tolerance), name


def test_model_exchange_follows_the_inputs_within_the_solver_tolerance(fmi3_fmu, feeddrive_fmu):
    res = {v: run(f, "ModelExchange", 0.7, dt=1e-3, input=profile()) for v, f in ((2, feeddrive_fmu), (3, fmi3_fmu))}
    cs = run(fmi3_fmu, "CoSimulation", 0.7, dt=1e-3, input=profile())
    np.testing.assert_array_equal(res[3]["time"], res[2]["time"])  # the same grid plus the input events
    for name in ("i", "w", "theta", "u"):
        assert scaled_error(res[3][name], res[2][name]) < 1e-8, name
    for name in ("i", "w", "theta"):  # continuous states, on the CS grid: CVode 1e-10 against RK4 at 1e-5 s
        assert scaled_error(np.interp(cs["time"], res[3]["time"], res[3][name]), cs[name]) < 1e-5, name


@pytest.mark.parametrize("kind", ["CoSimulation", "ModelExchange"])
def test_open_loop_voltage_step_matches_matrix_exponential(fmi3_fmu, kind):
    res = run(fmi3_fmu, kind, 0.3, dt=1e-3, start_values=OPEN_LOOP)
    exact = open_loop_exact(res["time"])
    for k, name in enumerate(("i", "w", "theta")):
        assert scaled_error(res[name], exact[:, k]) < 1e-6, name
    assert np.all(res["u"] == U_STEP)


# -- the contract, through fmpy's FMI 3 classes -------------------------------------------------------

@dataclass
class Instance3:
    fmu: FMU3Slave | FMU3Model
    vr: dict[str, int]
    log: list[tuple[int, str, str]] = field(default_factory=list)  # (status, category, message)

    def get(self, *names: str) -> np.ndarray:
        return np.array(self.fmu.getFloat64([self.vr[n] for n in names]))

    def set(self, **values: float) -> None:
        self.fmu.setFloat64([self.vr[n] for n in values], list(values.values()))

    def steps(self, first: int, last: int) -> None:
        for n in range(first, last):
            self.fmu.doStep(n * H, H)


@pytest.fixture(scope="session")
def fmi3_dir(fmi3_fmu: Path, tmp_path_factory: pytest.TempPathFactory) -> str:
    return extract(str(fmi3_fmu), str(tmp_path_factory.mktemp("fmi3_extracted")))


@pytest.fixture
def instance3(fmi3_dir: str) -> Iterator[Callable[..., Instance3]]:
    """Factory ``instance3(kind="cs" | "me", init=True, **start)``: at t = 0, initialised unless
    ``init`` is False; its log records every message the FMU sends."""
    made: list[Instance3] = []

    def make(kind: str = "cs", init: bool = True, **start: float) -> Instance3:
        md = read_model_description(fmi3_dir)
        cls, ident = (FMU3Slave, md.coSimulation) if kind == "cs" else (FMU3Model, md.modelExchange)
        fmu = cls(guid=md.guid, unzipDirectory=fmi3_dir, modelIdentifier=ident.modelIdentifier,
                  instanceName=f"{kind}{len(made)}")
        inst = Instance3(fmu, {v.name: v.valueReference for v in md.modelVariables})
        fmu.instantiate(logMessage=lambda env, status, cat, msg: inst.log.append((status, cat.decode(), msg.decode())))
        made.append(inst)
        inst.set(**start)
        if init:
            fmu.enterInitializationMode(startTime=0.0)
            fmu.exitInitializationMode()
            if kind == "me":
                fmu.enterContinuousTimeMode()
        return inst

    yield make
    for inst in made:
        inst.fmu.freeInstance()


def refused(sim: Instance3, call: Callable[[], object], message: str) -> None:
    """``call()`` fails with fmi3Error (3) and logs exactly ``message`` as an error."""
    n = len(sim.log)
    with pytest.raises(FMICallException) as exc:
        call()
    assert exc.value.status == 3
    assert sim.log[n:] == [(3, "logStatusError", message)]


@pytest.mark.parametrize("value,message", [
    (0.0, "fmi3SetFloat64: R = 0 is out of range (R > 0 required)"),
    (-1.0, "fmi3SetFloat64: R = -1 is out of range (R > 0 required)"),
    (math.nan, "fmi3SetFloat64: R = nan is not a finite number"),
])
def test_bad_resistance_is_an_error_with_a_message_and_the_instance_stays_usable(instance3, value, message):
    """Refused before initialisation and mid-run (R is tunable: step mode takes it); the instance then
    runs the 0.1 s open-loop step exactly like an untouched one, on the matrix exponential."""
    sim, clean = instance3(init=False, **OPEN_LOOP), instance3(init=False, **OPEN_LOOP)
    refused(sim, lambda: sim.set(R=value), message)
    for s in (sim, clean):
        s.fmu.enterInitializationMode(startTime=0.0)
        s.fmu.exitInitializationMode()
        s.steps(0, 500)
    refused(sim, lambda: sim.set(R=value, u_in=0.0), message)  # all or nothing: u_in unchanged too
    for s in (sim, clean):
        s.steps(500, 1000)
    np.testing.assert_array_equal(sim.get(*STATES, "u_in", "R"), clean.get(*STATES, "u_in", "R"))
    np.testing.assert_allclose(sim.get("i", "w", "theta"), open_loop_exact(np.array([0.1]))[0], rtol=1e-6)
    assert clean.log == [] and len(sim.log) == 2


def test_model_exchange_takes_parameters_in_event_mode_only(instance3):
    sim = instance3("me", **OPEN_LOOP)
    refused(sim, lambda: sim.set(R=2 * R),
            "fmi3SetFloat64: R is a parameter: continuous-time mode takes inputs only (call fmi3EnterEventMode first)")
    refused(sim, lambda: sim.fmu.fmi3GetContinuousStateDerivatives(sim.fmu.component, (c_double * 5)(), 5),
            "fmi3GetContinuousStateDerivatives: called with 5 states, this FMU has 6")
    sim.fmu.enterEventMode()
    refused(sim, lambda: sim.set(R=-R), f"fmi3SetFloat64: R = {-R:g} is out of range (R > 0 required)")
    sim.set(R=2 * R)
    sim.fmu.enterContinuousTimeMode()
    dx = (c_double * 6)()
    sim.fmu.getContinuousStateDerivatives(dx, 6)
    assert dx[0] == pytest.approx(U_STEP / NOMINAL["L"], rel=1e-15)  # at rest the resistance does not act yet
    assert sim.get("R")[0] == 2 * R


def test_overflowing_outputs_and_overlong_steps_are_errors_that_change_nothing(instance3):
    """The core's checks, under the fmi3 names: a finite input whose derivative overflows, and a step
    beyond the substep cap (before the cap, 1e14 s overflowed the substep count)."""
    sim, clean = instance3(**OPEN_LOOP), instance3(**OPEN_LOOP)
    sim.set(w_ref=1e308)
    refused(sim, lambda: sim.get("der(w_rf)"),
            "fmi3GetFloat64: der(w_rf) = inf at t = 0 s is not a finite number (inputs or parameters beyond the "
            "model's numeric range)")
    sim.set(w_ref=0.0)
    refused(sim, lambda: sim.fmu.doStep(0.0, 1e14),
            f"fmi3DoStep: h = 1e+14 s with cs_substep = 1e-05 s needs 1e+19 RK4 substeps, more than the cap of "
            f"{MAX_SUBSTEPS} per step; use shorter communication steps or a larger cs_substep")
    for s in (sim, clean):
        s.steps(0, 1000)
    np.testing.assert_array_equal(sim.get(*STATES), clean.get(*STATES))
    np.testing.assert_allclose(sim.get("i", "w", "theta"), open_loop_exact(np.array([0.1]))[0], rtol=1e-6)


def test_time_is_readable_and_not_settable(instance3):
    sim = instance3(**OPEN_LOOP)
    sim.steps(0, 37)
    assert sim.get("time")[0] == pytest.approx(37 * H, rel=1e-12)
    refused(sim, lambda: sim.set(time=0.0), "fmi3SetFloat64: time is the independent variable and cannot be set")
    refused(sim, lambda: sim.fmu.getFloat64([sim.vr["time"] + 1]),
            f"fmi3GetFloat64: unknown value reference {sim.vr['time'] + 1} (this FMU has 0..{sim.vr['time']})")


def test_calls_out_of_sequence_are_refused(instance3, fmi3_dir):
    sim = instance3(init=False, **OPEN_LOOP)
    refused(sim, lambda: sim.fmu.doStep(0.0, H), "fmi3DoStep: not allowed in the instantiated state (allowed in step mode)")
    refused(sim, lambda: sim.fmu.fmi3EnterContinuousTimeMode(sim.fmu.component),
            "fmi3EnterContinuousTimeMode: a Model Exchange function, this instance is Co-Simulation")
    sim.fmu.enterInitializationMode(startTime=0.0)
    sim.fmu.exitInitializationMode()
    refused(sim, lambda: sim.fmu.enterStepMode(),
            "fmi3EnterStepMode: not allowed in step mode (allowed in event mode)")
    refused(sim, lambda: sim.fmu.enterConfigurationMode(),
            "fmi3EnterConfigurationMode: this FMU has no structural parameters")
    sim.steps(0, 1000)
    np.testing.assert_allclose(sim.get("i", "w", "theta"), open_loop_exact(np.array([0.1]))[0], rtol=1e-6)
    md = read_model_description(fmi3_dir)  # event mode in Co-Simulation is not declared: refused
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=fmi3_dir, modelIdentifier="FeedDrive", instanceName="ev")
    log: list[str] = []
    with pytest.raises(Exception, match="Failed to instantiate"):
        fmu.instantiate(eventModeUsed=True, logMessage=lambda env, status, cat, msg: log.append(msg.decode()))
    assert log == ["fmi3InstantiateCoSimulation: eventModeUsed is true, but this FMU has no event mode in "
                   "Co-Simulation (hasEventMode is false)"]


def test_fmu_state_round_trip_and_foreign_states(instance3, instance):
    """A serialised state restores bit-identically; an FMI 2.0 state of the same model is refused."""
    sim = instance3(**OPEN_LOOP)
    sim.steps(0, 100)
    saved = sim.fmu.serializeFMUState(sim.fmu.getFMUState())
    assert saved.startswith(b"FDFMU3S\0")
    sim.steps(100, 300)
    first = sim.get(*STATES)
    state = sim.fmu.deserializeFMUState(saved)
    sim.fmu.setFMUState(state)
    sim.steps(100, 300)
    np.testing.assert_array_equal(sim.get(*STATES), first)
    fmi2 = instance(**OPEN_LOOP)
    foreign = fmi2.fmu.serializeFMUstate(fmi2.fmu.getFMUstate())
    refused(sim, lambda: sim.fmu.deserializeFMUState(foreign),
            "fmi3DeserializeFMUState: not an FMU state of this wrapper (bad header)")
    np.testing.assert_array_equal(sim.get(*STATES), first)


def test_fmi3_cs_steps_equal_fmi2_steps_through_the_raw_api(instance3, instance):
    """Same calls (including a mid-run tunable parameter change) -> bit-identical states: one core."""
    a, b = instance3(**OPEN_LOOP), instance(**OPEN_LOOP)
    for n in range(400):
        if n == 200:
            a.set(R=1.5 * R)
            b.set(R=1.5 * R)
        a.fmu.doStep(n * H, H)
        b.fmu.doStep(n * H, H)
    np.testing.assert_array_equal(a.get(*STATES), b.get(*STATES))
    assert [v.name for v in fmu_variables(feed_drive())] == [n for n in a.vr if n != "time"]


# -- the master (cosim/fmi3_adapter.py) -------------------------------------------------------------

def _estimates(plant: dict, out: Path) -> list[dict]:
    from feeddrive.cosim.run import run_scenario
    from feeddrive.cosim.scenario import scenario_from_dict

    program = [{"dwell": {"time": 0.1}}, {"tool_change": {"position": 0.27, "v_max": 0.22, "accel": 0.6, "time": 0.3}}]
    data = {"name": out.name, "axis": "X", "step": 1e-4, "plant": plant, "sensors": {"seed": 4},
            "nc": {"program": program}, "monitor": {}}
    report = run_scenario(scenario_from_dict(data), out, plots=False).report
    return [m["parameters"] for m in report["motions"]]


@pytest.mark.slow
def test_the_master_gets_the_same_estimates_from_fmi3(tmp_path, fmi3_fmu, feeddrive_fmu):
    from feeddrive.cosim.scenario import BUILTIN_MAP

    plant3 = {"fmu": str(fmi3_fmu), "map": {role: {"var": var} for role, var in BUILTIN_MAP.items()}}
    third = _estimates(plant3, tmp_path / "fmi3")
    # FMI 3.0 Co-Simulation has no input derivatives: the FMI 2.0 twin holds its inputs too
    second = _estimates({"fmu": "builtin", "input_hold": "zoh"}, tmp_path / "fmi2")
    assert len(third) == len(second) >= 1
    for p3, p2 in zip(third, second):
        assert p3.keys() == p2.keys()
        for name in p2:
            assert p3[name]["value"] == pytest.approx(p2[name]["value"], rel=1e-9, abs=1e-12), name
