"""Scenario loading: typed objects, the built-in plant's map, and one clear message per kind of mistake."""
from __future__ import annotations

import re
import sys
import textwrap
import zipfile
from pathlib import Path

import pytest
import yaml

from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.scenario import BUILTIN_MAP, load_scenario, scenario_from_dict, sha256

BASE = """\
name: t
step: 1.0e-4
plant:
  fmu: builtin
nc:
  program:
    - rapid: {to: 0.01}
"""


def write(tmp_path: Path, text: str, name: str = "s.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def error_of(path: Path) -> str:
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    message = str(info.value)
    assert "\n" not in message
    return message


def test_builtin_scenario_is_typed_resolved_and_frozen(tmp_path, feeddrive_fmu):
    s = load_scenario(write(tmp_path, BASE))
    assert s.step == 1e-4 and s.stop_time is None and s.nc.program[0].rapid.to == 0.01
    assert Path(s.plant.fmu).is_absolute() and s.plant.sha256 == sha256(Path(s.plant.fmu))
    assert {r: e.var for r, e in s.plant.map.items()} == BUILTIN_MAP
    assert all(e.scale == 1.0 and e.offset == 0.0 for e in s.plant.map.values())
    with pytest.raises(Exception):
        s.step = 1.0  # frozen


def test_resolved_dict_round_trips(tmp_path, feeddrive_fmu):
    s = load_scenario(write(tmp_path, BASE + "events:\n  - {time: 0.1, target: plant.Cd, value: 1.5}\n"))
    data = s.to_dict()
    again = scenario_from_dict(yaml.safe_load(yaml.safe_dump(data)), base_dir=tmp_path)
    assert again.to_dict() == data
    assert again.plant.fmu == s.plant.fmu and again.events[0].value == 1.5


def test_changed_fmu_is_refused_by_its_recorded_hash(tmp_path, feeddrive_fmu):
    data = load_scenario(write(tmp_path, BASE)).to_dict()
    data["plant"]["sha256"] = "0" * 64
    with pytest.raises(ScenarioError, match=r"plant\.sha256: .* has sha256 [0-9a-f]{64}, expected 0{64}"):
        scenario_from_dict(data)


@pytest.mark.parametrize("snippet, line, pattern", [
    ("plant:\n  fmu: builtin\n  fmuu: x\n", 3,
     r"plant\.fmuu: unknown key 'fmuu'; expected one of: build, call_timeout, fmu, input_hold, interface, map, oversample, parameters, sha256, start, tolerance"),
    ("step: fast\n", 1, r"step: Input should be a valid number.*got 'fast'"),
    ("step: -1.0e-4\n", 1, r"step: Input should be greater than 0, got -0.0001"),
    ("plant:\n  fmu: missing/plant.fmu\n", 2, r"plant\.fmu: FMU file not found: .*missing/plant\.fmu \(expected"),
    ("plant:\n  fmu: builtin\n  map:\n    speed: {var: Motor.n}\n", 4,
     r"plant\.map\.speed\.var: FMU 'FeedDrive\.fmu' has no variable 'Motor\.n'; its Real outputs are: .*\bw\b"),
    ("plant:\n  fmu: builtin\n  map:\n    speed_ref: {var: w}\n", 4,
     r"plant\.map\.speed_ref\.var: 'w' has causality 'output'; role 'speed_ref' needs an input"),
    ("plant:\n  fmu: builtin\n  parameters: {Rr: 1.0}\n", 3, r"plant\.parameters\.Rr: .* no Real parameter 'Rr'"),
    ("events:\n  - {time: 1.0, target: plant.bypass, value: 1}\n", 2,
     r"events\[0\]\.target: 'bypass' is not a tunable Real parameter"),
    ("events:\n  - {time: 1.0, target: spindle.speed, value: 1}\n", 2,
     r"events\[0\]\.target: unknown component 'spindle'"),
    ("record: 3\n", 1, r"record: Input should be 'all' or a valid list, got 3"),
    ("plant:\n  fmu: builtin\n  parameters: {R: -0.5}\n", 3,
     r"plant\.parameters\.R: R = -0\.5 is outside the range \(0, inf\] that FeedDrive\.fmu declares"),
    # R > 0: the FMU declared min 0 and refused R = 0 at run time (fmi2SetReal at t = 0, exit 1); the declared
    # min is now the next double above 0, so the reader refuses it with the range (found by audit4)
    ("plant:\n  fmu: builtin\n  parameters: {R: 0}\n", 3,
     r"plant\.parameters\.R: R = 0 is outside the range \(0, inf\] that FeedDrive\.fmu declares \(min 5e-324, "
     r"the smallest double above 0: R > 0\)"),
    ("events:\n  - {time: 1.0, target: plant.Jt, value: -1}\n", 2,
     r"events\[0\]\.value: Jt = -1 is outside the range \(0, inf\]"),
    ("nc:\n  program:\n    - rapid: {to: 0.1, accel: -1}\n", 3, r"nc\.program\[0\]\.rapid\.accel: .*greater than 0"),
    # a YAML `true` was seed 1, "2.0" seed 2 (pydantic's lax integers; found by audit3)
    ("sensors:\n  seed: true\n", 2, r"sensors\.seed: Input should be a valid integer, got True"),
    ("sensors:\n  seed: 2.0\n", 2, r"sensors\.seed: Input should be a valid integer, got 2\.0"),
])
def test_each_mistake_gets_its_own_message_with_file_and_line(tmp_path, feeddrive_fmu, snippet, line, pattern):
    base = {k: v for k, v in yaml.safe_load(BASE).items() if k not in yaml.safe_load(snippet)}
    text = snippet + yaml.safe_dump(base, sort_keys=False)
    path = write(tmp_path, text)
    message = error_of(path)
    assert message.startswith(f"{path}:{line}: "), message
    assert re.search(pattern, message), message


def test_the_declared_range_is_the_one_the_fmu_enforces(tmp_path, feeddrive_fmu):
    """What the reader accepts, the FMU accepts when the run sets it: the smallest positive R, and Cd = 0 (Cd >= 0)."""
    from fmpy import read_model_description

    md = {v.name: v for v in read_model_description(str(feeddrive_fmu)).modelVariables}
    assert float(md["R"].min) == 5e-324 and float(md["Cd"].min) == 0.0  # R > 0 strict, Cd >= 0 not
    base = {k: v for k, v in yaml.safe_load(BASE).items() if k != "plant"}
    s = load_scenario(write(tmp_path, yaml.safe_dump(base | {"plant": {"parameters": {"R": 5e-324, "Cd": 0.0}}})))
    assert s.plant.parameters["R"] == 5e-324 and s.plant.parameters["Cd"] == 0.0


def test_fmi1_fmu_is_refused(tmp_path):
    fmu = tmp_path / "fmi1.fmu"
    with zipfile.ZipFile(fmu, "w") as z:
        z.writestr("modelDescription.xml", '<?xml version="1.0"?><fmiModelDescription fmiVersion="1.0" '
                                           'modelName="m" guid="x"/>')
    message = error_of(write(tmp_path, BASE.replace("fmu: builtin", "fmu: fmi1.fmu")))
    assert "plant.fmu: fmi1.fmu is an FMI 1.0 FMU; expected FMI 2.0 or 3.0" in message
    (tmp_path / "junk.fmu").write_text("not a zip")
    message = error_of(write(tmp_path, BASE.replace("fmu: builtin", "fmu: junk.fmu")))
    assert "plant.fmu:" in message and "not an FMU" in message


def test_vendor_fmu_without_map_names_the_missing_roles(tmp_path, feeddrive_fmu):
    message = error_of(write(tmp_path, BASE.replace("fmu: builtin", f"fmu: {feeddrive_fmu}")))
    assert "plant.map: roles speed_ref, voltage, current, speed, position are not mapped" in message


def test_yaml_syntax_error_names_the_line(tmp_path):
    message = error_of(write(tmp_path, "name: t\nnc: {program: [\n"))
    assert message.startswith(f"{tmp_path / 's.yaml'}:3: invalid YAML")


def test_monitor_is_skipped_with_a_warning_when_unavailable(tmp_path, feeddrive_fmu, monkeypatch):
    monkeypatch.setitem(sys.modules, "feeddrive.cosim.monitor", None)  # import fails
    with pytest.warns(UserWarning, match="running without a monitor"):
        s = load_scenario(write(tmp_path, BASE + "monitor: {}\n"))
    assert s.monitor is None


def test_monitor_class_replaces_the_default(tmp_path, feeddrive_fmu):
    s = load_scenario(write(tmp_path, BASE + "monitor: {class: 'feeddrive.cosim.sensors:SensorsComponent', config: {seed: 3}}\n"))
    assert s.monitor.class_ == "feeddrive.cosim.sensors:SensorsComponent" and s.monitor.config == {"seed": 3}
    assert s.to_dict()["monitor"] == {"class": "feeddrive.cosim.sensors:SensorsComponent", "config": {"seed": 3}}


def test_builtin_drive_chain_is_the_default_of_nc_and_encoder(tmp_path, feeddrive_fmu):
    text = BASE.replace("fmu: builtin", "fmu: builtin\n  parameters: {pitch: 0.01, belt_ratio: 2.0}")
    s = load_scenario(write(tmp_path, text))
    assert (s.nc.pitch, s.nc.belt_ratio) == (0.01, 2.0)
    assert (s.sensors.encoder.pitch, s.sensors.encoder.belt_ratio) == (0.01, 2.0)
    # a second, different value is a contradiction naming both keys (it used to win silently)
    with pytest.raises(ScenarioError, match=r"nc\.pitch = 0\.005 contradicts plant\.parameters\.pitch = 0\.01"):
        load_scenario(write(tmp_path, text.replace("nc:\n", "nc:\n  pitch: 0.005\n")))
