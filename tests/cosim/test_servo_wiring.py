"""The ``servo`` component is the servo drive's sensors only on a PMSM axis (issue 25, PMSM monitor item 3): there it
steps before the monitor and feeds the monitor's servo inputs; on a DC axis a component of that name is a user
component like any other (stepped after the monitor, never a source of the monitor's ports).

``Impostor`` (loadable as ``test_servo_wiring:Impostor``) offers outputs named like the monitor's inputs."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from feeddrive.cosim.component import Component
from feeddrive.cosim.master import Master
from feeddrive.cosim.monitor_servo import SERVO_INPUTS
from feeddrive.cosim.scenario import scenario_from_dict

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


class Impostor(Component):
    """Outputs ``state``, ``motion`` and ``I_U``: constant 7.0 (a value no NC state or motion takes)."""

    output_names = ("state", "motion", "I_U")
    output_units = ("1", "1", "A")

    def setup(self, t0: float, h: float, n_steps: int) -> None:
        pass

    def step(self, n: int) -> None:
        pass

    def get_outputs(self) -> list[float]:
        return [7.0, 7.0, 7.0]


def _master(name: str, **changes) -> Master:
    data = yaml.safe_load((EXAMPLES / name).read_text()) | changes
    master = Master.from_scenario(scenario_from_dict(data, base_dir=EXAMPLES))
    master.setup()
    return master


def test_a_dc_axis_has_no_servo_component_and_a_user_servo_is_an_ordinary_component():
    """The DC example with a user component named ``servo``: stepped after the monitor, and the monitor's
    ``state``, ``motion`` and currents still come from the NC and the sensors."""
    m = _master("tool_change.yaml", stop_time=0.3,
                components=[{"name": "servo", "class": "test_servo_wiring:Impostor"}])
    try:
        order = list(m.components)
        assert order.index("monitor") < order.index("servo")
        assert m.connections["monitor.state"] == "nc.state" and m.connections["monitor.motion"] == "nc.motion"
        assert m.connections["monitor.Im1"] == "sensors.Im1"
        assert not any(src.startswith("servo.") for src in m.connections.values() if isinstance(src, str))
        assert not any(port.startswith("monitor.") and port.split(".")[1] in SERVO_INPUTS for port in m.connections)
    finally:
        m.terminate()
    # and without a user component of that name, the DC axis gets none
    dc = scenario_from_dict(yaml.safe_load((EXAMPLES / "tool_change.yaml").read_text()), base_dir=EXAMPLES)
    assert dc.components == [] and not dc.servo_drive


def test_a_pmsm_axis_monitor_gets_its_servo_inputs_from_the_servo_component_stepped_before_it():
    """examples/pmsm_monitor.yaml: the servo component steps before the monitor, and every one of the monitor's
    servo inputs is wired to the servo output of its name (the connections the scenario states)."""
    data = yaml.safe_load((EXAMPLES / "pmsm_monitor.yaml").read_text())
    s = scenario_from_dict(data, base_dir=EXAMPLES)
    assert s.servo_drive
    assert {f"monitor.{p}": f"servo.{p}" for p in SERVO_INPUTS}.items() <= s.connections.items()
    m = _master("pmsm_monitor.yaml")
    try:
        order = list(m.components)
        assert order.index("servo") < order.index("monitor")
        for port in SERVO_INPUTS:
            assert m.connections[f"monitor.{port}"] == f"servo.{port}", port
        assert m.connections["monitor.state"] == "nc.state"
    finally:
        m.terminate()


def _pmsm(**axis_drive) -> dict:
    data = yaml.safe_load((EXAMPLES / "pmsm_monitor.yaml").read_text())
    data["axis"]["drive"] |= axis_drive
    return data


def test_the_second_current_sensor_on_phase_v_is_checked_against_phase_v(tmp_path):
    """``axis.drive.second_sensor_on: V``: the servo sensors' I_2 measures phase V and the monitor pairs it with
    I_V (paired with I_U, a healthy motion would be a gross fault: the phases are 120 degrees apart). Motion 1
    healthy: the pair passes with a gain ratio within 0.5 % of 1; between the motions I_2's gain steps to 1.03:
    motion 2's pair is not valid (gain difference 3 % +- 0.5 %), the phase sum still passes (I_2 is not a phase
    of the sum)."""
    from feeddrive.cosim.run import run_scenario

    data = _pmsm(second_sensor_on="V")
    data["events"] = [{"time": 1.6, "target": "servo.I_2.gain", "value": 1.03}]
    s = scenario_from_dict(data, base_dir=EXAMPLES)
    (servo,) = [c for c in s.components if c.name == "servo"]
    assert servo.config["second_sensor_on"] == "V" and s.monitor.config.second_sensor_on == "V"
    m1, m2 = run_scenario(s, tmp_path / "v", plots=False).report["motions"]
    pair1, pair2 = m1["servo_checks"]["phase_sensor_pair"], m2["servo_checks"]["phase_sensor_pair"]
    assert pair1["phase"] == "V" and pair1["valid"] and abs(pair1["gain_ratio"] - 1) < 0.005, pair1
    assert m1["measurements_valid"], m1["sensor_faults"]
    assert not pair2["valid"] and abs(-pair2["gain_diff"] - 0.03) < 0.005, pair2
    assert m2["servo_checks"]["phase_current_sum"]["valid"]
    assert [f["sensor"] for f in m2["sensor_faults"]] == ["I_V or I_2"]


@pytest.mark.parametrize(("drive", "servo_config", "key", "words"), [
    ({"second_sensor_on": "X"}, None, "axis.drive.second_sensor_on", "expected the phase U, V or W, got 'X'"),
    ({"kind": "dc", "second_sensor_on": "V"}, None, "axis.drive.second_sensor_on", "a DC motor's second current"),
    ({"second_sensor_on": "V"}, {"second_sensor_on": "W"}, "components[0].config.second_sensor_on",
     "'W' contradicts axis.drive.second_sensor_on = 'V'"),
])
def test_a_bad_or_contradicting_second_sensor_phase_is_one_line_naming_the_key(drive, servo_config, key, words):
    from feeddrive.cosim.errors import ScenarioError

    data = _pmsm(**drive)
    if drive.get("kind") == "dc":
        data["axis"]["drive"].pop("pole_pairs")
        data.pop("plant")
    if servo_config is not None:
        data["plant"] = {"fmu": "builtin-pmsm", "parameters": data["plant"]["parameters"]}
        data["components"] = [{"name": "servo", "class": "feeddrive.cosim.sensors_servo:ServoSensors",
                               "config": servo_config, "inputs": {}}]
    with pytest.raises(ScenarioError) as err:
        scenario_from_dict(data, base_dir=EXAMPLES)
    assert key in str(err.value) and words in str(err.value) and "\n" not in str(err.value), str(err.value)


def test_no_second_sensor_is_said_not_paired_with_a_copy():
    """``second_sensor_on: null`` (the servo sensors' I_2 then repeats I_U): the monitor does not pair I_U with its
    own copy, which would always pass; the check says why. With the phase V stated, a 2 % gain error of I_2
    against I_V is found (gain difference -0.02 +- 0.003)."""
    from feeddrive.cosim.monitor_servo import servo_checks
    from feeddrive.estimator.validation import ValidationOptions

    h, n = 1e-4, 20000
    t = h * np.arange(n)
    rng = np.random.default_rng(1)
    phi = 2 * np.pi * 50 * t
    i = {k: 5 * np.cos(phi - a) + 0.05 * rng.standard_normal(n) for k, a in zip(("I_U", "I_V", "I_W"),
                                                                                  (0, 2 * np.pi / 3, 4 * np.pi / 3))}
    signals = i | {"I_2": 1.02 * i["I_V"] + 0.05 * rng.standard_normal(n), "phi_el": phi}
    args = (signals, h, 4, None, 0.01, 0.005, 0.005, 0.0, ValidationOptions(alpha=0.01))
    out, faults, skipped = servo_checks(*args, second_on=None)
    assert "phase_sensor_pair" not in out
    assert skipped["phase_sensor_pair"] == "not checked: one current sensor per phase (second_sensor_on: none)"
    out, faults, _ = servo_checks(*args, second_on="V")
    assert not out["phase_sensor_pair"]["valid"] and out["phase_sensor_pair"]["phase"] == "V"
    assert out["phase_sensor_pair"]["gain_diff"] == pytest.approx(-0.02, abs=0.003)
    assert [f["sensor"] for f in faults] == ["I_V or I_2"]
