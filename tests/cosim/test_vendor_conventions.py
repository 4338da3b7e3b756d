"""A vendor's conventions: its speed in a unit that counts no angle, its positive direction the master's negative.

A speed in a unit that counts no angle (``1/min``, ``Hz``, ``1/s``) is never read as rad/s.

pint holds the radian dimensionless, so it converts ``1/min`` into ``rad/s`` by 1/60 and ``Hz`` by 1; a motor
speed declared ``1/min`` (a German data sheet's rpm) then reached the monitor 2 pi too small: a false
``w_tach gain 0.1592`` sensor fault on a healthy drive. The plant's role map, the links into an FMU component
and the master's check of a connection refuse a rate whose angle is unsaid, in one line that names the
variable and the remedy (``unit: 'rpm'``).

A vendor that counts a direction negative (a motor mounted mirrored, an encoder counting down) states it with
the units' conversion of the opposite sign (``scale: -0.001`` on a position in mm); any other scale is still
refused, and the refusal names that option. Before, the sign could not be stated at all: the position loop
closed with the wrong sign ran the table away (-1.58 m on the tool change) while the monitor reported a
``w_enc gain -1`` sensor fault. RefAxis (tests/plants/ref_axis.py, FMI 3.0), relabelled ``1/min``.
"""
from __future__ import annotations

import math
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
import yaml

sys.path.insert(0, str(Path(__file__).parents[1] / "plants"))
from ref_axis import HERE, MAP, model_description, pack  # noqa: E402

from feeddrive.cosim.errors import ScenarioError  # noqa: E402
from feeddrive.cosim.master import Master  # noqa: E402
from feeddrive.cosim.port_units import mismatch  # noqa: E402
from feeddrive.cosim.scenario import scenario_from_dict  # noqa: E402

EXAMPLE = Path(__file__).parents[2] / "examples" / "tool_change.yaml"


@pytest.fixture(scope="module")
def axes(tmp_path_factory) -> dict[str, Path]:
    """RefAxis (FMI 3.0) as built (``rpm``) and the same binary with its speeds declared in 1/min."""
    tmp = tmp_path_factory.mktemp("per_min")
    rpm = pack(tmp / "RefAxis.fmu", 3, HERE, "RefAxis", model_description(3))
    out = {"rpm": rpm}
    for name, old, new in (("per_min", b'"rpm"', b'"1/min"'),
                           ("discrete", b'name="n_set" valueReference="1" causality="input" variability="continuous"',
                            b'name="n_set" valueReference="1" causality="input" variability="discrete"')):
        out[name] = tmp / f"RefAxis_{name}.fmu"
        with zipfile.ZipFile(rpm) as src, zipfile.ZipFile(out[name], "w") as dst:
            for entry in src.namelist():
                data = src.read(entry)
                dst.writestr(entry, data.replace(old, new) if entry == "modelDescription.xml" else data)
    return out


@pytest.mark.parametrize("unit, target, angle", [("1/min", "rad/s", False), ("Hz", "rad/s", False),
                                                 ("1/s", "rad/s", False), ("rpm", "rad/s", True),
                                                 ("deg/s", "rad/s", True), ("deg", "rad", True), ("1", "rad", False)])
def test_a_rate_or_an_angle_must_name_its_angle(unit, target, angle):
    from feeddrive.cosim.unit_map import angle_mismatch

    assert (angle_mismatch(unit, target) is None) == angle
    assert (mismatch(unit, target) is None or "scale" in mismatch(unit, target)) == angle


def test_the_connection_check_names_the_missing_angle():
    assert mismatch("Hz", "rad/s") == ("unit 'Hz' into 'rad/s': one counts an angle, the other not (revolutions "
                                       "or radians?); expected the same unit on both sides")
    assert mismatch("N.m", "N*m") is None and "0.10472 rad/s" in mismatch("rpm", "rad/s")


def plant(fmu: Path, **entries) -> dict:
    d = yaml.safe_load(EXAMPLE.read_text())
    d["plant"] = {"fmu": str(fmu), "interface": "cs", "map": MAP | {k: v for k, v in entries.items()}}
    d["monitor"] = {"db": ":memory:"}
    return d


def test_a_plant_speed_declared_per_minute_is_refused_until_its_unit_is_stated(axes):
    fmu = axes["per_min"]
    with pytest.raises(ScenarioError, match=r"plant\.map\.speed\.var: RefAxis_per_min\.fmu: 'n_act' is declared in "
                                            r"1/min, role 'speed' needs rad/s: 1/min counts no angle where rad/s "
                                            r"counts radians \(revolutions or radians\?\); expected its true unit "
                                            r"stated with unit: '\.\.\.', e\.g\. unit: 'rpm'") as info:
        scenario_from_dict(plant(fmu, speed={"var": "n_act"}, speed_ref={"var": "n_set", "unit": "rpm"}))
    assert "\n" not in str(info.value)
    # the speed command too (it was sent 2 pi too large: x 60 instead of x 9.5493)
    with pytest.raises(ScenarioError, match=r"plant\.map\.speed_ref\.var: .*'n_set' is declared in 1/min"):
        scenario_from_dict(plant(fmu, speed={"var": "n_act", "unit": "rpm"}, speed_ref={"var": "n_set"}))
    s = scenario_from_dict(plant(fmu, speed={"var": "n_act", "unit": "rpm"}, speed_ref={"var": "n_set", "unit": "rpm"}))
    assert s.plant.map["speed"].linear() == (pytest.approx(math.pi / 30, rel=1e-15), 0.0)
    assert s.plant.map["speed_ref"].linear() == (pytest.approx(30 / math.pi, rel=1e-15), 0.0)


