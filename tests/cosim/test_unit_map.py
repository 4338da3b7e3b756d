"""Units on the plant map (issue 23 item 1): every entry converted from the FMU's declared unit, never trusted.

A C FMU (``tests/plants/foreign_units_drive.py``) is the built-in feed drive behind an interface in rpm, mm,
mA and kN.m. Mapped without a single scale, its run must be the built-in plant's: same signals to rounding,
estimates within each other's intervals, no sensor fault. A unit that cannot be the role's, or a scale that
contradicts the declared units, is one line naming the variable and both units (exit 2).
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from feeddrive.cosim.cli import main
from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import scenario_from_dict

sys.path.insert(0, str(Path(__file__).parents[1] / "plants"))
from foreign_units_drive import ROLE_MAP, build_foreign_drive  # noqa: E402

ROOT = Path(__file__).parents[2]
EXAMPLE = ROOT / "examples" / "tool_change.yaml"


@pytest.fixture(scope="module")
def foreign_fmu(tmp_path_factory) -> Path:
    return build_foreign_drive(tmp_path_factory.mktemp("foreign") / "ForeignDrive.fmu")


def data(plant: dict | None = None) -> dict:
    d = yaml.safe_load(EXAMPLE.read_text())
    if plant is not None:
        d["plant"] = {"interface": "cs", "parameters": d["plant"]["parameters"]} | plant
    d["monitor"] = {"db": ":memory:"}
    return d


@pytest.fixture(scope="module")
def twin_runs(foreign_fmu, feeddrive_fmu, tmp_path_factory):
    si = run_scenario(scenario_from_dict(data()), tmp_path_factory.mktemp("si"), plots=False)
    foreign = run_scenario(scenario_from_dict(data({"fmu": str(foreign_fmu), "map": ROLE_MAP})),
                           tmp_path_factory.mktemp("foreign"), plots=False)
    return si, foreign


def test_the_declared_units_convert_every_role(foreign_fmu):
    s = scenario_from_dict(data({"fmu": str(foreign_fmu), "map": ROLE_MAP}))
    lin = {r: e.linear() for r, e in s.plant.map.items()}
    assert lin["speed"] == (pytest.approx(math.pi / 30, rel=1e-15), 0.0)       # rpm -> rad/s
    assert lin["speed_ref"] == (pytest.approx(30 / math.pi, rel=1e-15), 0.0)   # rad/s -> rpm (FMU input)
    assert lin["position"] == (pytest.approx(1e-3, rel=1e-15), 0.0)            # mm -> m
    assert lin["current"] == (pytest.approx(1e-3, rel=1e-15), 0.0)             # mA -> A
    assert lin["load"] == (pytest.approx(1e-3, rel=1e-15), 0.0)                # N.m -> kN.m (FMU input)
    assert lin["voltage"] == (1.0, 0.0) and s.unit_notes == []


def test_a_foreign_unit_plant_without_scales_runs_as_the_si_plant(twin_runs):
    si, foreign = twin_runs
    for key in ("plant.speed", "plant.current", "plant.position", "sensors.w_tach", "sensors.Im1"):
        scale = np.abs(si.signals[key]).max()
        np.testing.assert_allclose(foreign.signals[key], si.signals[key], rtol=0, atol=1e-9 * scale, err_msg=key)
    (m_si,), (m_f,) = si.report["motions"], foreign.report["motions"]
    assert m_f["sensor_faults"] == [] and m_f["validated"]
    for name, p in m_f["parameters"].items():
        lo, hi = m_si["parameters"][name]["ci95"]
        assert lo <= p["value"] <= hi, (name, p, m_si["parameters"][name])
    assert m_f["parameters"]["L"]["value"] == pytest.approx(4e-3, rel=0.01)


def test_the_vendor_example_without_scales_has_no_sensor_fault(tmp_path):
    """Issue 23: ``speed: {var: n_mot}`` (rpm) was read as rad/s and gave a false ``w_tach gain 9.549``."""
    sys.path.insert(0, str(ROOT / "examples" / "vendor_fmu"))
    from build_vendor_fmu import vendor_model

    from feeddrive.fmu_build import build_fmu

    build_fmu(vendor_model(), tmp_path / "vendor_fmu" / "VendorDrive.fmu")
    d = yaml.safe_load((ROOT / "examples" / "vendor_fmu.yaml").read_text())
    assert "scale" not in d["plant"]["map"]["speed"]  # the example maps n_mot [rpm] as it is
    d["monitor"] = {"db": ":memory:"}
    scenario = scenario_from_dict(d, base_dir=tmp_path)
    assert scenario.plant.map["speed"].linear() == (pytest.approx(math.pi / 30), 0.0)
    result = run_scenario(scenario, tmp_path / "run", plots=False)
    (motion,) = result.report["motions"]
    assert motion["sensor_faults"] == [] and motion["validated"], motion.get("sensor_faults")
    assert motion["parameters"]["K"]["value"] == pytest.approx(1.05, rel=0.01)
    assert np.abs(result.signals["plant.speed"]).max() == pytest.approx(70, rel=0.1)  # rad/s, not rpm


def _yaml(tmp_path, fmu, **entries) -> Path:
    d = data({"fmu": str(fmu), "map": ROLE_MAP | entries})
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    return path


def test_an_incompatible_declared_unit_is_one_line_exit_2(tmp_path, foreign_fmu, capsys):
    path = _yaml(tmp_path, foreign_fmu, speed={"var": "U_ist"})  # V for a speed
    assert main(["info", str(foreign_fmu), "--map", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{path}:" in err and "plant.map.speed.var" in err
    assert "'U_ist' is declared in V" in err and "needs rad/s: incompatible units" in err
    assert main(["run", str(path), "--out", str(tmp_path / "o")]) == 2  # in this process: ~1 s of imports less
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'U_ist' is declared in V" in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("entry, key, pattern", [
    ({"var": "n_ist", "scale": 1.0}, "scale", r"scale 1 contradicts the unit of 'n_ist' \(declared rpm; "
                                              r"rpm -> rad/s is x 0\.10472\)"),
    ({"var": "n_ist", "scale": 0.1}, "scale", r"scale 0\.1 contradicts"),
    ({"var": "n_ist", "offset": 1.0}, "offset", r"offset 1 contradicts"),
    ({"var": "n_ist", "unit": "V"}, "unit", r"'n_ist' is stated in V, role 'speed' needs rad/s: incompatible"),
    ({"var": "n_ist", "unit": "blorps"}, "unit", r"'n_ist' is stated in blorps, a unit pint does not know"),
])
def test_a_contradicting_scale_or_unit_is_refused(tmp_path, foreign_fmu, entry, key, pattern):
    with pytest.raises(ScenarioError, match=rf"plant\.map\.speed\.{key}: ForeignDrive\.fmu: {pattern}") as info:
        scenario_from_dict(data({"fmu": str(foreign_fmu), "map": ROLE_MAP | {"speed": entry}}))
    assert "\n" not in str(info.value)


def test_a_scale_agreeing_with_the_units_or_a_stated_unit_is_accepted(foreign_fmu):
    ok = {"var": "n_ist", "scale": 0.10471975511965977}
    s = scenario_from_dict(data({"fmu": str(foreign_fmu), "map": ROLE_MAP | {"speed": ok}}))
    assert s.plant.map["speed"].linear() == (pytest.approx(math.pi / 30, rel=1e-15), 0.0)
    # the entry says what the FMU's variable really is: its declaration (rpm) is overruled
    stated = {"var": "n_ist", "unit": "rad/s"}
    s = scenario_from_dict(data({"fmu": str(foreign_fmu), "map": ROLE_MAP | {"speed": stated}}))
    assert s.plant.map["speed"].linear() == (1.0, 0.0)


def test_info_prints_each_conversion(tmp_path, foreign_fmu, capsys):
    path = _yaml(tmp_path, foreign_fmu)
    assert main(["info", str(foreign_fmu), "--map", str(path)]) == 0
    out = capsys.readouterr().out
    for line in ("speed [rad/s] <- n_ist [rpm] x 0.10472", "speed_ref [rad/s] -> n_soll [rpm] x 9.5493",
                 "position [m] <- s_ist [mm] x 0.001", "current [A] <- I_ist [mA] x 0.001",
                 "load [N.m] -> M_last [kN.m] x 0.001", "voltage [V] <- U_ist [V] x 1", "map OK"):
        assert f"  {line}\n" in out, out


NO_UNITS = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class Bare(Fmi2Slave):
    """An ideal speed-controlled axis whose variables declare no unit (pythonfmu writes none)."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.w_set = self.T = self.w = self.x = self.U = self.I = 0.0
        for name in ("w_set", "T"):
            self.register_variable(Real(name, causality=Fmi2Causality.input))
        for name in ("w", "x", "U", "I"):
            self.register_variable(Real(name, causality=Fmi2Causality.output))

    def do_step(self, t, dt):
        self.w = self.w_set
        self.x += self.w_set / (2 * 3.141592653589793) * 0.02 * dt
        self.U = 1.05 * self.w
        self.I = self.T / 1.05
        return True
