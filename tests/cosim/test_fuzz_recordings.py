"""Realistic damaged recordings through the command line: exit 0, or exit 2 with one line; never a traceback,
a numerical warning or ``nan`` (issue 22, "Fuzzing").

A hypothesis strategy draws what loggers and machines do to a record: rates from 10 Hz to 10 kHz, records of
0.3 s to 4 s, one direction or both, rounding to 3 significant figures, quantisation, saturation, constant
stretches, spikes, dropped samples (the time column keeps its gaps), and a commanded voltage through a
nonlinear amplifier. The record is written as a CSV and run through ``cosim estimate`` (one of ls, iv, oe,
with ``--resample`` when samples were dropped) and ``cosim monitor``.

The default run draws 4 examples (derandomised: the same ones every run); ``FUZZ_RECORDINGS=2000 pytest
tests/cosim/test_fuzz_recordings.py`` is the fuzz campaign. ``FUZZ_SEED=N`` draws another random sequence, so that
shards in separate processes (``FUZZ_SEED=1 ... FUZZ_SEED=4``, 500 examples each) share the campaign.
"""
from __future__ import annotations

import importlib.util
import os
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, seed, settings
from hypothesis import strategies as st

from feeddrive.cosim.cli import main as cosim
from feeddrive.cosim.cli.monitor import NOTHING_JUDGED

_spec = importlib.util.spec_from_file_location("synthetic", Path(__file__).parents[1] / "estimator" / "synthetic.py")
synthetic = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(synthetic)

EXAMPLES = int(os.environ.get("FUZZ_RECORDINGS", "4"))
SEED = os.environ.get("FUZZ_SEED")
NAN = re.compile(r"\bnan\b", re.IGNORECASE)
DAMAGES = ("none", "round3", "quantise", "saturate", "constant", "spikes")


@st.composite
def recordings(draw: st.DrawFn) -> dict:
    return {
        "rate": 10 ** draw(st.floats(1.0, 4.0)),
        "seconds": draw(st.sampled_from([0.3, 1.0, 4.0])),
        "both": draw(st.booleans()),
        "snr_db": draw(st.sampled_from([None, 20.0, 40.0, 60.0])),
        "damage": {k: draw(st.sampled_from(DAMAGES)) for k in ("u", "i", "w")},
        "amplifier": draw(st.booleans()),
        "dropped": draw(st.sampled_from([0.0, 0.0, 0.01, 0.05])),
        "L_over_R": 10 ** draw(st.floats(-5.0, -2.0)),
        "method": draw(st.sampled_from(["ls", "iv", "oe"])),
        "seed": draw(st.integers(0, 2 ** 31 - 1)),
    }


def damaged_csv(spec: dict, path: Path) -> Path:
    rng = np.random.default_rng(spec["seed"])
    h = 1.0 / spec["rate"]
    corners = synthetic.ROUND_TRIP if spec["both"] else synthetic.FORWARD
    d = synthetic.record(corners, h, {"L": synthetic.TRUTH["R"] * spec["L_over_R"]}, snr_db=spec["snr_db"],
                         seed=spec["seed"])
    n = max(3, int(spec["seconds"] / h))
    start = int(rng.integers(0, max(1, len(d["w"]) - n)))
    d = {k: v[start:start + n].copy() for k, v in d.items()}
    for k, damage in spec["damage"].items():
        x = d[k]
        if damage == "round3":
            x[:] = [float(f"{v:.3g}") for v in x]
        elif damage == "quantise":
            x[:] = np.round(x / 0.1) * 0.1
        elif damage == "saturate":
            x[:] = np.clip(x, -0.5 * np.abs(x).max(), 0.5 * np.abs(x).max())
        elif damage == "constant" and x.size > 10:
            a = int(rng.integers(0, x.size - 5))
            x[a:a + x.size // 5] = x[a]
        elif damage == "spikes":
            x[rng.integers(0, x.size, size=max(1, x.size // 100))] *= 10
    if spec["amplifier"]:  # the logged voltage is a command through a nonlinear amplifier
        d["u"] = 27 * np.tanh(d["u"] / 30) + 0.5
    keep = np.ones(d["t"].size, bool)
    if spec["dropped"]:
        keep[1:-1] = rng.random(d["t"].size - 2) >= spec["dropped"]
    table = np.column_stack([d[k][keep] for k in ("t", "u", "i", "w")])
    np.savetxt(path, table, delimiter=",", header="t [s],u [V],i [A],w [rad/s]", comments="", fmt="%.12g")
    return path


def run(argv: list[str], capsys: pytest.CaptureFixture) -> tuple[int, str, str]:
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        code = cosim(argv)
    out, err = capsys.readouterr()
    return code, out, err


def clean(code: int, out: str, err: str, what: str) -> None:
    if code == NOTHING_JUDGED:  # cosim estimate: every parameter refused, said in the last line
        assert out.strip().splitlines()[-1].startswith("nothing estimated: "), f"{what}:\n{out}"
        code = 0
    assert code in (0, 2), f"{what}: exit {code}\n{err}"
    assert not NAN.search(out + err), f"{what}: nan printed\n{out}\n{err}"
    if code == 2:  # one line naming what went wrong (a note of what was left out may come before it)
        assert err.strip().splitlines()[-1].startswith("cosim "), f"{what}: {err}"


@settings(max_examples=EXAMPLES, deadline=None, derandomize=SEED is None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@seed(int(SEED or 0))
@given(spec=recordings())
def test_damaged_recordings_exit_cleanly(spec: dict, tmp_path_factory: pytest.TempPathFactory,
                                         capsys: pytest.CaptureFixture) -> None:
    folder = tmp_path_factory.mktemp("fuzz")
    path = damaged_csv(spec, folder / "rec.csv")
    what = f"{spec}"
    resample = ["--resample", str(20.0 / spec["rate"])] if spec["dropped"] else []
    roles = ["time=t", "voltage=u", "current=i", "speed=w"]
    code, out, err = run(["estimate", str(path), "--map", *roles, "--method", spec["method"], *resample], capsys)
    clean(code, out, err, "estimate " + what)
    if spec["dropped"] and not resample:
        assert code == 2
    code, out, err = run(["monitor", str(path), "--map", "time=t", "voltage=u", "current1=i", "speed=w",
                          *resample, "--db", str(folder / "h.sqlite"), "--min-motion", "0.2"], capsys)
    if code == NOTHING_JUDGED:  # no motion judged: said in the last line (a damaged recording may hold none)
        assert out.strip().splitlines()[-1].startswith("nothing judged: "), f"monitor {what}:\n{out}"
        code = 0
    clean(code, out, err, "monitor " + what)


def test_dropped_samples_without_an_option_are_refused_naming_it(tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture) -> None:
    spec = {"rate": 1000.0, "seconds": 4.0, "both": True, "snr_db": 40.0, "damage": dict.fromkeys("uiw", "none"),
            "amplifier": False, "dropped": 0.01, "L_over_R": 0.0067, "method": "ls", "seed": 3}
    path = damaged_csv(spec, tmp_path / "rec.csv")
    code, _, err = run(["estimate", str(path), "--map", "time=t", "voltage=u", "current=i", "speed=w"], capsys)
    assert code == 2 and err.count("\n") == 1 and "--resample" in err and "--split-gaps" in err
