"""``cosim estimate`` with refusals, bounds, fallbacks and several recordings of one machine (issue 22).

Recordings are built from the model's equations with known parameters (tests/estimator/synthetic.py),
1 kHz, white noise at 40 dB, written as CSV with units in the headers.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "estimator"))
from synthetic import ROUND_TRIP, TRUTH, record  # noqa: E402

from feeddrive.cosim.cli import main  # noqa: E402

H = 1e-3
MAP = ["--map", "time=t", "voltage=u", "current=i", "speed=w"]


def write(path: Path, params: dict | None = None, seed: int = 0, snr_db: float | None = 40.0) -> Path:
    d = record(ROUND_TRIP, H, params, snr_db=snr_db, seed=seed)
    np.savetxt(path, np.column_stack([d["t"], d["u"], d["i"], d["w"]]), delimiter=",",
               header="t [s],u [V],i [A],w [rad/s]", comments="", fmt="%.12g")
    return path


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("runs")
    out = {f"run{k}": write(root / f"run{k}.csv", seed=k) for k in range(3)}
    out["heavy"] = write(root / "heavy.csv", {"Jt": 1.3 * TRUTH["Jt"]}, seed=5)
    return out


def run(capsys, *argv) -> tuple[int, str, str]:
    code = main(["estimate", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def test_three_repeats_are_consistent_and_pooled_within_the_intervals(runs, capsys):
    code, out, err = run(capsys, runs["run0"], runs["run1"], runs["run2"], *MAP, "--json")
    assert code == 0 and err == ""
    doc = json.loads(out)
    assert [Path(f["file"]).name for f in doc["files"]] == ["run0.csv", "run1.csv", "run2.csv"]
    c = doc["consistency"]
    assert c["verdict"] == "consistent" and c["p_value"] > 0.01 and c["differ"] == []
    assert c["joint"]["dof"] == 2 * 6 and 0 <= c["joint"]["p_value"] <= 1
    for name, p in c["pooled"].items():
        assert p["ci95"][0] <= TRUTH[name] <= p["ci95"][1], name
        assert p["count"] == 3 and p["unit"]
    for f in doc["files"]:  # each file's own estimate is in its row
        assert set(f["estimate"]) == set(TRUTH) - {"T0"}


def test_a_glob_with_a_heavier_axis_is_judged_to_differ_in_jt(runs, capsys):
    pattern = str(runs["run0"].parent / "*.csv")  # heavy, run0, run1, run2
    code, out, _ = run(capsys, pattern, *MAP)
    assert code == 0
    assert out.splitlines()[0].split()[:2] == ["file", "R"]
    assert [line.split()[0] for line in out.splitlines()[1:5]] == ["heavy.csv", "run0.csv", "run1.csv", "run2.csv"]
    assert "agreement: differ: Jt (p < 1e-300, " in out and "(4 file(s), the files differ)" in out
    code, out, _ = run(capsys, pattern, *MAP, "--json")
    assert json.loads(out)["consistency"]["differ"] == ["Jt"]


def test_a_pattern_matching_nothing_is_one_line_and_exit_2(runs, capsys):
    code, _, err = run(capsys, str(runs["run0"].parent / "nothing*.csv"), *MAP)
    assert code == 2 and err.count("\n") == 1 and "no file matches this pattern" in err


def test_bounds_flag_an_estimate_and_offer_a_bounded_one(runs, capsys):
    code, out, _ = run(capsys, runs["run0"], *MAP, "--bounds", "Jt=0.2:", "ft=0:", "--json")
    assert code == 0
    (seg,) = json.loads(out)["segments"]
    assert list(seg["flags"]) == ["Jt"] and "below the stated lower bound 0.2" in seg["flags"]["Jt"]
    assert seg["bounded"]["Jt"] == {"value": pytest.approx(0.2), "bounded": True}
    code, out, _ = run(capsys, runs["run0"], *MAP, "--bounds", "Jt=0.2:")
    assert "Jt  FLAGGED, not to be validated: Jt = 0.1" in out and "\n  bounded estimate: R 0.59" in out
    code, _, err = run(capsys, runs["run0"], *MAP, "--bounds", "Jt=1:0")
    assert code == 2 and err.count("\n") == 1 and "--bounds 'Jt=1:0'" in err


def test_json_says_which_method_ran_when_oe_falls_back(tmp_path, capsys):
    path = write(tmp_path / "fast_current.csv", {"L": TRUTH["R"] * H / 5}, snr_db=None)
    code, out, err = run(capsys, path, *MAP, "--method", "oe", "--json")
    assert code == 0 and "Warning" not in err
    (seg,) = json.loads(out)["segments"]
    assert seg["method"] == "iv" and seg["method_requested"] == "oe" and "L = 0" in seg["fallback"]
    assert seg["refused"]["L"].startswith("sample period 0.001 s too long for the electrical time constant")
    assert seg["fixed"] == {"L": 0.0}
    for name in ("R", "K"):
        assert seg["parameters"][name]["value"] == pytest.approx(TRUTH[name], rel=0.02)


def test_a_repeat_of_which_nothing_can_be_estimated_is_left_out_with_a_note(runs, tmp_path, capsys):
    short = tmp_path / "short.csv"
    lines = runs["run0"].read_text().splitlines()
    short.write_text("\n".join(lines[:1] + lines[600:611]) + "\n")  # 11 samples: too short for the filter
    code, out, err = run(capsys, runs["run0"], runs["run1"], short, *MAP, "--json", "--segment", "none")
    assert code == 0 and len(json.loads(out)["files"]) == 2
    assert err.startswith(f"cosim estimate: {short} left out: ") and "motion too short: 11 samples" in err
    assert err.count("\n") == 1
