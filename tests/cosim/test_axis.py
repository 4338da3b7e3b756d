"""One axis description: the drive chain stated once in the scenario reaches the NC, the encoder and
the built-in plant; contradictions name both keys; other pitches run without false alarms.
"""
from __future__ import annotations

import math
import runpy
from pathlib import Path

import pytest

from feeddrive.cosim.axis import Axis, parameter_units
from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import scenario_from_dict

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
TRUTH = {"R": 0.6, "L": 0.004, "K": 1.05, "Jt": 0.1, "ft": 0.02, "Cd": 1.2}
VENDOR_MAP = {"speed_ref": {"var": "n_cmd", "scale": 30 / math.pi}, "load": {"var": "T_load"},
              "voltage": {"var": "U_arm"}, "voltage_ref": {"var": "U_ref"}, "current": {"var": "I_arm"},
              "speed": {"var": "n_mot", "scale": math.pi / 30}, "position": {"var": "x_mm", "scale": 0.001}}


def data(axis="X", plant=None, nc=None, sensors=None, pitch=0.02, seed=1):
    """A tool change at the motor's ~69 rad/s whatever the pitch (table speeds scale with it)."""
    k = pitch / 0.02
    program = [{"dwell": {"time": 0.2}},
               {"tool_change": {"position": 0.27 * k, "v_max": 0.22 * k, "accel": 0.6 * k, "time": 0.3}}]
    return {"name": "axis", "axis": axis, "step": 1e-4, "plant": plant or {"fmu": "builtin"},
            "sensors": {"seed": seed, **(sensors or {})},
            "nc": {"identification": {"distance": 0.2 * k, "v_max": 0.22 * k, "accel": 0.6 * k}, "program": program,
                   **(nc or {})},
            "monitor": {"db": ":memory:"}}


def test_units_follow_the_side():
    assert parameter_units("motor") == {"R": "Ohm", "L": "H", "K": "N.m/A", "Jt": "kg.m2", "ft": "N.m.s/rad",
                                        "Cd": "N.m", "T0": "N.m"}
    assert Axis(kind="linear", side="table").parameter_units() == parameter_units("table", "linear")
    assert parameter_units("table", "linear")["Jt"] == "kg" and parameter_units("table", "rotary")["Jt"] == "kg.m2"
    assert Axis.model_validate("Y").name == "Y"  # the old ``axis: Y``
    assert Axis(pitch=0.01, ratio=2.0).motor_rad_per_unit() == pytest.approx(2 * math.pi * 2 / 0.01)
    assert Axis(kind="rotary", ratio=10.0).motor_rad_per_unit() == pytest.approx(10.0)


def test_axis_section_reaches_nc_encoder_and_builtin_plant(feeddrive_fmu):
    s = scenario_from_dict(data(axis={"name": "Z", "pitch": 0.01, "ratio": 2.0}))
    assert s.axis.name == "Z" and (s.axis.pitch, s.axis.ratio) == (0.01, 2.0)
    assert (s.nc.pitch, s.nc.belt_ratio) == (0.01, 2.0)
    assert (s.sensors.encoder.pitch, s.sensors.encoder.belt_ratio) == (0.01, 2.0)
    assert (s.plant.parameters["pitch"], s.plant.parameters["belt_ratio"]) == (0.01, 2.0)
    # the resolved scenario reads back to the same axis (no contradiction with the copies)
    again = scenario_from_dict(s.to_dict())
    assert again.axis == s.axis and again.monitor.config.axis == "Z"
    # nothing stated: the built-in model's design values; the old ``axis: X`` still works
    s = scenario_from_dict(data())
    assert (s.axis.name, s.axis.pitch, s.axis.ratio, s.nc.pitch, s.sensors.encoder.pitch) == ("X", 0.02, 1.0, 0.02, 0.02)


@pytest.mark.parametrize(("kw", "second", "first"), [
    ({"axis": {"pitch": 0.01}, "nc": {"pitch": 0.02}}, "nc.pitch = 0.02", "axis.pitch = 0.01"),
    ({"axis": {"pitch": 0.01}, "sensors": {"encoder": {"pitch": 0.005}}}, "sensors.encoder.pitch = 0.005",
     "axis.pitch = 0.01"),
    ({"axis": {"ratio": 2}, "plant": {"fmu": "builtin", "parameters": {"belt_ratio": 3}}},
     "plant.parameters.belt_ratio = 3", "axis.ratio = 2"),
    ({"nc": {"pitch": 0.01}, "sensors": {"encoder": {"pitch": 0.02}}}, "sensors.encoder.pitch = 0.02", "nc.pitch = 0.01"),
])
def test_a_contradicting_definition_names_both_keys(feeddrive_fmu, kw, second, first):
    with pytest.raises(ScenarioError, match=rf"{second.replace('.', '[.]')} contradicts {first.replace('.', '[.]')}; "
                                            "state the drive chain once"):
        scenario_from_dict(data(**kw))


