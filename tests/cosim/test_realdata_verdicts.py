"""Verdicts on real recordings as a new user gets them (../shared/realdata, audit 2): right, or saying why not.

Skipped with the reason where ../shared/realdata is absent.
"""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from feeddrive.cosim.cli import main as cosim
from feeddrive.cosim.cli.monitor import NOTHING_JUDGED

REALDATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "realdata"
HSM = REALDATA / "hsm150"
pytestmark = pytest.mark.skipif(not HSM.is_dir(), reason=f"real recordings not found: {HSM}")
HSM_MAP = ["time=data[:,0] [s]", "speed=data[:,3] [rad/s]", "torque=data[:,5] [N.m]"]


def monitor(capsys: pytest.CaptureFixture, *args: object) -> tuple[int, dict | None, str]:
    code = cosim(["monitor", *map(str, args)])
    out, err = capsys.readouterr()
    return code, (json.loads(out) if code in (0, NOTHING_JUDGED) else None), err


def test_a_motion_whose_every_parameter_is_refused_is_not_estimated_and_stays_out_of_the_baseline(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """HSM150 repeat 2 at the monitor's 100 Hz cut-off: Jt, ft and Cd are each refused (IV's halves alias at
    1 kHz). The motion was "healthy", validated, and counted as healthy baseline motion 2 of 3 with no
    parameter at all; the history's trends page said its baseline was the mean of 3 motions while only one
    held values. Nothing given is nothing validated: "not estimated", with every refusal's reason kept."""
    db = tmp_path / "h.sqlite"
    code, first, err = monitor(capsys, HSM / "idf_pos_0.06_1.mat", "--map", *HSM_MAP, "--segment", "none",
                               "--db", db, "--axis", "hsm", "--json", "--start-time", "2024-01-01T10:00:00")
    assert code == 0, err
    (m1,) = first["motions"]
    assert m1["verdict"] == "healthy" and {"ft", "Cd"} <= set(m1["parameters"])
    # the split-sample IV does not settle on repeat 1: the lagged IV stands in, and the result says which ran
    # (report.json method_used; report.html "method iv-lag standing in for iv"), with Jt near the catalogue's 1.2e-4
    assert m1["method"] == "iv" and m1["method_used"] == "iv-lag", m1.get("method_used")
    assert 0.9e-4 < m1["parameters"]["Jt"]["value"] < 1.4e-4, m1["parameters"]["Jt"]
    code, second, err = monitor(capsys, HSM / "idf_pos_0.06_2.mat", "--map", *HSM_MAP, "--segment", "none",
                                "--db", db, "--axis", "hsm", "--json", "--start-time", "2024-01-01T11:00:00")
    assert code == NOTHING_JUDGED, err  # nothing judged: a script must not take it for a verdict (it exited 0)
    assert err.strip() == f"nothing judged: motion 1: {second['motions'][0]['error']}"
    (m2,) = second["motions"]
    assert m2["parameters"] == {} and {"Jt", "ft", "Cd"} <= set(m2["refused"])  # the case this test is about
    assert not m2["validated"]
    assert m2["verdict"].startswith("not estimated: every parameter refused (Jt, ft, Cd)"), m2["verdict"]
    assert m2["adequacy"]["verdict"] == "adequate"  # the residue check is still reported
    assert not any(n.startswith("healthy baseline") for n in m2["notes"]), m2["notes"]


def test_repeats_of_one_machine_are_not_drifting_on_intervals_conditional_on_a_refused_inertia(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """HSM150 repeats 1 and 2 (the same torque-step experiment) at the estimate's 50 Hz cut-off: on repeat 2 Jt is
    refused and fixed at its own estimate, and the intervals of ft and Cd given that value were 5 times narrower
    than without it (Cd +-0.0011 N.m against +-0.0066): repeat 2 was "drifting: unexplained drift (Cd)" against
    repeat 1. Motions are compared, like files (cosim estimate A B), on the intervals not conditional on it."""
    db = tmp_path / "h.sqlite"
    runs = []
    for k, hour in ((1, 10), (2, 11)):
        code, doc, err = monitor(capsys, HSM / f"idf_pos_0.06_{k}.mat", "--map", *HSM_MAP, "--segment", "none",
                                 "--filter-cutoff", "50", "--db", db, "--axis", "hsm", "--json",
                                 "--start-time", f"2024-01-01T{hour}:00:00")
        assert code == 0, err
        runs.append(doc["motions"][0])
    first, second = runs
    assert "Jt" in second["refused"] and {"ft", "Cd"} <= set(second["parameters"])  # the case this test is about
    assert second["verdict"] == "healthy" and second["diagnosis"] == [], second["diagnosis"]
    lo, hi = second["parameters"]["Cd"]["ci95"]
    assert hi - lo > 0.01  # +-0.0066 N.m: the interval several files are compared with
    assert lo < first["parameters"]["Cd"]["value"] < hi


def test_files_that_share_no_given_parameter_are_not_called_consistent(capsys: pytest.CaptureFixture) -> None:
    """HSM150 repeats 1 and 2 at a 100 Hz cut-off: repeat 2 has every parameter refused, so no parameter is given
    by both files. The agreement said "consistent (p = 1, Bonferroni over 0 parameters; joint chi2 0 on 0 dof)":
    a verdict with no test behind it."""
    argv = ["estimate", *(str(HSM / f"idf_pos_0.06_{k}.mat") for k in (1, 2)), "--map", *HSM_MAP,
            "--segment", "none", "--filter-cutoff", "100"]
    assert cosim([*argv, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["files"][1]["estimate"] == {}  # the case this test is about
    consistency = doc["consistency"]
    assert consistency["verdict"].startswith("not tested") and consistency["p_value"] is None
    assert consistency["per_parameter"] == {} and consistency["differ"] == []
    assert cosim(argv) == 0
    out = capsys.readouterr().out
    assert "agreement: not tested: no parameter is given by two files or more" in out and "consistent" not in out
