"""plant.input_hold: the NC's sampled speed reference reaches the plant FMU as a ramp (foh) or a staircase (zoh).

With zoh the 1e-4 s staircase leaves a sawtooth on u and a ripple on di/dt inside every step, and the
monitor's electrical regression on noise-free signals returns R and L ~0.2 % low; with foh (the
default for the built-in plant) the plant sees the linearly extrapolated reference and the bias goes.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from cosim.errors import ScenarioError
from cosim.fmu_adapter import FMUComponent
from cosim.run import run_scenario
from cosim.scenario import load_scenario, scenario_from_dict
from models import feed_drive

TRUTH = feed_drive().nominal()
EXAMPLE = Path(__file__).parents[2] / "examples" / "tool_change.yaml"
SILENT = {"noise": 0.0}


def tool_change(input_hold: str | None) -> dict:
    """examples/tool_change.yaml with every sensor noise 0 and the history in memory."""
    data = yaml.safe_load(EXAMPLE.read_text())
    data["sensors"] = {"seed": 1, "current": [SILENT, SILENT], "voltage": SILENT, "voltage_ref": SILENT,
                       "tachometer": SILENT, "encoder": SILENT}
    data["monitor"] = {"db": ":memory:"}
    if input_hold:
        data["plant"]["input_hold"] = input_hold
    return data


@pytest.fixture(scope="module")
def runs(tmp_path_factory, feeddrive_fmu):
    """The tool change with the default hold (foh for the built-in plant) and with zoh: motion, report."""
    out = {}
    for hold in (None, "zoh"):
        run = run_scenario(scenario_from_dict(tool_change(hold)), tmp_path_factory.mktemp(hold or "default"),
                           plots=False)
        (motion,) = run.report["motions"]
        out[hold] = motion, run
    return out


def test_first_order_hold_removes_the_electrical_bias(runs):
    foh, run = runs[None]
    assert run.report["components"]["plant"]["input_hold"] == "foh"
    p = foh["parameters"]
    assert abs(p["R"]["value"] / TRUTH["R"] - 1) < 5e-4, p["R"]
    assert abs(p["L"]["value"] / TRUTH["L"] - 1) < 2e-3, p["L"]
    for name in ("R", "L", "K"):  # noise-free signals: what is left is the regression's own spread
        lo, hi = p[name]["ci95"]
        assert lo <= TRUTH[name] <= hi, (name, p[name])
    zoh = runs["zoh"][0]["parameters"]
    assert zoh["R"]["value"] / TRUTH["R"] - 1 < -1.5e-3, zoh["R"]  # the staircase bias the test is about
    for name in ("R", "L"):  # foh is several times closer to the truth
        assert abs(p[name]["value"] / TRUTH[name] - 1) < abs(zoh[name]["value"] / TRUTH[name] - 1) / 3, name


def test_both_holds_follow_the_same_trajectory(runs):
    """The staircase lags the ramp by h/2 on average, so the speeds differ by at most |dw/dt| h / 2;
    the terminal voltage differs by the staircase's sawtooth through the proportional gains (0.3 V)."""
    a, b = runs[None][1].signals, runs["zoh"][1].signals
    h = 1e-4
    w_max, accel = np.abs(a["plant.speed"]).max(), np.abs(np.gradient(a["plant.speed"], h)).max()
    assert w_max > 60
    assert np.abs(a["plant.speed"] - b["plant.speed"]).max() < accel * h / 2
    assert 0.05 < np.abs(a["plant.voltage"] - b["plant.voltage"]).max() < 0.5


def test_resolved_hold_defaults_and_refusals(tmp_path, feeddrive_fmu):
    def plant(**kw) -> dict:
        return scenario_from_dict({**tool_change(None), "plant": {"fmu": "builtin", **kw}}).plant

    assert plant().input_hold == "foh"
    assert plant(input_hold="zoh").input_hold == "zoh"
    assert plant(interface="me").input_hold == "zoh"
    with pytest.raises(ScenarioError, match=r"plant\.input_hold.*foh is not available: interface me"):
        plant(interface="me", input_hold="foh")
    with pytest.raises(ScenarioError, match=r"plant\.input_hold"):
        plant(input_hold="linear")
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(tool_change("foh")))
    cfg = load_scenario(path).plant.model_copy(update={"interface": "me"})  # unresolved combination
    component = FMUComponent("plant", cfg)
    try:
        with pytest.raises(ScenarioError, match=r"plant: plant\.input_hold: input_hold foh is not available"):
            component.setup(0.0, 1e-4, 10)
    finally:
        component.terminate()
