"""The FMU adapter: CS and ME agree, ports and units, and every FMI failure becomes one clear error."""
from __future__ import annotations

import logging
import textwrap

import numpy as np
import pytest

from cosim.errors import FMIError
from cosim.fmu_adapter import FMUComponent, FMUDiscard
from cosim.master import Master
from cosim.scenario import MapEntry, PlantConfig, load_scenario

SCENARIO = """\
name: adapter
step: 1.0e-4
stop_time: {stop}
plant: {{fmu: builtin, interface: {interface}}}
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
        # CS: RK4 with 1e-5 s substeps; ME: CVode at rtol 1e-8, restarted at every input step
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
    extra = "events:\n  - {time: 0.05, target: plant.R, value: 0.0}\n"
    with caplog.at_level(logging.ERROR, logger="cosim.fmu.plant"), pytest.raises(FMIError) as info:
        signals(tmp_path, extra=extra, signals_path=tmp_path / "signals.csv")
    err = info.value
    assert (err.component, err.function, err.status) == ("plant", "fmi2SetReal", "fmi2Error")
    assert err.time == pytest.approx(0.05) and "R" in err.last_log
    assert str(err).startswith("plant: fmi2SetReal returned fmi2Error at t=0.05 s: ")
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
