"""``--sampling voltage=mean`` on recorded data: an interval-mean voltage is aligned to its interval's middle.

The closed-loop plant data of the estimator tests, its voltage replaced by its mean over each 1e-4 s interval
before the time stamp (the trapezoidal rule on the smooth voltage of the built-in model: within 0.001 % of R
and L of the mean of a 1e-5 s simulation). Read as instantaneous, the half-sample lag leaves L -0.77 % and R
-0.09 % low; declared as a mean they come out within 0.03 %.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "estimator"))
from plant_data import TRUTH, closed_loop  # noqa: E402

from feeddrive.cosim.cli import main  # noqa: E402

MAP = ["--map", "time=time", "--map", "voltage=u", "--map", "current=i", "--map", "speed=w", "--map", "state=state"]


@pytest.fixture(scope="module")
def mean_voltage(tmp_path_factory) -> Path:
    d = closed_loop()
    u = d["u"]
    u_mean = np.r_[u[0], 0.5 * (u[1:] + u[:-1])]  # the mean over (t_(n-1), t_n], stamped t_n
    state = (np.abs(d["w_ref"]) > 0).astype(float)
    path = tmp_path_factory.mktemp("mean") / "axis.csv"
    np.savetxt(path, np.column_stack([d["t"], u_mean, d["i"], d["w"], state]), delimiter=",",
               header="time,u,i,w,state", comments="", fmt="%.12g")
    return path


def errors(capsys, *argv) -> dict[str, float]:
    """The largest relative error of each parameter over the record's motions (out and back)."""
    assert main(["estimate", *map(str, argv), "--json"]) == 0
    segments = json.loads(capsys.readouterr().out)["segments"]
    assert len(segments) == 2
    return {k: max((s["parameters"][k]["value"] / TRUTH[k] - 1 for s in segments), key=abs) for k in ("R", "L", "K")}


def test_declared_mean_voltage_is_aligned(mean_voltage, capsys):
    lagged = errors(capsys, mean_voltage, *MAP)
    assert lagged["L"] < -0.005, lagged  # the half-sample lag read as instantaneous: L -0.77 %
    aligned = errors(capsys, mean_voltage, *MAP, "--sampling", "voltage=mean")
    for name in ("R", "L", "K"):
        assert abs(aligned[name]) < 3e-4, (name, aligned)  # measured 0.000 %, -0.023 %, 0.000 %


@pytest.mark.parametrize("option", ["volts=mean", "voltage=average", "voltage"])
def test_bad_sampling_option_is_a_one_line_input_error(mean_voltage, capsys, option):
    assert main(["estimate", str(mean_voltage), *MAP, "--sampling", option]) == 2
    err = capsys.readouterr().err.strip()
    assert "--sampling" in err and "\n" not in err and "Traceback" not in err, err
