"""FMI 3.0 plants and FMU components: RefAxis (tests/plants/ref_axis.py), the same C model as FMI 2.0 and
3.0, through the role map with unit conversion (rpm, mm), in Co-Simulation and Model Exchange, with timed
parameter events, errors through the choke point, `cosim info`, several FMUs connected to each other
(multi-rate, units checked) and a hanging FMU component contained and named."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

sys.path.insert(0, str(Path(__file__).parents[1] / "plants"))
from ref_axis import MAP, build  # noqa: E402

from feeddrive.cosim.cli import main  # noqa: E402
from feeddrive.cosim.errors import FMIError, ScenarioError  # noqa: E402
from feeddrive.cosim.master import Master  # noqa: E402
from feeddrive.cosim.scenario import scenario_from_dict  # noqa: E402

H = 1e-4


@pytest.fixture(scope="module")
def axes(built_once) -> dict[int, Path]:
    """RefAxis as FMI 2.0 and 3.0, built once for the test run (tests/conftest.py built_once)."""
    return {v: built_once(f"RefAxis{v}", lambda folder, v=v: build(folder / f"RefAxis{v}.fmu", v)) for v in (2, 3)}


def plant_scenario(fmu: Path, interface: str, **extra) -> dict:
    return {"name": "ref-axis", "step": H, "stop_time": 0.6,
            "plant": {"fmu": str(fmu), "interface": interface, "input_hold": "zoh", "map": MAP},
            "sensors": {"current": [{"noise": 0.0}, {"noise": 0.0}], "voltage": {"noise": 0.0},
                        "voltage_ref": {"noise": 0.0}},
            "nc": {"program": [{"rapid": {"to": 0.01}}, {"feed": {"to": 0.012, "feed": 0.005, "load": 5.0}}]}} | extra


def run(data: dict) -> dict[str, np.ndarray]:
    with Master.from_scenario(scenario_from_dict(data)) as master:
        return master.run().signals()


@pytest.mark.parametrize("interface", ["cs", "me"])
def test_fmi3_plant_equals_the_fmi2_build_and_converts_units(axes, interface):
    s3, s2 = run(plant_scenario(axes[3], interface)), run(plant_scenario(axes[2], interface))
    speed_ref, load = s3["nc.speed_ref"], s3["nc.load"]
    assert np.abs(speed_ref).max() > 10 and np.abs(load).max() == 5.0
    for name in ("plant.speed", "plant.position", "plant.voltage", "plant.current"):
        np.testing.assert_allclose(s3[name], s2[name], rtol=0, atol=1e-12 * max(1.0, np.abs(s2[name]).max()),
                                   err_msg=name)  # the same C model: FMI 3.0 and 2.0 agree to rounding
    # rpm <-> rad/s, % -> A: at t_{n+1} the plant has the NC's output of t_{n+1} (the NC runs first)
    np.testing.assert_allclose(s3["plant.speed"], speed_ref, rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(s3["plant.voltage"], 0.11 * 30 / math.pi * speed_ref, rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(s3["plant.current"][1:], load[1:] / 1.05, rtol=0, atol=1e-12)
    # the position integrates the held speed over each step: the NC's plan at every grid point (mm -> m)
    tol = 1e-12 if interface == "cs" else 1e-8
    np.testing.assert_allclose(s3["plant.position"], s3["nc.x_ref"], rtol=0, atol=tol)


def test_fmi3_timed_parameter_event_and_its_error_through_the_choke_point(axes):
    """pitch_mm 20 -> 10 mm at t = 0.3 s halves the feed per turn from the next step on; a negative pitch is
    refused by the FMU: one FMIError naming fmi3SetFloat64, fmi3Error, the time and the FMU's message."""
    events = [{"time": 0.3, "target": "plant.pitch_mm", "value": 10.0}]
    s = run(plant_scenario(axes[3], "cs", events=events))
    w, n_e = s["nc.speed_ref"], 3000
    pitch = np.where(np.arange(len(w)) <= n_e, 0.020, 0.010)  # step j (ending at t_j) uses the pitch at t_(j-1)
    expected = np.concatenate([[0.0], np.cumsum(w[1:] * H * pitch[1:] / (2 * math.pi))])
    np.testing.assert_allclose(s["plant.position"], expected, rtol=0, atol=1e-12)
    unchanged = np.concatenate([[0.0], np.cumsum(w[1:] * H * 0.020 / (2 * math.pi))])
    assert np.abs(s["plant.position"] - unchanged).max() > 1e-3  # the event is visible, not within tolerance
    bad = [{"time": 0.05, "target": "plant.pitch_mm", "value": -1.0}]
    with pytest.raises(FMIError) as info:
        run(plant_scenario(axes[3], "cs", events=bad))
    err = info.value
    assert (err.component, err.function, err.status) == ("plant", "fmi3SetFloat64", "fmi3Error")
    assert err.time == pytest.approx(0.05) and "pitch_mm must be positive" in err.last_log