def test_bad_axis_sections_are_one_line_errors(feeddrive_fmu):
    with pytest.raises(ScenarioError, match=r"axis.*pitch"):
        scenario_from_dict(data(axis={"pitch": -0.01}))
    with pytest.raises(ScenarioError, match=r"axis.*unknown key 'pich'"):
        scenario_from_dict(data(axis={"pich": 0.01}))
    with pytest.raises(ScenarioError, match=r"rotary axis has no ball-screw pitch"):
        scenario_from_dict(data(axis={"kind": "rotary", "pitch": 0.01}))


@pytest.fixture(scope="module")
def vendor_fmu_10mm(tmp_path_factory, fmu_cache_dir) -> Path:
    """The example's vendor FMU (rpm, mm, other names) built with a 10 mm ball-screw pitch."""
    build = runpy.run_path(str(EXAMPLES / "vendor_fmu" / "build_vendor_fmu.py"))
    return build["main"](["--out", str(tmp_path_factory.mktemp("vendor") / "VendorDrive.fmu"), "--pitch", "0.01"])


def _check_healthy(motion: dict, names) -> None:
    assert motion["validated"] and motion["sensor_faults"] == [] and motion["diagnosis"] == []
    for name in names:
        p = motion["parameters"][name]
        assert p["ci95"][0] <= TRUTH[name] <= p["ci95"][1], (name, p)
        assert p["unit"] == parameter_units("motor")[name]


@pytest.mark.slow
def test_vendor_axis_with_10_mm_pitch_has_no_false_sensor_fault(vendor_fmu_10mm, tmp_path):
    plant = {"fmu": str(vendor_fmu_10mm), "map": VENDOR_MAP}
    # the old way: nc.pitch alone now reaches the encoder too (it used to keep 20 mm: "w_enc gain 0.5")
    old = scenario_from_dict(data(plant=plant, nc={"pitch": 0.01}, pitch=0.01))
    assert old.sensors.encoder.pitch == 0.01 and old.axis.pitch == 0.01
    # the scenario left at the built-in 20 mm is refused before the run, naming the FMU's parameter
    with pytest.raises(ScenarioError, match=r"axis.pitch = 0.02 contradicts the FMU's pitch = 0.01; expected "
                                            r"axis: \{pitch: 0.01\}"):
        scenario_from_dict(data(plant=plant, pitch=0.01))
    for seed in range(5):
        s = scenario_from_dict(data(axis={"pitch": 0.01}, plant=plant, pitch=0.01, seed=seed))
        report = run_scenario(s, tmp_path / str(seed), plots=False).report
        (motion,) = report["motions"]
        _check_healthy(motion, ("Jt", "ft", "Cd"))
        assert report["drive_chain"]["pitch"] == 0.01 and report["parameter_units"]["Jt"] == "kg.m2"


@pytest.mark.slow
@pytest.mark.parametrize("pitch", [0.005, 0.02])
def test_builtin_plant_with_another_pitch_gives_no_false_alarm(feeddrive_fmu, tmp_path, pitch):
    s = scenario_from_dict(data(axis={"pitch": pitch}, pitch=pitch, seed=2))
    assert s.plant.parameters["pitch"] == pitch
    (motion,) = run_scenario(s, tmp_path, plots=False).report["motions"]
    _check_healthy(motion, TRUTH)


def test_rotary_axis_hands_one_turn_per_pitch_to_the_nc_and_encoder(feeddrive_fmu):
    """A rotary table: position in rad, motor angle = ratio x table angle (pitch 2 pi rad per turn)."""
    s = scenario_from_dict(data(axis={"kind": "rotary", "ratio": 10.0}))
    assert s.axis.pitch is None and s.nc.pitch == s.sensors.encoder.pitch == pytest.approx(2 * math.pi)
    assert s.plant.parameters["pitch"] == pytest.approx(2 * math.pi) and s.plant.parameters["belt_ratio"] == 10.0
    assert s.axis.motor_rad_per_unit() == pytest.approx(10.0)
    assert scenario_from_dict(s.to_dict()).axis == s.axis  # the resolved scenario reads back
    with pytest.raises(ScenarioError, match=r"nc.pitch: expected a positive number \[m\], got 'fast'"):
        scenario_from_dict(data(nc={"pitch": "fast"}))
    with pytest.raises(ScenarioError, match=r"nc.pitch contradicts axis.kind = rotary"):
        scenario_from_dict(data(axis={"kind": "rotary"}, nc={"pitch": 0.01}))


def test_monitor_nominal_values_are_the_axis_own(feeddrive_fmu):
    """``monitor: {nominal: ...}`` replaces the built-in model's design values for the axis's motor."""
    from feeddrive.cosim.monitor import MonitorPipeline
    from feeddrive.estimator.history import History

    s = scenario_from_dict(data() | {"monitor": {"db": ":memory:", "baseline": "nominal", "nominal": {"R": 1.2}}})
    with History(":memory:") as history:
        pipe = MonitorPipeline(s.monitor.config, history, "X")
        assert pipe.baseline()["R"] == (1.2, 0.0) and pipe.baseline()["K"] == (1.05, 0.0)
    with pytest.raises(ScenarioError, match=r"monitor.nominal"):
        scenario_from_dict(data() | {"monitor": {"nominal": {"Q": 1.0}}})
