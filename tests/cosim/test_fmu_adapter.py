"""The FMU adapter: CS and ME agree, ports and units, and every FMI failure becomes one clear error."""
from __future__ import annotations

import logging
import textwrap

import numpy as np
import pytest

from feeddrive.cosim.errors import FMIError
from feeddrive.cosim.fmu_adapter import FMUComponent, FMUDiscard
from feeddrive.cosim.master import Master
from feeddrive.cosim.scenario import MapEntry, PlantConfig, load_scenario

SCENARIO = """\
name: adapter
step: 1.0e-4
stop_time: {stop}
plant: {{fmu: builtin, interface: {interface}, input_hold: zoh}}
sensors: {{seed: 1}}
nc:
  program:
    - rapid: {{to: 0.03}}
{extra}"""


def signals(tmp_path, interface="cs", stop=0.6, extra="", **run):
    path = tmp_path / f"{interface}.yaml"
    path.write_text(SCENARIO.format(interface=interface, stop=stop, extra=extra))
    with Master.from_scenario(load_scenario(path)) as master:
        return master.run(**run).signals()


@pytest.mark.slow
def test_co_simulation_and_model_exchange_agree(tmp_path, feeddrive_fmu):
    cs, me = signals(tmp_path, "cs"), signals(tmp_path, "me")
    for name in ("plant.current", "plant.speed", "plant.voltage", "plant.position"):
        scale = np.abs(cs[name]).max()
        assert scale > 0
        # CS: RK4 with 1e-5 s substeps; ME: CVode at rtol 1e-8, restarted at every input step; both
        # hold the inputs over each step (ME has no input derivatives, so CS runs with input_hold zoh)
        np.testing.assert_allclose(me[name], cs[name], rtol=0, atol=1e-5 * scale, err_msg=name)
    assert abs(cs["plant.position"][-1] - 0.03) < 2e-5  # settling through the kv = 30 1/s position loop


def test_ports_follow_the_roles_then_the_other_outputs(feeddrive_fmu):
    plant = FMUComponent("plant", load_scenario_plant(feeddrive_fmu))
    plant.setup(0.0, 1e-4, 10)
    try:
        assert plant.input_names == ("speed_ref", "load")
        assert plant.output_names == ("voltage", "voltage_ref", "current", "speed", "position", "theta", "i_ref")
        assert plant.output_units == ("V", "V", "A", "rad/s", "m", "rad", "A")
        assert list(plant.get_outputs()) == [0.0] * 7  # at rest
    finally:
        plant.terminate()
        plant.terminate()  # a second call is harmless


def load_scenario_plant(fmu):
    roles = {"speed_ref": "w_ref", "load": "Tl", "voltage": "u", "voltage_ref": "u_ref", "current": "i",
             "speed": "w", "position": "x"}
    return PlantConfig(fmu=str(fmu), map={r: MapEntry(var=v) for r, v in roles.items()})


def test_fmi2_error_mid_run_names_function_time_and_log(tmp_path, feeddrive_fmu, caplog):
    # an L in the FMU's declared range (L > 0) so small that the current overflows in the next step (L = 0, which
    # fmi2SetReal refused, is now refused when the scenario is read: the declared min is the next double above 0)
    extra = "events:\n  - {time: 0.05, target: plant.L, value: 1.0e-300}\n"
    with caplog.at_level(logging.ERROR, logger="cosim.fmu.plant"), pytest.raises(FMIError) as info:
        signals(tmp_path, extra=extra, signals_path=tmp_path / "signals.csv")
    err = info.value
    assert (err.component, err.function, err.status) == ("plant", "fmi2DoStep", "fmi2Error")
    assert err.time == pytest.approx(0.05) and "non-finite" in err.last_log
    assert str(err).startswith("plant: fmi2DoStep returned fmi2Error at t=0.05 s: ")
    assert any(r.name == "cosim.fmu.plant" and r.getMessage() == err.last_log for r in caplog.records)
    data = np.loadtxt(tmp_path / "signals.csv", delimiter=",", skiprows=1)
    assert data[-1, 0] == pytest.approx(0.05) and data.shape[0] == 501  # t_0 .. t_500, then the failure
    assert np.all(np.isfinite(data))


