"""Vendor FMUs with other names and units (rpm, mm, %) run through a role map with correct conversions."""
from __future__ import annotations

import math
import runpy
import textwrap
from pathlib import Path

import numpy as np
import pytest
import yaml

from feeddrive.cosim.master import Master
from feeddrive.cosim.scenario import load_scenario, scenario_from_dict

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def run(scenario) -> dict:
    with Master.from_scenario(scenario) as master:
        return master.run().signals()


@pytest.mark.slow
def test_example_vendor_fmu_matches_the_builtin_plant(built_once, feeddrive_fmu):
    """The example's vendor FMU (same physics, rpm / mm interface) gives the built-in plant's signals."""
    build = runpy.run_path(str(EXAMPLES / "vendor_fmu" / "build_vendor_fmu.py"))
    fmu = built_once("VendorDrive", lambda folder: build["main"](["--out", str(folder / "VendorDrive.fmu")]))
    data = yaml.safe_load((EXAMPLES / "vendor_fmu.yaml").read_text())
    data.pop("monitor", None)
    data["stop_time"] = 1.0
    data["plant"]["fmu"] = str(fmu)
    vendor = run(scenario_from_dict(data))
    builtin = {k: v for k, v in data.items() if k != "plant"} | {"plant": {"parameters": data["plant"]["parameters"]}}
    reference = run(scenario_from_dict(builtin))
    for name in ("plant.speed", "plant.position", "plant.current", "plant.voltage", "plant.voltage_ref"):
        scale = np.abs(reference[name]).max()
        assert scale > 0
        np.testing.assert_allclose(vendor[name], reference[name], rtol=0, atol=1e-10 * scale, err_msg=name)
    assert np.abs(reference["plant.speed"]).max() > 60  # a real rapid traverse (rad/s)


IDEAL_AXIS = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class IdealAxis(Fmi2Slave):
    """An ideal speed-controlled axis with a vendor's units.

    n_act [rpm] = n_set; pos_mm [mm] integrates n_set / 60 * 20 mm per turn; U [V] = 0.11 V/rpm * n_act;
    I_pct [%] = 50 + 2.5 * T_load / 1.05 (bipolar current output: 50 % is 0 A, 2.5 % per A).
    """

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.n_set = self.T_load = self.n_act = self.pos_mm = self.U = 0.0
        self.I_pct = 50.0
        for name in ("n_set", "T_load"):
            self.register_variable(Real(name, causality=Fmi2Causality.input))
        for name in ("n_act", "pos_mm", "U", "I_pct"):
            self.register_variable(Real(name, causality=Fmi2Causality.output))

    def do_step(self, t, dt):
        self.n_act = self.n_set
        self.pos_mm += self.n_set / 60.0 * 20.0 * dt
        self.U = 0.11 * self.n_act
        self.I_pct = 50.0 + 2.5 * self.T_load / 1.05
        return True
'''

SCENARIO = """\
name: ideal-axis
step: 1.0e-4
stop_time: 0.75
plant:
  fmu: {fmu}
  map:
    speed_ref: {{var: n_set, scale: {rpm}}}
    load:      {{var: T_load}}
    voltage:   {{var: U}}
    current:   {{var: I_pct, scale: 0.4, offset: -20.0}}
    speed:     {{var: n_act, scale: {rad}}}
    position:  {{var: pos_mm, scale: 0.001}}
sensors:
  current: [{{noise: 0.0}}, {{noise: 0.0}}]
  voltage: {{noise: 0.0}}
  voltage_ref: {{noise: 0.0}}
nc:
  program:
    - rapid: {{to: 0.01}}
    - feed: {{to: 0.012, feed: 0.005, load: 5.0}}
"""


def test_python_fmu_with_rpm_mm_and_percent_is_converted_exactly(tmp_path):
    from pythonfmu.builder import FmuBuilder

    script = tmp_path / "ideal_axis.py"
    script.write_text(textwrap.dedent(IDEAL_AXIS))
    fmu = FmuBuilder.build_FMU(script, dest=tmp_path)
    path = tmp_path / "ideal.yaml"
    path.write_text(SCENARIO.format(fmu=fmu, rpm=30 / math.pi, rad=math.pi / 30))
    scenario = load_scenario(path)
    s = run(scenario)
    speed_ref, x_ref, load = s["nc.speed_ref"], s["nc.x_ref"], s["nc.load"]
    assert np.abs(speed_ref).max() > 10 and np.abs(load).max() == 5.0
    # plant outputs at t_{n+1} come from the NC's outputs at t_{n+1} (the NC runs first)
    np.testing.assert_allclose(s["plant.speed"], speed_ref, rtol=1e-14, atol=1e-12)       # rpm <-> rad/s
    np.testing.assert_allclose(s["plant.voltage"], 0.11 * 30 / math.pi * speed_ref, rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(s["plant.current"][1:], load[1:] / 1.05, rtol=0, atol=1e-12)  # % with offset
    # an ideal speed-controlled axis follows the NC's plan exactly at every grid point (mm -> m)
    np.testing.assert_allclose(s["plant.position"], x_ref, rtol=0, atol=1e-12)
    assert x_ref[-1] == pytest.approx(0.012, abs=1e-15)
    # no voltage_ref in the map: the sensors measure the voltage for both channels
    np.testing.assert_array_equal(s["sensors.u_ref"], s["sensors.u"])
