"""The console summary's sensor-fault line: the values with their unit, and nothing that is not a number."""
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