def test_cosim_info_lists_an_fmi3_fmu_and_checks_the_map(axes, tmp_path, capsys):
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(plant_scenario(axes[3], "cs")))
    assert main(["info", str(axes[3]), "--map", str(path)]) == 0
    out = capsys.readouterr().out
    assert "FMI 3.0, Co-Simulation + Model Exchange" in out
    assert "position [m] <- pos_mm [mm] x 0.001" in out and "map OK" in out


def components(axes: dict, multiple: int, source: str = "a.n_act") -> dict:
    return {"name": "two-fmus", "step": 1e-3, "stop_time": 0.5,
            "components": [
                {"name": "a", "fmu": str(axes[3]), "inputs": {"n_set": 60.0, "T_load": 0.0}},
                {"name": "b", "fmu": str(axes[2]), "config": {"interface": "me", "step_multiple": multiple},
                 "inputs": {"n_set": source, "T_load": 1.05}}]}


def test_two_fmus_connected_multi_rate(axes):
    """FMU a (FMI 3.0, CS, every ms) drives FMU b (FMI 2.0, ME, every 5 ms): b's position is 60 rpm at
    20 mm per turn, 20 mm/s, sampled on b's own grid; its current is its constant input / 1.05."""
    with Master.from_scenario(scenario_from_dict(components(axes, 5))) as master:
        s = master.run().signals()
        assert master.rates == {"a": 1, "b": 5}
    t = np.arange(len(s["a.pos_mm"])) * 1e-3
    np.testing.assert_allclose(s["a.pos_mm"], 20.0 * t, rtol=0, atol=1e-9)
    held = 20.0 * np.floor(np.round(t / 5e-3, 9)) * 5e-3  # b steps every 5 ticks, its outputs hold in between
    np.testing.assert_allclose(s["b.pos_mm"], held, rtol=0, atol=1e-7)
    np.testing.assert_allclose(s["b.I"], np.where(t >= 5e-3 - 1e-12, 1.0, 0.0), rtol=0, atol=1e-12)


def test_a_connection_between_units_of_another_dimension_is_refused(axes):
    with pytest.raises(ScenarioError, match=r"a\.pos_mm -> b\.n_set: unit 'mm' does not convert to 'rpm'"):
        Master.from_scenario(scenario_from_dict(components(axes, 1, source="a.pos_mm"))).setup()


def test_a_hanging_fmu_component_is_named_with_its_own_watchdog(axes, tmp_path, capfd, built_once):
    from faulty import MODES
    from faulty import build as build_faulty

    faulty = built_once("Faulty", lambda folder: build_faulty(folder / "Faulty.fmu"))
    data = components(axes, 1) | {"stop_time": 0.6}  # Faulty fails at t = 0.5 s
    data["components"].append({"name": "drive2", "fmu": str(faulty),
                               "config": {"parameters": {"mode": MODES["loop"]}, "call_timeout": 1.0},
                               "inputs": {"w_ref": 0.0, "Tl": 0.0}})
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(data))
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--no-progress"]) == 1
    err = capfd.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("cosim run: failed: drive2: hung in fmi2DoStep at t=0.5 s: exceeded "
                          "drive2.call_timeout = 1 s"), err


def test_a_plant_of_two_fmus_is_described_by_the_same_role_map(axes):
    """The drive (FMI 3.0: speed_ref, load, voltage, current, speed) and the mechanics (FMI 2.0: the
    position, fed with the drive's speed in rad/s, converted to its rpm by its own map entry) give the
    one-FMU plant's signals exactly; the NC and the sensors read the position where it lives."""
    one = run(plant_scenario(axes[3], "cs"))
    drive_map = {r: e for r, e in MAP.items() if r != "position"}
    data = plant_scenario(axes[3], "cs")
    data["plant"]["map"] = drive_map
    data["components"] = [{"name": "mech", "fmu": str(axes[2]),
                           "config": {"map": {"speed_ref": MAP["speed_ref"], "position": MAP["position"]}},
                           "inputs": {"speed_ref": "plant.speed", "T_load": 0.0}}]
    with Master.from_scenario(scenario_from_dict(data)) as master:
        two = master.run().signals()
        assert master.connections["nc.position"] == "mech.position"
        assert master.connections["sensors.position"] == "mech.position"
    assert "plant.position" not in two
    np.testing.assert_allclose(two["mech.position"], one["plant.position"], rtol=0, atol=1e-15)
    for name in ("plant.speed", "plant.voltage", "plant.current", "nc.x_ref", "sensors.x"):
        np.testing.assert_allclose(two[name], one[name], rtol=0, atol=1e-15, err_msg=name)


