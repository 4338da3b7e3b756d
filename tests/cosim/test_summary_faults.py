"""The console summary's motion lines: a sensor fault's values with their unit and nothing that is not a number; a
motion not estimated said once."""
from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from feeddrive.cosim.cli.run import summary


def lines_of(fault: dict) -> list[str]:
    motion = {"sensor_faults": [fault], "parameters": {"R": {"value": 0.6}}}
    report = {"scenario": "s", "stop_time_s": 1.0, "wall_time_s": 0.5, "steps": 10, "step_s": 0.1, "motions": [motion]}
    return summary(SimpleNamespace(report=report, signals={}, out_dir="runs/x", paths={"plots": []})).splitlines()


@pytest.mark.parametrize(("fault", "line"), [
    ({"sensor": "Im1", "kind": "gain+offset", "gain": 1.03, "offset": 0.2}, "sensor fault: Im1 gain+offset (gain 1.03, offset 0.2 A)"),
    ({"sensor": "u", "kind": "offset", "gain": math.nan, "offset": -1.5}, "sensor fault: u offset (offset -1.5 V)"),
    ({"sensor": "w_tach", "kind": "gain", "gain": 0.9, "offset": None}, "sensor fault: w_tach gain (gain 0.9)"),
])
def test_the_fault_line_has_units_and_no_nan(fault, line):
    details = [ln.strip() for ln in lines_of(fault) if ln.startswith("    sensor fault:")]
    assert details == [line]


def test_a_motion_not_estimated_says_why_once():
    """Its verdict carries the reason: no bare 'not validated' line without values, no second copy of it."""
    error = ("motion of 0.258 s is shorter than min_motion_s = 1.0 s (a scenario's monitor.min_motion_s, "
             "cosim monitor's --min-motion)")
    report = {"scenario": "s", "stop_time_s": 1.0, "wall_time_s": 0.5, "steps": 10, "step_s": 0.1,
              "motions": [{"error": error, "parameters": {}, "validated": False}]}
    lines = summary(SimpleNamespace(report=report, signals={}, out_dir="runs/x", paths={"plots": []})).splitlines()
    assert lines[1] == f"  motion 1: not estimated: {error}"
    assert sum(error in line for line in lines) == 1 and not any(line.strip() == "not validated" for line in lines)
