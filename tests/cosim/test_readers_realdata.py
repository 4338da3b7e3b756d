"""The readers on the real recordings of ../shared/realdata (other people's files, in their own formats).

``cosim info`` lists what each README entry names, and the README's role maps resolve to arrays of the
recording's length and rate. No estimates are asserted here (the estimator's tests do that).
"""
from __future__ import annotations

from pathlib import Path

import pytest

from feeddrive.cosim.cli import main
from feeddrive.cosim.errors import DataError
from feeddrive.cosim.recorded import load_recording

REALDATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "realdata"

#: file -> (lines `cosim info` must print (name, shape, dtype, unit as columns), role map, samples, rate [Hz])
CASES = {
    "kuka_kr300/rec_A.mat": (
        ["rec.act_torque_abs_nm 2501 x 6 float64 stored 6 x 2501", "rec.act_vel_mot_deg_per_s 2501 x 6 float64",
         "rec.act_pos_mot_deg 2501 x 6 float64", "rec.act_pos_se_deg 2501 x 6 float64", "rec.time_cont 2501 float64"],
        {"time": "rec.time_cont", "torque": "rec.act_torque_abs_nm[:,0]",
         "speed": f"rec.act_vel_mot_deg_per_s[:,0]*{3.141592653589793 / 180 * 1798 / 7}"}, 2501, 250.0),
    "quanser_aero2/NO_WEIGHTS_4V.mat": (
        ["data 44402 x 11 float64 stored 11 x 44402"],
        {"time": "data[:,0]", "voltage": "data[:,1]", "current": "data[:,3]", "speed": "data[:,9]"}, 44402, 500.0),
    "regbot/regbot_karla_10_f.txt": (
        ["time 472 float64 sec", "Motor voltage left 472 float64 V", "Motor current left 472 float64 A",
         "Wheel velocity left 472 float64 m/s", "Battery voltage 472 float64 V"],
        {"time": "time", "voltage": "Motor voltage left", "current": "Motor current left",
         "speed": "Wheel velocity left"}, 472, 1000.0),
    "regbot/regbot_karla_10_mf.txt": (
        ["Motor voltage right 472 float64 V", "Motor current right 472 float64 A"],
        {"time": "time", "voltage": "Motor voltage right", "current": "col10"}, 472, 1000.0),
    "umich_cnc/experiment_01.csv": (
        ["X1_ActualPosition 1055 float64", "X1_CurrentFeedback 1055 float64", "X1_OutputVoltage 1055 float64",
         "Machining_Process 1055 text"],
        {"voltage": "X1_OutputVoltage", "current": "X1_CurrentFeedback", "speed": "X1_ActualVelocity*0.001"},
        1055, 10.0),
} | {f"hsm150/idf_pos_0.06_{k}.mat": (
    ["data 20000 x 7 float64", "Im 20000 float64", "J scalar float64"],
    {"time": "data[:,0]", "speed": "data[:,3]", "torque": "data[:,5]"}, 20000, 1000.0) for k in (1, 2, 3)}


@pytest.fixture(scope="module")
def realdata() -> Path:
    if not REALDATA.is_dir():
        pytest.skip(f"real recordings not found: {REALDATA}")
    return REALDATA


@pytest.mark.parametrize("name", CASES)
def test_info_lists_the_variables_the_readme_names(realdata, name, capsys):
    lines, _, n, rate = CASES[name]
    assert main(["info", str(realdata / name)]) == 0
    out = capsys.readouterr().out
    rows = [" ".join(line.split()) for line in out.splitlines()]
    for expected in lines:  # name, shape, dtype, unit (and the note where the test names it)
        assert any(r == expected or r.startswith(expected + " ") for r in rows), f"{expected!r} not in\n{out}"
    if name.startswith("umich"):  # no time column: says what to give
        assert "time: no time column found" in out and "--rate HZ or --dt SECONDS" in out
    else:
        assert f"({rate:g} Hz)" in out and "no gaps" in out and f"{n} samples" in out


@pytest.mark.parametrize("name", CASES)
def test_the_readme_role_maps_resolve_to_the_recordings_length_and_rate(realdata, name):
    _, role_map, n, rate = CASES[name]
    sample_time = 0.1 if name.startswith("umich") else None
    if sample_time is not None:
        with pytest.raises(DataError, match=r"no time column \(role time\).*--rate HZ or --dt SECONDS"):
            load_recording(realdata / name, role_map)
    rec = load_recording(realdata / name, role_map, sample_time)
    assert rec.n == n and 1 / rec.h == pytest.approx(rate, rel=1e-6)  # kuka: float32-rounded stamps
    assert set(rec.signals) == set(role_map) - {"time"}
    assert rec.timing["gaps"] == 0 and rec.timing["action"] == "none"


def test_kuka_axis_columns_are_the_stored_rows(realdata):
    """``[:,k]`` of the samples-first matrix is row k of what the logger stored (6 x 2501)."""
    import scipy.io

    raw = scipy.io.loadmat(realdata / "kuka_kr300/rec_A.mat", simplify_cells=True)["rec"]["act_torque_abs_nm"]
    for k in range(6):
        rec = load_recording(realdata / "kuka_kr300/rec_A.mat", {"time": "rec.time_cont",
                                                                  "torque": f"rec.act_torque_abs_nm[:,{k}]"})
        assert (rec.signals["torque"] == raw[k]).all()
