"""``axis: {drive: {kind: pmsm, pole_pairs: 4}}``: the plant, role map and servo sensors it selects, its refusals,
and the servo redundancies on `cosim run` signals (built-in PMSM: no lost motion; vendor PMSM: 0.02 mm found)."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from feeddrive.cosim.cli import main
from feeddrive.cosim.drive import SERVO_WIRING
from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import PMSM_MAP, load_scenario, scenario_from_dict
from feeddrive.estimator import redundancy_servo as rs

sys.path.insert(0, str(Path(__file__).parents[1] / "plants"))
from vendor_pmsm import ROLE_MAP  # noqa: E402

EXAMPLE = Path(__file__).parents[2] / "examples" / "pmsm_axis.yaml"
H = 1e-4


def example(**changes) -> dict:
    data = yaml.safe_load(EXAMPLE.read_text())
    data["stop_time"] = 1.0
    for key, value in changes.items():
        data[key] = value
    return data


def test_the_drive_selects_the_pmsm_plant_its_map_and_the_servo_sensors(tmp_path):
    s = load_scenario(EXAMPLE)
    assert s.axis.drive.kind == "pmsm" and s.axis.drive.pole_pairs == 4
    assert Path(s.plant.fmu).name == "PMSMFeedDrive.fmu"
    assert {r: e.var for r, e in s.plant.map.items()} == PMSM_MAP
    (servo,) = [c for c in s.components if c.name == "servo"]
    assert servo.class_ == "feeddrive.cosim.sensors_servo:ServoSensors" and servo.inputs == SERVO_WIRING
    assert servo.config["pole_pairs"] == 4
    # the resolved scenario reads back with one servo component
    again = scenario_from_dict(s.to_dict())
    assert [c.name for c in again.components] == ["servo"]
    # no drive stated: the DC plant, no servo sensors (unchanged behaviour)
    data = example()
    data["axis"] = {"name": "X"}
    data.pop("plant")
    dc = scenario_from_dict(data)
    assert Path(dc.plant.fmu).name != "PMSMFeedDrive.fmu" and dc.components == [] and dc.axis.drive is None


@pytest.mark.parametrize(("axis", "plant", "key", "words"), [
    ({"drive": {"kind": "pmsm", "pole_pairs": 3}}, None, "axis.drive.pole_pairs", "contradicts plant.parameters.p = 4"),
    ({"drive": {"kind": "pmsm"}}, {"fmu": "builtin"}, "plant.fmu", "built-in DC plant but axis.drive.kind is pmsm"),
    ({"drive": {"kind": "dc"}}, {"fmu": "builtin-pmsm"}, "plant.fmu", "built-in PMSM plant but axis.drive.kind is dc"),
    ({"drive": {"kind": "bldc"}}, None, "axis.drive.kind", "expected dc or pmsm"),
    ({"drive": {"kind": "dc", "pole_pairs": 2}}, None, "axis.drive.pole_pairs", "a DC motor has no pole pairs"),
    ({"drive": {"kind": "pmsm", "pole_pairs": 2.5}}, None, "axis.drive.pole_pairs", "expected an integer >= 1"),
    ({"drive": {"kind": "pmsm", "poles": 8}}, None, "axis.drive.poles", "unknown key"),
])
def test_contradictions_are_one_line_errors(tmp_path, axis, plant, key, words):
    data = example()
    data["axis"] = {"name": "X"} | axis
    if plant is not None:
        data["plant"] = plant
    elif axis["drive"].get("kind") == "dc":
        data.pop("plant")
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    msg = str(err.value)
    assert "\n" not in msg and key in msg and words in msg and msg.startswith(str(path)), msg
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2  # bad input: exit 2, no traceback


def test_builtin_pmsm_run_phase_currents_and_no_lost_motion(tmp_path):
    """The example's tool change (out 0.2 m, dwell, back) through `cosim run`, with an event at 1 s (in the dwell)
    raising phase V's sensor gain to 1.03: on the way out the phase currents sum to zero within their noise and
    agree with i_q; on the way back the sum isolates phase V and its gain (within 0.005). The built-in drive chain
    has no play, so the two encoders show no lost motion (the 95 % interval within half a count of the motor
    encoder, +-0.5 um, of 0: at 0.3 m/s the axis moves exactly 30 counts per sample, so the encoder's rounding
    error does not average out within a direction; measured -0.05 +- 0.08 um)."""
    data = example(stop_time=2.1, events=[{"time": 1.0, "target": "servo.I_V.gain", "value": 1.03}])
    s = run_scenario(scenario_from_dict(data), tmp_path / "run", plots=False).signals
    i = [s[f"servo.I_{k}"] for k in "UVW"]
    n = np.arange(len(i[0]))
    moving = np.abs(s["plant.speed"]) > 1
    out, back = moving & (n < 10_000), moving & (n > 10_000)
    check = rs.phase_current_sum(*(x[out] for x in i))
    assert not check.faulty and check.noise_std == pytest.approx(0.05 * math.sqrt(3), rel=0.1)
    phi = 4 * s["plant.theta"][out]
    assert not rs.dq_current_consistency(s["plant.current"][out], *(x[out] for x in i), phi).faulty
    fault = rs.phase_current_sum(*(x[back] for x in i))
    assert fault.faulty and fault.phase == "V" and fault.gain == pytest.approx(1.03, abs=0.005)
    lm = rs.lost_motion(s["servo.x_mot"] * 1e3, s["servo.x_lin"] * 1e3, H)
    assert not lm.detected and -5e-4 < lm.ci95_mm[0] and lm.ci95_mm[1] < 5e-4, lm


def test_vendor_pmsm_with_lost_motion_through_cosim_run(vendor_pmsm_fmu, tmp_path):
    """The vendor FMU (A rms, mm, electrical angle) with 0.02 mm lost motion, its servo sensors wired by the
    scenario with ``scales``: the two encoders measure 0.02 mm within 0.2 um."""
    data = example(stop_time=2.1)
    data["axis"] = {"name": "V", "pitch": 0.01, "drive": {"kind": "pmsm", "pole_pairs": 4}}
    data["plant"] = {"fmu": str(vendor_pmsm_fmu), "map": ROLE_MAP, "parameters": {"lost_motion_mm": 0.02}}
    wiring = {"i_d": "plant.I_d_rms", "i_q": "plant.current", "theta": "plant.phi_el", "u_d_ref": "plant.U_d_soll",
              "u_q_ref": "plant.voltage_ref", "u_d": "plant.U_d", "u_q": "plant.voltage", "x_table": "plant.s_lin_mm"}
    data["components"] = [{"name": "servo", "class": "feeddrive.cosim.sensors_servo:ServoSensors", "inputs": wiring,
                           "config": {"seed": 2, "scales": {"i_d": math.sqrt(2), "theta": 0.25, "x_table": 1e-3}}}]
    scenario = scenario_from_dict(data)
    s = run_scenario(scenario, tmp_path / "run", plots=False).signals
    lm = rs.lost_motion(s["servo.x_mot"] * 1e3, s["servo.x_lin"] * 1e3, H)
    assert lm.detected and lm.value_mm == pytest.approx(0.02, abs=2e-4), lm
    # and a pole-pair count contradicting the vendor's p is refused
    data["axis"]["drive"]["pole_pairs"] = 3
    with pytest.raises(ScenarioError, match="axis.drive.pole_pairs: 3 contradicts the FMU's p = 4"):
        scenario_from_dict(data)


def test_servo_sensors_refuse_an_unknown_input_scale():
    from feeddrive.cosim.master import Master

    data = example()
    data["components"] = [{"name": "servo", "class": "feeddrive.cosim.sensors_servo:ServoSensors",
                           "config": {"scales": {"i_x": 1.0}}, "inputs": dict(SERVO_WIRING)}]
    with pytest.raises(ScenarioError) as err:
        Master.from_scenario(scenario_from_dict(data))
    msg = str(err.value)
    assert "\n" not in msg and "scales.i_x" in msg and "'x_table'" in msg, msg
