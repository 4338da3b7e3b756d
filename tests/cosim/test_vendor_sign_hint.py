"""A vendor FMU that counts the current (or the voltage) the other way: both sensors of the pair agree, so
the redundancy sees nothing, and eq. 1 is fitted with the sign flipped. The motion is refused as physically
impossible (R, L, Jt < 0); the note says which signal's sign the pattern points at, instead of leaving five
impossible parameters to the user (a vendor plant with I_arm = -i gave R=-0.6 L=-0.004 K=1.05 Jt=-0.1).

Plant data: the closed-loop CasADi model with redundant sensors of tests/estimator/test_validation.py.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from feeddrive.cosim.monitor import MEASUREMENTS, Monitor, MonitorConfig

_spec = importlib.util.spec_from_file_location(
    "validation_plant", Path(__file__).parents[1] / "estimator" / "test_validation.py")
plant = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(plant)
H, IDLE = plant.H, 0.05


def monitored(**faults) -> dict:
    """One motion between idle gaps through the Monitor component; its result."""
    m = plant.measure(plant.plant_motion(plateau=0.3), 3, **faults)
    gap, n = np.zeros((int(round(IDLE / H)), len(MEASUREMENTS) + 2)), len(m["Im1"])
    rows = np.vstack([gap, np.column_stack([np.asarray(m[s]) for s in MEASUREMENTS] + [np.ones(n), np.ones(n)]), gap])
    mon = Monitor("monitor", MonitorConfig())
    mon.setup(0.0, H, len(rows))
    for k, values in enumerate(rows.tolist()):
        mon.set_inputs(values)
        mon.step(k)
    (res,) = mon.report()["motions"]
    return res


@pytest.mark.parametrize("pair, sensors, points_at", [
    ("current", ("Im1", "Im2"), "R and L < 0 with K > 0: the current counts the direction opposite to the voltage's"),
    ("voltage", ("u", "u_ref"), "R, L and K < 0: the voltage counts the direction opposite to the current's"),
])
def test_a_signal_counted_the_other_way_by_both_sensors_is_named(pair, sensors, points_at):
    res = monitored(**{s: (-1.0, 0.0) for s in sensors})
    assert not res["validated"] and res["sensor_faults"] == []  # the pair agrees: no sensor fault to see
    values = {k: v["value"] for k, v in res["parameters"].items()}
    assert values["R"] == pytest.approx(-plant.NOMINAL["R"], rel=0.02) and values["Jt"] < 0
    assert (values["K"] > 0) == (pair == "current")
    (note,) = [n for n in res["notes"] if n.startswith("not validated: physically impossible estimate")]
    assert points_at in note and note.endswith("map it with the opposite sign)")