PYTHON_FMU = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class Flaky(Fmi2Slave):
    """y = u; from t = 0.0025 s on, mode 1 refuses the step (fmi2Discard), mode 2 raises."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u, self.y, self.mode = 0.0, 0.0, 0.0
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output))
        self.register_variable(Real("mode", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.tunable))

    def do_step(self, t, dt):
        self.y = self.u
        if t >= 0.0025 and self.mode == 2.0:
            raise ValueError("torque sensor saturated")
        return not (t >= 0.0025 and self.mode == 1.0)
'''


@pytest.fixture(scope="module")
def flaky_fmu(tmp_path_factory):
    from pythonfmu.builder import FmuBuilder

    d = tmp_path_factory.mktemp("flaky")
    script = d / "flaky.py"
    script.write_text(textwrap.dedent(PYTHON_FMU))
    return FmuBuilder.build_FMU(script, dest=d)


@pytest.mark.parametrize("mode, cls, pattern", [
    (1.0, FMUDiscard, r"plant: fmi2DoStep returned fmi2Discard at t=0\.003 s: the FMU could not complete it; "
                      r"the run stops"),
    (2.0, FMIError, r"plant: fmi2DoStep returned fmi2Fatal at t=0\.003 s: .*torque sensor saturated"),
])
def test_discard_and_fatal_stop_with_their_own_message(flaky_fmu, mode, cls, pattern):
    cfg = PlantConfig(fmu=str(flaky_fmu), parameters={"mode": mode},
                      map={"speed_ref": MapEntry(var="u", scale=2.0, offset=1.0), "speed": MapEntry(var="y")})
    plant = FMUComponent("plant", cfg)
    plant.setup(0.0, 1e-3, 10)
    seen = []
    with pytest.raises(cls, match=pattern):
        for n in range(10):
            plant.set_inputs([float(n)])
            plant.step(n)
            seen.append(plant.get_outputs()[0])
    plant.terminate()
    assert seen == [1.0, 3.0, 5.0]  # the input map 2 x + 1, then the failing step at t = 0.003 s


def _direct_run(fmu, speed_refs, h, foh: bool) -> np.ndarray:
    """The built-in plant driven straight through fmpy: w_ref = 2 x + 1 set before each step and, if
    ``foh``, its slope (w_ref_n - w_ref_(n-1)) / h (0 at the first step); rows (u, i, w)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzip = extract(str(fmu))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier)
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    rows, before = [], None
    for n, x in enumerate(speed_refs):
        value = 2.0 * x + 1.0
        slave.setReal([vr["w_ref"]], [value])
        if foh:
            slave.setRealInputDerivatives([vr["w_ref"]], [1], [0.0 if before is None else (value - before) / h])
        before = value
        slave.doStep(n * h, h)
        rows.append(slave.getReal([vr["u"], vr["i"], vr["w"]]))
    slave.terminate()
    slave.freeInstance()
    return np.array(rows)


@pytest.mark.parametrize("hold", ["foh", "zoh"])
def test_input_hold_sets_the_mapped_slope_of_each_step(feeddrive_fmu, hold):
    """Through the role map w_ref = 2 speed_ref + 1: foh gives the FMU the slope of the mapped values,
    (w_ref_n - w_ref_(n-1)) / h, 0 at the first step; zoh none. Same FMU calls, same numbers."""
    h, steps = 1e-4, 300
    speed_refs = [200.0 * (n * h) + 5e3 * (n * h) ** 2 for n in range(steps)]  # slope changes every step
    cfg = load_scenario_plant(feeddrive_fmu).model_copy(update={"input_hold": hold})
    cfg = cfg.model_copy(update={"map": {**cfg.map, "speed_ref": MapEntry(var="w_ref", scale=2.0, offset=1.0)}})
    plant = FMUComponent("plant", cfg)
    plant.setup(0.0, h, steps)
    rows = []
    try:
        assert plant.input_hold == hold
        for n, x in enumerate(speed_refs):
            plant.set_inputs([x, 0.0])
            plant.step(n)
            out = dict(zip(plant.output_names, plant.get_outputs()))
            rows.append([out["voltage"], out["current"], out["speed"]])
    finally:
        plant.terminate()
    np.testing.assert_array_equal(np.array(rows), _direct_run(feeddrive_fmu, speed_refs, h, hold == "foh"))
    other = _direct_run(feeddrive_fmu, speed_refs, h, hold != "foh")
    assert np.abs(np.array(rows)[:, 0] - other[:, 0]).max() > 0.01  # the hold matters for u
