"""The ``servo`` component is the servo drive's sensors only on a PMSM axis (issue 25, PMSM monitor item 3): there it
steps before the monitor and feeds the monitor's servo inputs; on a DC axis a component of that name is a user
component like any other (stepped after the monitor, never a source of the monitor's ports).

``Impostor`` (loadable as ``test_servo_wiring:Impostor``) offers outputs named like the monitor's inputs."""
from __future__ import annotations

from pathlib import Path

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