def test_a_link_from_a_per_minute_output_into_rpm_is_refused(axes):
    data = {"name": "units", "step": 1e-3, "stop_time": 0.1, "components": [
        {"name": "a", "fmu": str(axes["per_min"]), "inputs": {"n_set": 60.0, "T_load": 0.0}},
        {"name": "b", "fmu": str(axes["rpm"]), "inputs": {"n_set": "a.n_act", "T_load": 0.0}}]}
    with pytest.raises(ScenarioError, match=r"components\[1\]\.inputs\.n_set: a\.n_act -> b\.n_set: unit '1/min' "
                                            r"into 'rpm': 1/min counts no angle where rpm counts radians"):
        scenario_from_dict(data)


def mirrored(fmu: Path, *inverted: str) -> dict:
    """RefAxis as a plant on a short rapid, the roles ``inverted`` mapped with the opposite sign."""
    plant_map = {r: e | ({"scale": -e["scale"]} if r in inverted else {}) for r, e in MAP.items()}
    return {"name": "mirrored", "step": 1e-4, "stop_time": 0.3,
            "plant": {"fmu": str(fmu), "interface": "cs", "input_hold": "zoh", "map": plant_map},
            "sensors": {"current": [{"noise": 0.0}, {"noise": 0.0}], "voltage": {"noise": 0.0},
                        "voltage_ref": {"noise": 0.0}},
            "nc": {"program": [{"rapid": {"to": 0.01}}]}}


def test_a_vendor_counting_the_direction_negative_states_it_with_the_sign_of_the_scale(axes):
    def run(data):
        with Master.from_scenario(scenario_from_dict(data)) as master:
            return master.run().signals()

    s = scenario_from_dict(mirrored(axes["rpm"], "speed_ref", "speed", "position"))
    assert s.plant.map["position"].linear() == (-1e-3, 0.0)
    assert s.unit_notes[-1] == "position <- pos_mm: sign inverted as given, scale -0.001 (the FMU's opposite direction)"
    same, flipped = run(mirrored(axes["rpm"])), run(mirrored(axes["rpm"], "speed_ref", "speed", "position"))
    assert np.abs(same["plant.speed"]).max() > 10
    for role in ("speed", "position"):  # the master sees the same axis ...
        np.testing.assert_array_equal(flipped[f"plant.{role}"], same[f"plant.{role}"])
    np.testing.assert_array_equal(flipped["plant.voltage"], -same["plant.voltage"])  # ... the FMU turned the other way
    np.testing.assert_allclose(flipped["plant.position"], flipped["nc.x_ref"], rtol=0, atol=1e-12)


def test_a_scale_of_neither_sign_is_refused_naming_both(axes):
    with pytest.raises(ScenarioError, match=r"plant\.map\.position\.scale: RefAxis\.fmu: scale -0\.01 contradicts "
                                            r"the unit of 'pos_mm' \(declared mm; mm -> m is x 0\.001\); expected no "
                                            r"scale \(the units convert\), the conversion with the opposite sign "
                                            r"\(scale -0\.001: a direction the FMU counts negative\)"):
        scenario_from_dict(mirrored(axes["rpm"]) | {"plant": {"fmu": str(axes["rpm"]), "map": MAP | {
            "position": {"var": "pos_mm", "scale": -0.01}}}})


def test_a_position_counted_the_other_way_is_named_when_the_axis_runs_away(axes):
    from feeddrive.cosim.axis import following_note

    with Master.from_scenario(scenario_from_dict(mirrored(axes["rpm"], "position"))) as master:
        s = master.run().signals()
    # the position loop closed with the wrong sign: the table leaves the 10 mm rapid's target, away from it
    assert abs(s["plant.position"][-1] - 0.01) > 0.01
    note = following_note(s)
    assert note.startswith("the axis did not follow the NC: it ended ") and "m from the NC's target; its position " \
        "moved against the NC's speed reference: a direction the plant FMU counts negative?" in note
    with Master.from_scenario(scenario_from_dict(mirrored(axes["rpm"], "speed_ref", "speed", "position"))) as master:
        assert following_note(master.run().signals()) is None
    # run_scenario puts it in report.json (the console's summary gets the last sample only), the page shows it
    from markupsafe import escape  # jinja2's

    from feeddrive.cosim.report.page import render_run

    page = render_run({"scenario": "s", "status": "ok", "following": note}, Path("."))
    assert f'<p class="error" id="following">{escape(note)}</p>' in page


