"""Units on every connection into an FMU component, on real compiled FMUs: RefAxis (rpm, mm; FMI 2.0 and 3.0)
and RampIntegrator (rad/s, m/s; FMI 3.0). A different scale is converted with pint at the input (rpm <->
rad/s between two FMU components, the NC's rad/s into an FMU component's rpm), a plant part's role map is
converted by its units like the plant's, another dimension is refused with one line, `cosim info` lists them."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

sys.path.insert(0, str(Path(__file__).parents[1] / "plants"))
from ramp_integrator import build as build_integrator  # noqa: E402
from ref_axis import MAP, build  # noqa: E402

from feeddrive.cosim.cli import main  # noqa: E402
from feeddrive.cosim.errors import ScenarioError  # noqa: E402
from feeddrive.cosim.master import Master  # noqa: E402
from feeddrive.cosim.scenario import scenario_from_dict  # noqa: E402

H = 1e-3


@pytest.fixture(scope="module")
def fmus(built_once) -> dict[str, Path]:
    """RefAxis (FMI 2.0, 3.0) and RampIntegrator, built once for the test run (tests/conftest.py built_once)."""
    return {"axis2": built_once("RefAxis2", lambda folder: build(folder / "RefAxis2.fmu", 2)),
            "axis3": built_once("RefAxis3", lambda folder: build(folder / "RefAxis3.fmu", 3)),
            "integrator": built_once("RampIntegrator1",
                                     lambda folder: build_integrator(folder / "RampIntegrator1.fmu"))}


def chain(fmus: dict, w_source: str = "a.n_act") -> dict:
    """a (60 rpm) -> ri.w [rad/s] -> ri.w_last [rad/s] -> b.n_set [rpm]: two conversions, both ways."""
    return {"name": "units", "step": H, "stop_time": 0.1, "components": [
        {"name": "a", "fmu": str(fmus["axis3"]), "inputs": {"n_set": 60.0, "T_load": 0.0}},
        {"name": "ri", "fmu": str(fmus["integrator"]), "inputs": {"w": w_source, "v": 0.0}},
        {"name": "b", "fmu": str(fmus["axis2"]), "inputs": {"n_set": "ri.w_last", "T_load": 0.0}}]}


def run(data: dict) -> tuple[dict[str, np.ndarray], Master]:
    with Master.from_scenario(scenario_from_dict(data)) as master:
        return master.run().signals(), master


def test_rpm_and_rad_per_s_are_converted_between_fmu_components(fmus):
    s, master = run(chain(fmus))
    t = np.arange(len(s["ri.phi"])) * H
    np.testing.assert_allclose(s["ri.w_last"][1:], 2 * math.pi, rtol=1e-15)  # 60 rpm = 2 pi rad/s
    np.testing.assert_allclose(s["ri.phi"], 2 * math.pi * t, rtol=1e-13, atol=1e-15)  # one turn per second
    np.testing.assert_allclose(s["b.n_act"][2:], 60.0, rtol=1e-14)  # and back: 2 pi rad/s into rpm
    assert master.components["ri"].input_units == ("m/s", "rpm")  # the port takes the source's unit ...
    assert master.recorder.units[master.recorder.names.index("ri.w_last")] == "rad/s"  # ... its FMU keeps its own


def test_another_dimension_is_refused_with_one_line_naming_the_connection(fmus, tmp_path, capfd):
    with pytest.raises(ScenarioError, match=r"components\[1\]\.inputs\.w: a\.pos_mm -> ri\.w: unit 'mm' does not "
                                            r"convert to 'rad/s' \(another dimension\)"):
        scenario_from_dict(chain(fmus, "a.pos_mm"))
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(chain(fmus, "a.pos_mm")))
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capfd.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and "s.yaml:" in err, err


def test_the_nc_speed_reference_reaches_an_fmu_component_in_its_rpm(fmus):
    """A standard component's role output into an FMU component (not a plant part): rad/s -> rpm."""
    data = {"name": "nc-to-fmu", "step": 1e-4, "stop_time": 0.3,
            "plant": {"fmu": str(fmus["axis3"]), "input_hold": "zoh", "map": MAP},
            "sensors": {"current": [{"noise": 0.0}, {"noise": 0.0}], "voltage": {"noise": 0.0},
                        "voltage_ref": {"noise": 0.0}},
            "nc": {"program": [{"rapid": {"to": 0.01}}]},
            "components": [{"name": "twin", "fmu": str(fmus["axis2"]),
                            "inputs": {"n_set": "nc.speed_ref", "T_load": "nc.load"}}]}
    s, _ = run(data)
    assert np.abs(s["nc.speed_ref"]).max() > 10
    # twin steps every recording step after the NC: its n_act at t_n+1 is the NC's speed_ref at t_n+1, in rpm
    np.testing.assert_allclose(s["twin.n_act"][1:], s["nc.speed_ref"][1:] * 30 / math.pi, rtol=1e-13, atol=1e-12)


