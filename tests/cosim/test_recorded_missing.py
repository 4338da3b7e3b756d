"""Rows with a missing value (audit 6): refused by default, naming ``--missing drop``; dropped with it, the rows
left keep their times and the dropped ones become gaps for ``--resample`` / ``--split-gaps``.

The DC-motor-like motion of dc_motion.py (4 s at 1 kHz) with three rows missing a value: a ``nan`` speed, an
empty torque cell and an ``inf`` speed, as loggers and spreadsheets leave them.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from dc_motion import TRUTH, motor  # noqa: E402

from feeddrive.cosim.cli import main  # noqa: E402

ROWS = (1000, 2000, 3000)  # samples whose row misses a value (file rows 1002, 2002, 3002: the header is row 1)
ARGS = ["--segment", "none", "--method", "ls", "--json"]


def write(path: Path, holes: bool, time: bool = True) -> Path:
    d = motor()
    lines = [("t [s]," if time else "") + "w [rad/s],T [N.m]"]
    for k in range(len(d["t"])):
        w, torque = f"{d['w'][k]:.12g}", f"{d['T'][k]:.12g}"
        if holes and k in ROWS:
            w, torque = {ROWS[0]: ("nan", torque), ROWS[1]: (w, ""), ROWS[2]: ("inf", torque)}[k]
        lines.append((f"{d['t'][k]:.12g}," if time else "") + f"{w},{torque}")
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("missing")
    return {"clean": write(folder / "clean.csv", False), "holes": write(folder / "holes.csv", True),
            "no_time": write(folder / "no_time.csv", True, time=False)}


def estimate(capsys, path: Path, *argv: str) -> tuple[dict, str]:
    mapping = ["--map", "speed=w", "torque=T"] + (["time=t"] if "no_time" not in path.name else [])
    assert main(["estimate", str(path), *mapping, *ARGS, *argv]) == 0
    out, err = capsys.readouterr()
    return json.loads(out), err


def values(out: dict) -> dict[str, float]:
    return {k: p["value"] for k, p in out["segments"][0]["parameters"].items()}


def test_a_missing_value_is_refused_by_default_naming_the_option(files, capsys) -> None:
    assert main(["estimate", str(files["holes"]), "--map", "time=t", "speed=w", "torque=T", *ARGS]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"cosim estimate: error: {files['holes']}: column 'w [rad/s]' row 1002: 'nan' is not a finite "
                   "number; expected a finite value, or --missing drop to drop the rows with a missing value (the gaps "
                   "left: --resample MAXGAP or --split-gaps)")
    assert main(["estimate", str(files["holes"]), "--map", "time=t", "torque=T", *ARGS]) == 2
    assert "column 'T [N.m]' row 2002: '' is not a number (a missing value? --missing drop drops such rows)" in \
        capsys.readouterr().err


def test_dropped_rows_are_gaps_said_and_bridged_giving_the_clean_records_parameters(files, capsys) -> None:
    clean, _ = estimate(capsys, files["clean"])
    assert main(["estimate", str(files["holes"]), "--map", "time=t", "speed=w", "torque=T", *ARGS,
                 "--missing", "drop"]) == 2  # gaps now: bridged or split only when asked
    assert "is not uniformly sampled (3997 samples, median step 0.001 s (1000 Hz), jitter below 0.0001 %, 3 gaps " \
           "(largest 0.002 s at t = 0.999 s, after sample 999)) after --missing drop dropped 3 rows (the first: " \
           "column 'w [rad/s]' row 1002: 'nan'); use --resample MAXGAP" in capsys.readouterr().err
    out, err = estimate(capsys, files["holes"], "--missing", "drop", "--resample", "0.005")
    assert ("--missing drop: dropped 3 rows with a missing value (the first: column 'w [rad/s]' row 1002: 'nan' at "
            "t = 1 s); the rows left keep their times") in err
    timing = out["timing"]
    assert (timing["dropped_rows"], timing["first_dropped"], timing["first_dropped_at_s"], timing["gaps"]) == \
        (3, "column 'w [rad/s]' row 1002: 'nan'", 1.0, 3)
    assert values(out) == pytest.approx(values(clean), rel=0.01)
    assert values(out) == pytest.approx(TRUTH, rel=0.03)


def test_without_a_time_column_the_rows_are_a_uniform_grid_and_dropped_the_same(files, capsys) -> None:
    clean, _ = estimate(capsys, files["clean"])
    out, err = estimate(capsys, files["no_time"], "--rate", "1000", "--missing", "drop", "--resample", "0.005")
    assert "dropped 3 rows with a missing value (the first: column 'w [rad/s]' row 1002: 'nan' at t = 1 s)" in err
    assert out["timing"]["source"] == "--rate/--dt" and out["timing"]["dropped_rows"] == 3
    assert values(out) == pytest.approx(values(clean), rel=0.01)
    out, _ = estimate(capsys, files["no_time"], "--rate", "1000", "--missing", "drop", "--split-gaps")
    assert out["timing"]["records"] == 4 and out["timing"]["dropped_rows"] == 3