def test_a_step_that_is_not_a_multiple_of_the_fmus_fixed_internal_step_is_refused(axes, capsys):
    # RefAxis declares fixedInternalStepSize 5e-5 and takes no partial step: every 7.5e-5 s its outputs would
    # lag by up to 5e-5 s, silently (the Reference-FMUs' Dahlquist, 0.1 s stepped every 0.03 s, showed x(0.1) at 0.12)
    data = mirrored(axes["rpm"]) | {"step": 7.5e-5}
    with pytest.raises(ScenarioError, match=r"step: RefAxis\.fmu steps with a fixed internal step of 5e-05 s "
                                            r"\(fixedInternalStepSize\) and its communication step would be 7\.5e-05 s, "
                                            r"not a multiple of it: its outputs would lag up to 5e-05 s; expected a "
                                            r"communication step that is a multiple of 5e-05 s, or interface: me"):
        scenario_from_dict(data)
    scenario_from_dict(data | {"plant": data["plant"] | {"interface": "me"}})  # the master integrates it
    with pytest.raises(ScenarioError, match=r"communication step would be 2\.5e-05 s.*\(step / plant\.oversample\)"):
        scenario_from_dict(data | {"plant": data["plant"] | {"oversample": 3}})
    scenario_from_dict(mirrored(axes["rpm"]) | {"step": 1.5e-4})  # 3 internal steps
    parts = {"name": "c", "step": 2.5e-5, "stop_time": 0.01,
             "components": [{"name": "a", "fmu": str(axes["rpm"]), "inputs": {"n_set": 60.0, "T_load": 0.0}}]}
    with pytest.raises(ScenarioError, match=r"components\[0\]\.config\.step_multiple: RefAxis\.fmu steps .* "
                                            r"communication step would be 7\.5e-05 s"):
        scenario_from_dict(parts | {"components": [parts["components"][0] | {"config": {"step_multiple": 3}}]})
    scenario_from_dict(parts | {"components": [parts["components"][0] | {"config": {"step_multiple": 2}}]})
    from feeddrive.cosim.cli import main

    assert main(["info", str(axes["rpm"])]) == 0
    assert ("  Co-Simulation: fixed internal step 5e-05 s (fixedInternalStepSize): the communication step must be "
            "a multiple of it\n") in capsys.readouterr().out


def test_a_discrete_input_for_a_role_is_refused_in_model_exchange(axes):
    # there it may change only in event mode, which the master does not enter for an input: the run failed at
    # t = 0 in fmi3SetFloat64 (the Reference-FMUs' Feedthrough), a simulation failure for a bad map
    data = mirrored(axes["discrete"])
    data["plant"]["interface"] = "me"
    with pytest.raises(ScenarioError, match=r"plant\.map\.speed_ref\.var: 'n_set' is a discrete input: in Model "
                                            r"Exchange it may change only in event mode, which the master does not "
                                            r"enter for an input; expected a continuous input, or interface: cs"):
        scenario_from_dict(data)
    data["plant"]["interface"] = "cs"  # set at each communication point
    assert scenario_from_dict(data).plant.map["speed_ref"].var == "n_set"


def test_a_pmsm_axis_without_servo_sensors_names_the_missing_component(axes):
    # a DC FMU (or a vendor PMSM FMU without its servo component) on a PMSM axis: the master said only
    # "input 'monitor.I_U' is not connected; add 'monitor.I_U: <component.output or number>' to connections"
    data = mirrored(axes["rpm"]) | {"axis": {"name": "P", "drive": {"kind": "pmsm"}}, "monitor": {"db": ":memory:"}}
    with pytest.raises(ScenarioError, match=r"axis\.drive\.kind: a PMSM axis's monitor reads the servo drive's sensors "
                                            r"\(I_U, I_V, I_W, \.\.\.\), and no component provides them: expected a "
                                            r"component named servo \(class feeddrive\.cosim\.sensors_servo:ServoSensors\)"
                                            r".*or kind: dc if RefAxis\.fmu is a DC drive"):
        scenario_from_dict(data)
    scenario_from_dict(data | {"axis": {"name": "P", "drive": {"kind": "dc"}}})


@pytest.mark.parametrize("unit", ["1/min", "Hz", "1/s"])
def test_a_recorded_speed_column_per_minute_is_refused_too(tmp_path, unit):
    from feeddrive.cosim.errors import DataError
    from feeddrive.cosim.recorded import load_recording

    path = tmp_path / "r.csv"
    path.write_text(f"t [s],n [{unit}]\n" + "".join(f"{k * 1e-3},{60.0 * k}\n" for k in range(20)))
    with pytest.raises(DataError, match=rf"column 'n \[{unit}\]' \(role speed\): {unit} counts no angle where rad/s "
                                        r"counts radians \(revolutions or radians\?\); expected the unit that says it, "
                                        r"e\.g\. \[rpm\]"):
        load_recording(path, {"time": "t", "speed": "n"})
    path.write_text("t [s],n [rpm]\n" + "".join(f"{k * 1e-3},{60.0 * k}\n" for k in range(20)))
    rec = load_recording(path, {"time": "t", "speed": "n"})
    np.testing.assert_allclose(rec.signals["speed"], 2 * math.pi * np.arange(20), rtol=1e-15)
