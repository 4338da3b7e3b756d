"""``cosim history``: the table, JSON, the trend plot and the one-line errors, on a real SQLite file."""
import json

import matplotlib.image
import pytest

from feeddrive.cosim.cli import main
from feeddrive.estimator.history import History

NAMES = ("R", "L", "K", "Jt", "ft", "Cd")


def motion(k, validated=True, drift=0.0):
    params = {n: {"value": v * (1 + drift), "std": 0.001 * v, "ci95": [v * (1 + drift) - 0.002 * v,
                                                                      v * (1 + drift) + 0.002 * v]}
              for n, v in zip(NAMES, (0.6, 0.004, 1.05, 0.1, 0.02, 1.2))}
    return {"motion": k, "start": 0.1, "end": 3.4, "validated": validated, "parameters": params,
            "sensor_faults": [] if validated else [{"sensor": "Im2", "kind": "gain", "gain": 1.03,
                                                    "gain_ci95": [1.029, 1.031], "offset": 0.0,
                                                    "offset_ci95": [-0.01, 0.01]}],
            "diagnosis": [{"fault": "bearing or slide-way wear", "parameters": ["Cd", "ft"], "evidence": []}]
            if drift else []}


@pytest.fixture
def db(tmp_path):
    path = tmp_path / "h.sqlite"
    with History(path) as h:
        h.record("X", motion(1), time=1.7e9)
        h.record("X", motion(2, validated=False), time=1.7e9 + 60)
        h.record("X", motion(3, drift=0.1), time=1.7e9 + 120)
        h.record("Y", motion(1), time=1.7e9)
    return path


def test_table(db, capsys):
    assert main(["history", "--db", str(db), "--axis", "X"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == ("axis X: 3 motion(s); parameters as estimate ± half-width of the 95 % confidence interval")
    assert out[1].split()[:3] == ["motion", "run:motion", "time"] and "R ±95%" in out[1]
    first, second, third = out[2:]
    assert "2023-11-14 22:13:20" in first and " yes " in first and "0.6 ±0.0012" in first
    assert " no " in second and "Im2:gain" in second
    assert "1.32 ±0.0024" in third and "bearing or slide-way wear" in third


def test_json_round_trip(db, capsys):
    assert main(["history", "--db", str(db), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert sorted(data["axes"]) == ["X", "Y"]
    assert [m["motion"] for m in data["axes"]["X"]] == [1, 2, 3]
    assert data["axes"]["X"][2]["parameters"]["Cd"] == motion(3, drift=0.1)["parameters"]["Cd"]


def test_plot_and_no_silent_overwrite(db, tmp_path, capsys):
    png = tmp_path / "trend.png"
    assert main(["history", "--db", str(db), "--axis", "X", "--plot", str(png)]) == 0
    image = matplotlib.image.imread(png)
    assert image.shape[0] > 500 and image.shape[1] > 800
    capsys.readouterr()
    assert main(["history", "--db", str(db), "--axis", "X", "--plot", str(png)]) == 2
    out, err = capsys.readouterr()
    assert "exists; use --overwrite" in err
    assert out.startswith("axis X: 3 motion(s)") and len(out.splitlines()) == 5  # the table all the same
    assert main(["history", "--db", str(db), "--axis", "X", "--plot", str(png), "--overwrite"]) == 0


def test_errors_are_one_line(db, tmp_path, capsys):
    assert main(["history", "--db", str(tmp_path / "none.sqlite")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "none.sqlite does not exist" in err
    assert not (tmp_path / "none.sqlite").exists()
    assert main(["history", "--db", str(db), "--axis", "Z"]) == 2
    assert "no motion for axis 'Z'" in capsys.readouterr().err


def test_motions_are_numbered_per_axis_across_runs(tmp_path, capsys):
    """Two runs of one motion each on axis X: motions 1 and 2 of the axis (each run's own number is 1)."""
    path = tmp_path / "h.sqlite"
    with History(path) as h:
        h.record("X", motion(1), time=1.7e9, scenario="tool-change")
        h.record("Y", motion(1), time=1.7e9, scenario="other-axis")
        h.record("X", motion(1), time=1.7e9 + 60, scenario="worn-axis")
    assert main(["history", "--db", str(path), "--axis", "X"]) == 0
    rows = capsys.readouterr().out.splitlines()[2:]
    assert [r.split()[:2] for r in rows] == [["1", "tool-change:1"], ["2", "worn-axis:1"]]


def test_the_database_as_an_argument(db, tmp_path, capsys):
    """``cosim history FILE`` reads FILE, as ``--db FILE`` does (it was an argparse error); two different files
    are refused in one line."""
    assert main(["history", str(db), "--axis", "Y"]) == 0
    assert capsys.readouterr().out.startswith("axis Y: 1 motion(s)")
    assert main(["history", str(db), "--db", str(tmp_path / "other.sqlite")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "two history files" in err