'''


def test_a_variable_without_unit_is_a_stated_assumption(tmp_path, capsys):
    import textwrap

    from pythonfmu.builder import FmuBuilder

    script = tmp_path / "bare.py"
    script.write_text(textwrap.dedent(NO_UNITS))
    fmu = FmuBuilder.build_FMU(script, dest=tmp_path)
    d = data({"fmu": str(fmu), "map": {"speed_ref": {"var": "w_set"}, "load": {"var": "T"},
                                      "voltage": {"var": "U"}, "current": {"var": "I", "scale": 2.0},
                                      "speed": {"var": "w"}, "position": {"var": "x"}}})
    d["stop_time"], d["nc"]["program"] = 0.3, [{"rapid": {"to": 0.01}}]
    d.pop("monitor")
    d["plant"].pop("parameters")
    path = tmp_path / "bare.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    assert main(["info", str(fmu), "--map", str(path)]) == 0
    out = capsys.readouterr().out
    assert "  speed [rad/s] <- w [?]  unit not declared: taken as rad/s\n" in out
    assert "  current [A] <- I [?] x 2  (unit not declared: scale 2 offset 0 as given)\n" in out
    assert main(["run", str(path), "--out", str(tmp_path / "o"), "--no-progress", "--no-plots"]) == 0  # in this process
    stdout = capsys.readouterr().out
    notes = [line for line in stdout.splitlines() if line.startswith("plant.map:")]
    assert notes == ["plant.map: speed_ref <- w_set: unit not declared: taken as rad/s",
                     "plant.map: load <- T: unit not declared: taken as N.m",
                     "plant.map: voltage <- U: unit not declared: taken as V",
                     "plant.map: current <- I: unit not declared: scale 2 offset 0 as given",
                     "plant.map: speed <- w: unit not declared: taken as rad/s",
                     "plant.map: position <- x: unit not declared: taken as m"], stdout
    # and they stay with the results: report.json and the page's summary, not only the console
    report = json.loads((tmp_path / "o" / "report.json").read_text())
    assert report["unit_notes"] == notes
    page = (tmp_path / "o" / "report.html").read_text()
    assert "<th>units</th>" in page and "position &lt;- x: unit not declared: taken as m" in page
