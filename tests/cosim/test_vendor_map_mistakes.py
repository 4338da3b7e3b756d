"""A vendor's FMU as users bring it, with the mistakes they make (audit3): every one refused in one line naming the
file, the key and what was expected (exit 2, before anything is written), or converted right; never a number
taken on trust, never a traceback.

The FMUs are RefAxis (tests/plants/ref_axis.py: rpm, mm, FMI 2.0 and 3.0), built once for the test run, and
copies of it whose modelDescription.xml a test rewrites as a vendor's would read.
"""
from __future__ import annotations

import math
import re
import sys
import zipfile
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "plants"))
from ref_axis import MAP, build  # noqa: E402

from feeddrive.cosim.cli import main  # noqa: E402
from feeddrive.cosim.errors import ScenarioError  # noqa: E402
from feeddrive.cosim.scenario import scenario_from_dict  # noqa: E402

H = 1e-3
PROGRAM = [{"dwell": {"time": 0.05}}, {"tool_change": {"position": 0.02, "v_max": 0.1, "accel": 1.0, "time": 0.05}}]


@pytest.fixture(scope="module")
def fmus(built_once) -> dict[int, Path]:
    """RefAxis as FMI 2.0 and 3.0 (tests/conftest.py built_once: shared with the other modules)."""
    return {2: built_once("RefAxis2", lambda folder: build(folder / "RefAxis2.fmu", 2)),
            3: built_once("RefAxis3", lambda folder: build(folder / "RefAxis3.fmu", 3))}


def rewritten(fmu: Path, out: Path, old: str, new: str) -> Path:
    """A copy of ``fmu`` whose modelDescription.xml has ``old`` replaced by ``new`` (exactly once)."""
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                assert text.count(old) == 1, old
                data = text.replace(old, new).encode()
            dst.writestr(item, data)
    return out


def scenario(fmu: Path, **plant) -> dict:
    return {"name": "vendor", "step": H, "plant": {"fmu": str(fmu), "map": dict(MAP)} | plant,
            "nc": {"program": PROGRAM}}


@pytest.mark.parametrize("version", [2, 3])
def test_a_unit_declared_only_as_display_unit_is_never_taken_on_trust(fmus, tmp_path, version):
    """n_act declared ``displayUnit="rpm"`` and no unit: fmpy's validator failed with KeyError(None) ("invalid
    modelDescription.xml: None"); read as no unit, the rpm would have been taken as rad/s (a false gain 9.549)."""
    bare = _bare(fmus[version], tmp_path / "Bare.fmu")
    speed = {"var": "n_act"}
    with pytest.raises(ScenarioError, match=r"plant\.map\.speed\.var: Bare\.fmu: 'n_act' declares no unit, only the "
                                            r"displayUnit 'rpm' .* expected its true unit stated with unit: '\.\.\.' "
                                            r"\(e\.g\. unit: 'rpm'") as info:
        scenario_from_dict(scenario(bare, map=MAP | {"speed": speed}))
    assert "\n" not in str(info.value)
    s = scenario_from_dict(scenario(bare, map=MAP | {"speed": {"var": "n_act", "unit": "rpm"}}))
    assert s.plant.map["speed"].linear() == (pytest.approx(math.pi / 30, rel=1e-15), 0.0)


def _bare(fmu: Path, out: Path) -> Path:
    """RefAxis with n_act's ``unit="rpm"`` as ``displayUnit="rpm"`` (FMI 3.0: its Float64 element; FMI 2.0: its
    ``<Real/>``, the first element closed after its name)."""
    text = zipfile.ZipFile(fmu).read("modelDescription.xml").decode()
    start = text.index('name="n_act"')
    element = text[start:text.index("/>", start)]
    return rewritten(fmu, out, element, element.replace('unit="rpm"', 'displayUnit="rpm"'))


def test_a_scale_copied_from_cosim_info_says_why_it_is_refused(fmus):
    """``cosim info --map`` prints ``x 0.10472``; copied into the map it was refused as "scale 0.10472 contradicts
    ... rpm -> rad/s is x 0.10472": two equal numbers. The message shows the digits that differ and the tolerance."""
    with pytest.raises(ScenarioError, match=r"plant\.map\.speed\.scale: RefAxis2\.fmu: scale 0\.10472 contradicts the "
                                            r"unit of 'n_act' \(declared rpm; rpm -> rad/s is x 0\.10471976\) "
                                            r"\(agreement to a relative 1e-06 is asked: state all the digits, or no "
                                            r"scale\)"):
        scenario_from_dict(scenario(fmus[2], map=MAP | {"speed": {"var": "n_act", "scale": 0.10472}}))
    # an offset on a current in A: the other sign's conversion is the scale -1, not the offset's "-0"
    with pytest.raises(ScenarioError, match=r"plant\.map\.current\.offset: .*offset 0\.5 contradicts .*\(scale -1: a "
                                            r"direction the FMU counts negative\)"):
        scenario_from_dict(scenario(fmus[2], map=MAP | {"current": {"var": "I", "offset": 0.5}}))


