"""``cosim monitor`` and the residue model check on real recordings (../shared/realdata, issue 22).

The .mat files are read here with scipy.io and written as CSV into tmp_path (the monitor's readers take
CSV on this branch); nothing is copied into the project. Skipped where ../shared/realdata is absent.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from feeddrive.cosim.cli import main
from feeddrive.estimator.adequacy import check_adequacy

REALDATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "realdata"
sio = pytest.importorskip("scipy.io")


def _need(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"real recordings not found: {path}")
    return path


@pytest.fixture(scope="module")
def quanser(tmp_path_factory) -> Path:
    """time [s], logged command voltage [V], current [A], speed [rad/s] of motor 0 (quanser_aero2)."""
    mat = sio.loadmat(_need(REALDATA / "quanser_aero2" / "NO_WEIGHTS_4V.mat"))
    (matrix,) = [v for k, v in mat.items() if not k.startswith("__")]
    path = tmp_path_factory.mktemp("quanser") / "quanser.csv"
    np.savetxt(path, matrix[[0, 1, 3, 9]].T, delimiter=",", header="t,V,I,w", comments="", fmt="%.9g")
    return path


def kuka_axis(axis: int) -> dict:
    rec = sio.loadmat(_need(REALDATA / "kuka_kr300" / "rec_A.mat"), squeeze_me=True, struct_as_record=False)["rec"]
    return {"w": np.deg2rad(rec.act_vel_mot_deg_per_s[axis - 1]), "torque": rec.act_torque_abs_nm[axis - 1],
            "position": np.deg2rad(rec.act_pos_mot_deg[axis - 1])}


def run(capsys, *args) -> tuple[int, str, str]:
    code = main(["monitor", *map(str, args)])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_quanser_one_current_sensor_never_a_traceback(quanser, tmp_path, capsys):
    code, out, err = run(capsys, quanser, "--map", "time=t", "voltage=V", "current1=I", "speed=w",
                         "--db", tmp_path / "h.sqlite", "--out", tmp_path / "out")
    assert code in (0, 2)
    assert "Traceback" not in err and "nan" not in out.lower()
    if code == 2:
        assert err.count("\n") == 1
    else:
        assert "current: not checked: no second current sensor (Im2)" in out
        report = (tmp_path / "out" / "report.json").read_text()
        assert "nan" not in report.lower() and "Im2" not in json.loads(report)["motions"][0]["residues"]


def test_quanser_raw_command_voltage_is_a_mismatch(quanser, tmp_path, capsys):
    """With the manual's R and K, the logged command (8 V) is not the terminal voltage (about 5.6 V
    through the amplifier): the residue check flags a mismatch, in the monitor and as a function."""
    code, out, err = run(capsys, quanser, "--map", "time=t", "voltage=V", "current1=I", "speed=w",
                         "--db", tmp_path / "h.sqlite", "--known", "R=8.4", "K=0.042", "--json")
    assert code == 0, err
    (m,) = json.loads(out)["motions"]
    assert m["adequacy"]["verdict"] == "model mismatch" and m["adequacy"]["p_value"] < 0.01
    assert m["adequacy"]["equations"]["electrical"]["p_value"] < 0.01
    assert m["verdict"] == "model mismatch" and not m["validated"]


@pytest.mark.parametrize("axis", [2, 3])
def test_kuka_gravity_axes_are_a_mismatch_not_a_lack_of_excitation(axis, tmp_path, capsys):
    """Axes 2 and 3 carry gravity, which the DC model lacks: the estimator alone called it "not enough
    excitation to identify Jt"; the residue check names the mismatch."""
    sig = kuka_axis(axis)
    res = check_adequacy(0.004, **sig)
    assert res.verdict == "model mismatch" and res.p_value < 0.01, res.line()
    assert res.equations["mechanical"].effect > 0.05
    path = tmp_path / f"kuka{axis}.csv"
    np.savetxt(path, np.column_stack([np.arange(sig["w"].size) * 0.004, sig["w"], sig["torque"]]), delimiter=",",
               header="t,w,T", comments="", fmt="%.9g")
    code, out, err = run(capsys, path, "--map", "time=t", "speed=w", "torque=T", "--segment", "none",
                         "--db", tmp_path / "h.sqlite", "--json")
    assert code == 0, err
    (m,) = json.loads(out)["motions"]
    assert m["verdict"] == "model mismatch" and m["adequacy"]["verdict"] == "model mismatch"
    assert "not enough excitation" not in m["verdict"]


def test_quanser_model_check_that_cannot_run_says_why_and_keeps_the_estimates(quanser, tmp_path, capsys):
    """500 Hz: L/R (about 1 ms) is shorter than the sample period, L is refused and fixed at 0, so the paper's
    output-error check cannot simulate the current. It said "not estimated" (the check's simulation
    diverged) and dropped the estimates; now the check says why it did not run, R and K are given (the
    manual's 8.4 Ohm and 0.042 within the amplifier's and the propeller's distortions) and the residue
    check decides."""
    code, out, err = run(capsys, quanser, "--map", "time=t", "voltage=V", "current1=I", "speed=w",
                         "--db", tmp_path / "h.sqlite", "--json")
    assert code == 0, err
    assert err == ""  # no numpy warning of the diverging simulation
    (m,) = json.loads(out)["motions"]
    why = m["not_checked"]["model (paper, output error)"]
    assert why.startswith("not checked: the model check could not be run: its simulation needs L > 0, the fit "
                          "holds L = 0 (sample period 0.002 s too long for the electrical time constant"), why
    assert m["refused"]["L"].startswith("sample period 0.002 s too long") and m["fitted"]["L"] == 0.0
    assert {"R", "K"} <= set(m["parameters"]) and not m["verdict"].startswith("not estimated")
    assert 0.8 < m["parameters"]["R"]["value"] / 8.4 < 1.3 and 1.0 < m["parameters"]["K"]["value"] / 0.042 < 1.6
    assert m["verdict"] == "model mismatch" and m["adequacy"]["verdict"] == "model mismatch"