def test_fmi3_model_exchange_ramps_the_inputs_and_oversamples_like_fmi2(axes):
    """Model Exchange, first-order hold (the master ramps the inputs inside CVode) and oversample 4 with the
    exact interval means: the FMI 3.0 build gives the FMI 2.0 build's signals; the ramped position is not the
    held one (the hold is in effect)."""
    def data(v: int, hold: str, stop: float = 0.2) -> dict:
        d = plant_scenario(axes[v], "me", stop_time=stop)  # the rapid's ramps: CVode is the costly part
        d["plant"] |= {"input_hold": hold, "oversample": 4}
        return d

    s3, s2, held = run(data(3, "foh")), run(data(2, "foh")), run(data(3, "zoh", 0.05))
    for name in ("plant.position", "plant.speed_mean", "plant.current_mean", "sensors.x"):
        scale = max(1.0, np.abs(s2[name]).max())
        np.testing.assert_allclose(s3[name], s2[name], rtol=0, atol=1e-9 * scale, err_msg=name)
    n = len(held["plant.position"])  # the held run: the rapid's start only (0.05 s; measured 7.8e-7 m apart there)
    assert np.abs(s3["plant.position"][:n] - held["plant.position"]).max() > 1e-7


def test_the_osp_system_and_ssp_export_carry_the_fmu_components(axes, tmp_path, feeddrive_fmu):
    """Two FMU components beside the built-in plant: copied, each a simulator (b at its step multiple),
    connected as `cosim run` connects them, constants as initial values; the SSP archive has them too."""
    import zipfile
    from xml.etree import ElementTree

    from feeddrive.cosim.export.system import OSP_NS, export_system

    data = {"name": "with-fmus", "step": 1e-3, "stop_time": 0.5, "plant": {"fmu": "builtin"},
            "nc": {"program": [{"rapid": {"to": 0.01}}]},
            "components": [{"name": "a", "fmu": str(axes[2]), "inputs": {"n_set": 60.0, "T_load": 0.0}},
                           {"name": "b", "fmu": str(axes[3]), "config": {"step_multiple": 2},
                            "inputs": {"n_set": "a.n_act", "T_load": 1.05}}]}
    paths = export_system(scenario_from_dict(data), tmp_path / "sys")
    ns = {"osp": OSP_NS}
    root = ElementTree.parse(paths["system"]).getroot()
    sims = {s.get("name"): s for s in root.iterfind("osp:Simulators/osp:Simulator", ns)}
    assert set(sims) == {"nc", "plant", "sensors", "a", "b"}
    assert (sims["a"].get("source"), sims["b"].get("source")) == ("RefAxis2.fmu", "RefAxis3.fmu")
    assert float(sims["a"].get("stepSize")) == 1e-3 and float(sims["b"].get("stepSize")) == 2e-3
    initial = {(s, v.get("variable")): float(v[0].get("value")) for s, sim in sims.items()
               for v in sim.iterfind("osp:InitialValues/osp:InitialValue", ns)}
    assert initial[("a", "n_set")] == 60.0 and initial[("b", "T_load")] == 1.05
    links = set()
    for c in root.iterfind("osp:Connections/osp:VariableConnection", ns):
        a, b = c.iterfind("osp:Variable", ns)
        links.add((a.get("simulator"), a.get("name"), b.get("simulator"), b.get("name")))
    assert ("a", "n_act", "b", "n_set") in links and ("nc", "speed_ref", "plant", "w_ref") in links
    assert (tmp_path / "sys" / "RefAxis3.fmu").read_bytes() == axes[3].read_bytes()
    with zipfile.ZipFile(paths["ssp"]) as z:
        assert {"resources/RefAxis2.fmu", "resources/RefAxis3.fmu"} <= set(z.namelist())