def test_info_map_names_the_display_unit_mistake_in_one_line_exit_2(fmus, tmp_path, capsys):
    import yaml

    bare = _bare(fmus[2], tmp_path / "Bare.fmu")
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(scenario(bare, map=MAP | {"speed": {"var": "n_act"}})))
    assert main(["info", str(bare), "--map", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{path}:" in err and "'n_act' declares no unit, only the displayUnit 'rpm'" in err
    assert main(["info", str(bare)]) == 0  # the FMU itself is listed: nothing wrong with it but that unit


def test_a_start_value_the_fmu_calculates_or_not_finite_is_refused_when_read(fmus):
    """``plant.start: {n_act: 5}`` (an output the FMU calculates) ran, and failed at t = 0 in fmi2SetReal (exit 1,
    "failed"); a NaN parameter or start value the same way: bad input, refused when the scenario is read (exit 2)."""
    with pytest.raises(ScenarioError, match=r"plant\.start\.n_act: RefAxis2\.fmu calculates 'n_act' \(causality "
                                            r"output, no start value\): it cannot be set; expected a variable with a "
                                            r"start value"):
        scenario_from_dict(scenario(fmus[2], start={"n_act": 5.0}))
    for key, name in (("parameters", "pitch_mm"), ("start", "pos_mm")):
        with pytest.raises(ScenarioError, match=rf"plant\.{key}\.{name}: {name} = nan is not a finite number"):
            scenario_from_dict(scenario(fmus[3], **{key: {name: math.nan}}))
    s = scenario_from_dict(scenario(fmus[2], start={"pos_mm": 1.0}, parameters={"pitch_mm": 20.0}))
    assert s.plant.start == {"pos_mm": 1.0}


def test_an_event_after_the_run_or_not_finite_is_refused(fmus):
    """A fault injected after the run's end was dropped without a word (the run's verdict: healthy)."""
    data = scenario(fmus[2], parameters={"pitch_mm": 20.0}) | {"stop_time": 0.3}
    late = data | {"events": [{"time": 0.3, "target": "plant.pitch_mm", "value": 10.0}]}
    with pytest.raises(ScenarioError, match=r"events\[0\]\.time: 0\.3 s is not before the run's end \(0\.3 s, "
                                            r"stop_time\): the event would never be applied"):
        scenario_from_dict(late)
    last = data | {"events": [{"time": 0.299, "target": "plant.pitch_mm", "value": 10.0}]}  # the last step's start
    assert scenario_from_dict(last).events[0].time == 0.299
    nan = data | {"events": [{"time": 0.1, "target": "plant.pitch_mm", "value": math.nan}]}
    with pytest.raises(ScenarioError, match=r"events\[0\]\.value: expected a finite number for plant\.pitch_mm"):
        scenario_from_dict(nan)


def test_a_stop_time_that_cuts_the_motions_is_said(fmus, tmp_path, capsys):
    """The program's tool change runs 0.05 s to ~0.29 s. With a monitor, a stop_time inside it (or before it) left the
    motion unjudged and the run silent about it. It is said before the run and in its summary (a short run stays a
    valid simulation: a slice of a motion, as the loops' parity tests run); without a monitor nothing is judged."""
    import yaml

    from feeddrive.cosim.nc import plan_program
    from feeddrive.cosim.scenario import stop_note

    monitored = scenario(fmus[2]) | {"monitor": {"db": ":memory:"}}
    motion_end = plan_program(scenario_from_dict(monitored).nc)[-1][0]
    judged = math.ceil(motion_end / H - 1e-9) * H
    assert stop_note(scenario_from_dict(monitored)) is None  # the default stop time: the program + 0.3 s
    for stop, where in ((0.1, r"inside the NC program's high-speed motion 1 \(0\.05-[\d.]+ s\): it is not judged"),
                        (0.04, r"before the NC program's first high-speed motion \(0\.05-[\d.]+ s\): the monitor "
                               r"judges nothing")):
        note = stop_note(scenario_from_dict(monitored | {"stop_time": stop}))
        assert re.fullmatch(rf"stop_time: {stop:g} s ends {where}; a stop_time of at least {judged:.10g} s judges it",
                            note), note
        assert stop_note(scenario_from_dict(scenario(fmus[2]) | {"stop_time": stop})) is None  # no monitor
    assert stop_note(scenario_from_dict(monitored | {"stop_time": round(judged, 6)})) is None
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(monitored | {"stop_time": 0.1}))
    assert main(["run", str(path), "--out", str(tmp_path / "o"), "--no-plots", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "\nstop_time: 0.1 s ends inside the NC program's high-speed motion 1" in out
    assert "  motion 1: not judged: the run stopped inside it at 0.1 s (stop_time)\n" in out
    # the page says it at the top too (it read "No high-speed motion was processed in this run.")
    page = (tmp_path / "o" / "report.html").read_text()
    assert ('id="unfinished">motion 1: not judged: the run stopped inside it at 0.1 s (stop_time)</p>' in page
            and "No high-speed motion was processed" not in page)


def test_a_plant_that_diverges_is_named_not_an_overflow():
    """A plant that is not a feed drive (the Reference-FMUs' Feedthrough mapped onto the roles) runs away under the
    NC's position loop until its position overflows the encoder's count: "sensors: OverflowError: cannot convert
    float infinity to integer". The failure names the position, the time and the likely cause."""
    from feeddrive.cosim.errors import SimulationError
    from feeddrive.cosim.sensors import SensorsComponent

    s = SensorsComponent("sensors", {"seed": 1})
    s.setup(0.0, 1e-3, 10)
    s.set_inputs((0.0, 0.0, 0.0, 0.0, 0.01))
    s.step(0)
    for position in (1e305, math.inf, math.nan):
        s.set_inputs((0.0, 0.0, 0.0, 0.0, position))
        with pytest.raises(SimulationError, match=rf"sensors: the plant's position {re.escape(f'{position:.4g}')} m cannot be counted "
                                                  r"by the encoder at t=0\.002 s: the plant diverged"):
            s.step(1)


def test_an_axis_that_did_not_move_is_said_so():
    """A vendor plant whose parameters open its loops (VendorDrive's ``bypass: 1``) never moved: an out-and-back tool
    change still ended at the NC's target, so the run said nothing and the motion's verdict was only "gain_ratio: the
    second signal is constant". The run now says the axis did not move, with both spans."""
    import numpy as np

    from feeddrive.cosim.axis import following_note

    t = np.linspace(0.0, 1.0, 1001)
    ref = 0.1 * np.sin(np.pi * t)  # out to 0.1 m and back
    still = {"plant.position": np.zeros_like(t), "nc.x_ref": ref, "nc.speed_ref": np.gradient(ref)}
    assert following_note(still) == ("the axis did not move: its position spanned 0 m where the NC's spanned 0.1 m; its "
                                     "speed did not follow the NC's speed reference (loops the plant's parameters "
                                     "open, a limit, a fault or plant.map)")
    assert following_note(still | {"plant.position": 0.98 * ref}) is None  # a following axis


def test_a_key_given_twice_is_refused_naming_both_lines(tmp_path):
    """A second ``sensors:`` (or ``name:``) replaced the first silently: its seed and faults were gone. A YAML merge
    (``<<: *base`` then an override) is not a duplicate."""
    from feeddrive.cosim.scenario import load_scenario
    from feeddrive.cosim.yaml_source import read_yaml

    path = tmp_path / "s.yaml"
    path.write_text("name: t\nstep: 1.0e-3\nsensors: {seed: 1, voltage: {noise: 0.5}}\nplant: {fmu: builtin}\n"
                    "nc: {program: [{rapid: {to: 0.01}}]}\nsensors: {seed: 2}\n")
    with pytest.raises(ScenarioError, match=rf"^{re.escape(str(path))}:6: sensors: duplicate key \(first at line 3\); "
                                            r"expected each key once in a mapping"):
        load_scenario(path)
    path.write_text("a: {x: 1, x: 1}\n")
    with pytest.raises(ScenarioError, match=r":1: x: duplicate key \(first at line 1\)"):
        read_yaml(path)
    path.write_text("base: &b {x: 1, y: 2}\nc:\n  <<: *b\n  x: 3\n")
    assert read_yaml(path)[0] == {"base": {"x": 1, "y": 2}, "c": {"x": 3, "y": 2}}


def test_an_empty_unit_is_refused_as_such(fmus):
    """``unit: ""`` was read as dimensionless: "'n_act' is stated in , role 'speed' needs rad/s"."""
    with pytest.raises(ScenarioError, match=r"plant\.map\.speed\.unit: unit is empty; expected a unit such as 'rpm', or "
                                            r"'1' for a dimensionless value$"):
        scenario_from_dict(scenario(fmus[2], map=MAP | {"speed": {"var": "n_act", "unit": " "}}))


def test_an_array_variable_is_refused_for_a_role_a_parameter_or_a_start_value(fmus, tmp_path):
    """An FMI 3.0 array (the Reference-FMUs' StateSpace u, y, x0) mapped onto a role, or given one number, ran and
    failed at t = 0 (exit 1: "set-up failed: ValueError: could not convert string to float: '1 2 3'", "fmi3SetFloat64
    returned fmi3Error: Expected nValues >= 3 but was 1"). RefAxis3 with n_set and pitch_mm declared as arrays of 2."""
    arrays = rewritten(fmus[3], tmp_path / "Arrays.fmu",
                       'unit="rpm" start="0"/>', 'unit="rpm" start="0 0"><Dimension start="2"/></Float64>')
    arrays = rewritten(arrays, tmp_path / "Arrays2.fmu",
                       'unit="mm" start="20"/>', 'unit="mm" start="20 20"><Dimension start="2"/></Float64>')
    with pytest.raises(ScenarioError, match=r"plant\.map\.speed_ref\.var: 'n_set' is an array variable \(FMI 3\.0 "
                                            r"Dimension\); role 'speed_ref' needs a scalar"):
        scenario_from_dict(scenario(arrays))
    as_component = {"name": "c", "step": H, "stop_time": 0.01,
                    "components": [{"name": "a", "fmu": str(arrays), "config": {"parameters": {"pitch_mm": 10.0}},
                                    "inputs": {"T_load": 0.0}}]}
    with pytest.raises(ScenarioError, match=r"components\[0\]\.config\.parameters\.pitch_mm: Arrays2\.fmu: 'pitch_mm' "
                                            r"is an array variable \(FMI 3\.0 Dimension\); expected a scalar variable"):
        scenario_from_dict(as_component)


def test_a_program_faster_than_the_fmus_input_range_is_refused(fmus, tmp_path):
    """n_set declared [-500, 500] rpm: the program's tool change at 0.1 m/s on RefAxis's 20 mm screw is 300 rpm (passes),
    at 0.2 m/s (3 m/s^2) 600 rpm (refused, naming the program's item): FMI forbids an input outside its declared range, and the
    run fed it without a word."""
    text = zipfile.ZipFile(fmus[2]).read("modelDescription.xml").decode()
    start = text.index('name="n_set"')
    element = text[start:text.index("/>", start)]
    limited = rewritten(fmus[2], tmp_path / "Limited2.fmu", element,
                        element.replace('unit="rpm"', 'unit="rpm" min="-500" max="500"'))
    scenario_from_dict(scenario(limited))  # 300 rpm
    fast = scenario(limited)
    fast["nc"]["program"] = [PROGRAM[0], {"tool_change": PROGRAM[1]["tool_change"] | {"v_max": 0.2, "accel": 3.0}}]
    with pytest.raises(ScenarioError, match=r"nc\.program\[1\]: the NC program asks a motor speed of 62\.832 rad/s: "
                                            r"n_set = -600 \(x 9\.5493\), outside the range \[-500, 500\] that "
                                            r"Limited2\.fmu declares for its input"):
        scenario_from_dict(fast)


def test_a_voltage_pair_without_redundancy_is_said(fmus, tmp_path, capsys):
    """RefAxis has no voltage reference: unmapped, the sensors' u_ref measures the plant's voltage (the master's
    fallback), and so does voltage_ref mapped onto the voltage's own variable; the pair's check then passes by
    construction, and the run said "measurements valid" with nothing to tell it compared a signal with itself."""
    import yaml

    monitored = scenario(fmus[2]) | {"monitor": {"db": ":memory:"}}
    assert scenario_from_dict(scenario(fmus[2])).unit_notes == []  # without a monitor no pair is checked
    assert scenario_from_dict(monitored).unit_notes[-1] == (
        "voltage_ref not mapped: the sensors' u_ref measures the plant's voltage, so the voltage pair (u against "
        "u_ref) has no redundancy and its check passes by construction")
    same = monitored | {"plant": monitored["plant"] | {"map": MAP | {"voltage_ref": {"var": "U"}}}}
    assert scenario_from_dict(same).unit_notes[-1].startswith("voltage and voltage_ref both read U: the voltage pair")
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(same))
    assert main(["info", str(fmus[2]), "--map", str(path)]) == 0
    assert capsys.readouterr().out.endswith("  voltage and voltage_ref both read U (no redundancy in the voltage "
                                            "pair)\n  map OK\n")


def test_a_program_line_without_its_settings_is_refused(fmus):
    """``- dwell:`` with nothing under it validated as a line with no move: loading the scenario without a stop_time
    (which plans the program) ended in a bare StopIteration."""
    data = scenario(fmus[2])
    data["nc"]["program"] = [{"dwell": None}, PROGRAM[1]]
    with pytest.raises(ScenarioError, match=r"nc\.program\[0\]: dwell: expected its settings, e\.g\. \{dwell: "
                                            r"\{time: 0\.2\}\}, got nothing"):
        scenario_from_dict(data)
