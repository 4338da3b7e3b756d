"""What the monitor compares a machine with: only values stated for that axis, never another motor's.

The first motion's sensor isolation (paper Fig. 6) needs R, L, K. Before, a recording or a vendor FMU with no
stated values was isolated with the built-in plant's (R 0.6, L 0.004, K 1.05): on a machine with ten times
those, a 3 % gain fault of Im1 came out as faults of both current sensors with gains of 0.004, and
``baseline: nominal`` diagnosed a healthy machine with motor heating, wear and lubrication.
Plant data: tests/estimator/test_validation.py's closed loop (10 kHz, redundant sensors); "another machine"
has its voltages scaled by 10, the electrical equation of R, L, K ten times the built-in's.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.monitor import Monitor
from feeddrive.cosim.report.verdict import verdict_line
from feeddrive.cosim.scenario import load_scenario

_spec = importlib.util.spec_from_file_location("monitor_tests", Path(__file__).with_name("test_monitor.py"))
mt = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(mt)
EXAMPLES = Path(__file__).parents[2] / "examples"


def other_machine(seed: int, **faults) -> dict:
    m = mt.motion(seed, **faults)
    return m | {"u": 10 * m["u"], "u_ref": 10 * m["u_ref"]}


def first_motion(motion: dict, **config) -> dict:
    mon = Monitor("monitor", mt.MonitorConfig(**config))
    mt.run(mon, [motion])
    (res,) = mon.report()["motions"]
    mon.terminate()
    return res


def test_a_disagreeing_pair_is_not_isolated_with_another_motors_values():
    res = first_motion(other_machine(21, Im1=(1.03, 0.0)))
    (fault,) = res["sensor_faults"]
    assert fault["sensor"] == "Im1 or Im2" and fault["gain"] == pytest.approx(1.03, abs=0.003)
    assert res["reference"] == "none" and not res["measurements_valid"] and not res["validated"]
    assert res["verdict"] == "sensor fault"
    line = verdict_line(res)
    assert line.startswith("sensor fault: Im1 or Im2 gain 1.03") and " A; parameters not validated" in line
    assert any("needs the axis's R, L, K: state them" in n for n in res["notes"])
    assert not any("isolation uses nominal" in n for n in res["notes"])


def test_the_stated_values_isolate_the_faulty_sensor():
    res = first_motion(other_machine(21, Im1=(1.03, 0.0)), nominal={"R": 6.0, "L": 0.04, "K": 10.5})
    (fault,) = res["sensor_faults"]
    assert fault["sensor"] == "Im1" and fault["gain"] == pytest.approx(1.03, abs=0.003)
    assert res["reference"] == "nominal" and res["validated"]
    for name, truth in {"R": 6.0, "L": 0.04, "K": 10.5}.items():
        assert res["parameters"][name]["value"] == pytest.approx(truth, rel=0.01), name


def test_baseline_nominal_needs_the_axis_values_and_a_builtin_plant_states_them():
    with pytest.raises(ScenarioError, match=r"baseline: nominal needs the axis's nominal values of R, L, K, Jt, "
                                            r"ft, Cd .*missing R, L, K, Jt, ft, Cd"):
        Monitor("monitor", {"baseline": "nominal"})
    with pytest.raises(ScenarioError, match="missing Jt, ft, Cd"):
        Monitor("monitor", {"baseline": "nominal", "nominal": {"R": 6.0, "L": 0.04, "K": 10.5}})
    # examples/worn_axis.yaml: the built-in plant (worn), baseline: nominal -> the model's design values
    s = load_scenario(EXAMPLES / "worn_axis.yaml")
    assert s.monitor.config.nominal == {"R": 0.6, "L": 0.004, "K": 1.05, "Jt": 0.1, "ft": 0.02, "Cd": 1.2, "T0": 0.0}


def test_a_reversed_current_measurement_says_so_in_the_verdict():
    m = mt.motion(22)
    res = first_motion(m | {"Im1": -m["Im1"], "Im2": -m["Im2"]}, nominal=mt.NOMINAL)  # both: they agree
    line = verdict_line(res)
    # the cause first, then the impossible values
    assert line.startswith("not validated: the current's sign is the opposite of the model's convention: with it "
                           "negated every parameter is physically possible (R 0.")
    assert "; the estimate is physically impossible: R = -0." in line
    quoted_r = float(line.split("physically possible (R ")[1].split(",")[0])
    assert quoted_r == pytest.approx(0.6, rel=0.01)
    # only the reasons it was not validated: no note about the isolation's reference, no "no power"
    assert "isolation uses" not in line and "no power" not in line
    assert res["hint"].startswith("the current's sign")


def test_stated_values_must_be_physically_possible():
    """A known value is fixed in the fit and the checks: K = 0 gave a 'model mismatch' verdict about the data,
    K = -1.05 a hint that the speed was reversed. Now the input is refused, naming it."""
    with pytest.raises(ScenarioError, match=r"^monitor.known: .*K=0: expected a positive value \(K > 0\)"):
        Monitor("monitor", {"known": {"K": 0.0}})
    with pytest.raises(ScenarioError, match=r"^monitor.nominal: .*R=-1: expected a positive value"):
        Monitor("monitor", {"nominal": {"R": -1.0, "L": 0.004, "K": 1.05}})
    with pytest.raises(ScenarioError, match=r"^monitor.known: .*ft=-0.1: expected a value >= 0 \(a friction\)"):
        Monitor("monitor", {"known": {"ft": -0.1}})
    assert Monitor("monitor", {"known": {"T0": -3.0, "ft": 0.0}}).config.known == {"T0": -3.0, "ft": 0.0}


def test_cosim_estimate_refuses_an_impossible_known_value(capsys):
    from feeddrive.cosim.cli import main

    assert main(["estimate", str(EXAMPLES / "tool_change.yaml"), "--known", "K=-1.05"]) == 2
    assert capsys.readouterr().err.strip() == "cosim estimate: error: --known K=-1.05: expected a positive value (K > 0)"
