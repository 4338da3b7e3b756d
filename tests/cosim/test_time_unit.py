"""A time column that states no unit is taken as seconds, and that is said (never taken on trust).

The linear axis of tests/cosim/linear_axis.py (100 kg, 1 kHz) written with its time in milliseconds and a
bare ``t`` header: taken as seconds, the moving mass came out as 1e8 kg with a clean model check and no word.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from linear_axis import TRUTH, linear_axis  # noqa: E402

from feeddrive.cosim.cli import main  # noqa: E402


@pytest.fixture(scope="module")
def in_ms(tmp_path_factory) -> Path:
    d = linear_axis()
    k = slice(0, 8000)  # 8 s: enough for Jt, ft, Cd and T0 (speed reversals at 0.2 and 0.73 Hz)
    path = tmp_path_factory.mktemp("ms") / "axis_ms.csv"
    np.savetxt(path, np.column_stack([d["t"][k] * 1e3, d["x"][k], d["F"][k]]), delimiter=",",
               header="t,x [m],F [N]", comments="", fmt="%.12g")
    return path


def estimate(capsys, *argv) -> tuple[dict, str]:
    assert main(["estimate", *map(str, argv), "--offset", "--segment", "none", "--method", "ls", "--json"]) == 0
    out, err = capsys.readouterr()
    return json.loads(out), err


def test_a_bare_time_column_is_said_to_be_taken_as_seconds(in_ms, capsys):
    out, err = estimate(capsys, in_ms, "--map", "time=t", "position=x", "torque=F")
    line = ("time: 't' states no unit (not in the header, not in the map): taken as s (a step of 1 s, 1 Hz); "
            "state it: --map 'time=t [UNIT]' (e.g. ms)")
    assert line in err and line in out["unit_assumptions"]


def test_the_stated_unit_gives_the_axis_and_says_nothing(in_ms, capsys):
    out, err = estimate(capsys, in_ms, "--map", "time=t [ms]", "position=x", "torque=F")
    assert "time:" not in err and not any(n.startswith("time:") for n in out.get("unit_assumptions", []))
    (seg,) = out["segments"]
    assert round(1000.0 / seg["rate_hz"], 9) in (1.0, 2.0, 3.0)  # 1 kHz, or every D-th sample of it (decimation)
    assert seg["parameters"]["Jt"]["value"] == pytest.approx(TRUTH["Jt"], rel=0.02)
