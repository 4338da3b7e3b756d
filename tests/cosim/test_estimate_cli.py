"""``cosim estimate`` on recorded CSV files (and ``cosim.recorded.load_recording``)."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "estimator"))
from plant_data import TRUTH, closed_loop  # noqa: E402

from feeddrive.cosim.cli import main  # noqa: E402
from feeddrive.cosim.errors import DataError  # noqa: E402
from feeddrive.cosim.recorded import load_recording  # noqa: E402

HEADER = "time [s],u [V],i [A],w [rad/s],theta [rad],state"
MAP = ["--map", "time=time", "--map", "voltage=u", "--map", "current=i [A]", "--map", "speed=w"]


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    d = closed_loop()
    state = (np.abs(d["w_ref"]) > 0).astype(float)
    path = tmp_path_factory.mktemp("rec") / "axis.csv"
    np.savetxt(path, np.column_stack([d["t"], d["u"], d["i"], d["w"], d["theta"], state]), delimiter=",",
               header=HEADER, comments="", fmt="%.12g")
    return path


def run(capsys, *argv) -> tuple[int, str, str]:
    code = main(["estimate", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def test_json_holds_every_parameter_within_half_a_percent(recording, capsys):
    code, out, _ = run(capsys, recording, *MAP, "--json")
    assert code == 0
    (seg,) = json.loads(out)["segments"]
    assert set(seg) == {"start", "end", "method", "parameters", "condition_number", "fit_error", "model_check",
                        "rate_hz"}
    assert seg["method"] == "iv" and seg["condition_number"] < 100
    assert seg["model_check"]["verdict"] == "adequate"  # the residue check (estimator/adequacy.py)
    for name, p in seg["parameters"].items():
        assert p["value"] == pytest.approx(TRUTH[name], rel=0.005), name
        assert p["ci95"][0] <= p["value"] <= p["ci95"][1]
    assert 0.0 < seg["start"] < 0.14 and 3.5 > seg["end"] > 3.4  # speed-profile segmentation, padded


def test_nc_state_segmentation_and_table_output(recording, capsys):
    code, out, _ = run(capsys, recording, *MAP, "--map", "state=state", "--segment", "nc", "--method", "ls")
    assert code == 0
    # the NC state is 1 while w_ref != 0: the round trip is two motions, one per direction
    assert out.startswith("motion 1: 0.1001-1.66 s, LS") and "\nmotion 2: 1.86-3.42 s, LS" in out
    assert out.count("95 % CI") == 12


def test_known_K_without_voltage_reports_only_the_mechanical_parameters(recording, capsys):
    code, out, _ = run(capsys, recording, "--map", "time=time", "--map", "current=i", "--map", "position=theta",
                       "--known", f"K={TRUTH['K']}", "--json")
    assert code == 0
    (seg,) = json.loads(out)["segments"]
    assert set(seg["parameters"]) == {"Jt", "ft", "Cd"}
    assert seg["parameters"]["Jt"]["value"] == pytest.approx(TRUTH["Jt"], rel=0.005)


def write(tmp_path: Path, rows: list[list[str]], header: str = HEADER) -> Path:
    path = tmp_path / "bad.csv"
    path.write_text(header + "\n" + "\n".join(",".join(r) for r in rows) + "\n")
    return path


def good_rows(n: int = 20) -> list[list[str]]:
    return [[f"{k * 1e-4:.4f}", "1", "2", "3", "4", "1"] for k in range(n)]


@pytest.mark.parametrize("case, needle", [
    ("missing", "column 'current_A' (role current) not found"),
    ("time", "'time [s]' is not strictly increasing at row 7"),
    ("nan", "column 'i [A]' row 4: 'nan' is not a finite number"),
    ("short", "5 samples, need at least 10"),
])
def test_bad_csv_gives_one_line_and_exit_status_2(tmp_path, capsys, case, needle):
    rows = good_rows(5 if case == "short" else 20)
    argv = list(MAP)
    if case == "missing":
        argv[5] = "current=current_A"
    elif case == "time":
        rows[5][0] = "0.0001"
    elif case == "nan":
        rows[2][2] = "nan"
    code, out, err = run(capsys, write(tmp_path, rows), *argv)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and needle in err and "bad.csv" in err


def test_bad_map_and_known_options_are_refused(recording, capsys):
    assert run(capsys, recording, "--map", "volts=u")[0] == 2
    code, _, err = run(capsys, recording, *MAP, "--known", "K=fast")
    assert code == 2 and "--known K='fast'" in err


def test_load_recording_matches_columns_with_or_without_units(recording):
    rec = load_recording(recording, {"time": "time", "current": "i", "speed": "w [rad/s]"})
    assert rec.columns == {"current": "i [A]", "speed": "w [rad/s]"}
    assert rec.h == pytest.approx(1e-4) and rec.t0 == 0.0 and rec.n == len(closed_loop()["i"])
    by_period = load_recording(recording, {"current": "i"}, sample_time=1e-4)
    np.testing.assert_array_equal(by_period.signals["current"], rec.signals["current"])
    with pytest.raises(DataError, match="sample time is 0.001"):
        load_recording(recording, {"time": "time", "current": "i"}, sample_time=1e-3)
    with pytest.raises(DataError, match="no time column"):
        load_recording(recording, {"current": "i"})


def test_a_motion_that_cannot_be_estimated_is_left_out_with_a_note(tmp_path, capsys):
    d = closed_loop()
    state = (np.abs(d["w_ref"]) > 0).astype(float)
    state[100:110] = 1.0  # a 1 ms "rapid" block before the real one: too short to filter
    path = tmp_path / "blip.csv"
    np.savetxt(path, np.column_stack([d["t"], d["u"], d["i"], d["w"], d["theta"], state]), delimiter=",",
               header=HEADER, comments="", fmt="%.12g")
    code, out, err = run(capsys, path, *MAP, "--map", "state=state", "--json")
    assert code == 0
    assert len(json.loads(out)["segments"]) == 2
    assert err.startswith("cosim estimate: motion 0.01-0.0109 s left out:") and err.count("\n") == 1