def test_a_plant_part_map_is_converted_by_its_units(fmus):
    """The mechanics part maps speed_ref -> n_set [rpm] and position <- pos_mm [mm] without scales: the units
    decide (x 9.5493, x 0.001), as on the plant's own map, and the two-FMU plant gives the one-FMU plant's position."""
    one = {"name": "one", "step": 1e-4, "stop_time": 0.3,
           "plant": {"fmu": str(fmus["axis3"]), "input_hold": "zoh", "map": MAP},
           "sensors": {"current": [{"noise": 0.0}, {"noise": 0.0}], "voltage": {"noise": 0.0},
                       "voltage_ref": {"noise": 0.0}},
           "nc": {"program": [{"rapid": {"to": 0.01}}]}}
    two = yaml.safe_load(yaml.safe_dump(one))
    two["plant"]["map"] = {r: e for r, e in MAP.items() if r != "position"}
    two["components"] = [{"name": "mech", "fmu": str(fmus["axis2"]),
                          "config": {"map": {"speed_ref": {"var": "n_set"}, "position": {"var": "pos_mm"}}},
                          "inputs": {"speed_ref": "plant.speed", "T_load": 0.0}}]
    a, _ = run(one)
    b, _ = run(two)
    assert abs(b["mech.position"][-1] - 0.01) < 1e-6  # in m, where the NC sent it (not 10 "m" of mm)
    np.testing.assert_allclose(b["mech.position"], a["plant.position"], rtol=0, atol=1e-15)


def test_cosim_info_lists_the_links_of_an_fmu_component(fmus, tmp_path, capsys):
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(chain(fmus)))
    assert main(["info", str(fmus["integrator"]), "--map", str(path)]) == 0
    out = capsys.readouterr().out
    assert f"component ri of {path} (port [unit] <- source [unit] x scale + offset)" in out
    assert "  w [rad/s] <- a.n_act [rpm] x 0.10472" in out and "  v [m/s] <- 0.0 (a constant)" in out
    assert main(["info", str(fmus["axis2"]), "--map", str(path)]) == 0
    assert "  n_set [rpm] <- ri.w_last [rad/s] x 9.5493" in capsys.readouterr().out


def test_the_export_refuses_a_converted_connection(fmus, tmp_path, feeddrive_fmu):
    """An OSP connection is a plain assignment: an input converted from its source's unit is not exported."""
    from feeddrive.cosim.export.system import ExportError, export_system

    data = {"name": "converted", "step": 1e-3, "stop_time": 0.5, "plant": {"fmu": "builtin"},
            "nc": {"program": [{"rapid": {"to": 0.01}}]},
            "components": [{"name": "twin", "fmu": str(fmus["axis2"]),
                            "inputs": {"n_set": "nc.speed_ref", "T_load": 0.0}}]}
    with pytest.raises(ExportError, match=r"components\[twin\]\.inputs\.n_set: nc\.speed_ref \[rad/s\] into \[rpm\] "
                                          r"is converted \(x 9\.5493\); an OSP connection cannot convert units"):
        export_system(scenario_from_dict(data), tmp_path / "sys")
