"""``cosim monitor`` on a recorded CSV: the same pipeline as the component, history across invocations."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from feeddrive.cosim.cli import main
from feeddrive.estimator.history import History

_spec = importlib.util.spec_from_file_location(
    "validation_plant", Path(__file__).parents[1] / "estimator" / "test_validation.py")
plant = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(plant)
H = plant.H
COLUMNS = {"voltage": ("u [V]", "u"), "voltage_ref": ("u_ref [V]", "u_ref"), "current1": ("Im1 [A]", "Im1"),
           "current2": ("Im2 [A]", "Im2"), "speed": ("w_tach [rad/s]", "w_tach"),
           "position": ("theta_enc [rad]", "theta_enc")}
MAP = [a for role, (col, _) in COLUMNS.items() for a in ("--map", f"{role}={col.split(' [')[0]}")]
MAP += ["--map", "time=time", "--map", "state=state"]


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """Idle, a healthy motion, idle, a motion with an Im1 offset of 0.3 A, idle; NC state recorded."""
    motions = [plant.measure(plant.plant_motion(), 21), plant.measure(plant.plant_motion(), 22, Im1=(1.0, 0.3))]
    idle = 1000
    blocks, state = [], []
    for m in motions:
        blocks.append(np.zeros((idle, len(COLUMNS))))
        blocks.append(np.column_stack([m[s] for _, s in COLUMNS.values()]))
        state += [0] * idle + [1] * len(m["Im1"])
    blocks.append(np.zeros((idle, len(COLUMNS))))
    state += [0] * idle
    data = np.vstack(blocks)
    path = tmp_path_factory.mktemp("rec") / "axis_x.csv"
    header = ",".join(["time"] + [c for c, _ in COLUMNS.values()] + ["state"])
    np.savetxt(path, np.column_stack([np.arange(len(state)) * H, data, state]), delimiter=",", header=header,
               comments="", fmt="%.9g")
    return path


def test_two_invocations_continue_the_history(recording, tmp_path, capsys):
    db = tmp_path / "h.sqlite"
    assert main(["monitor", str(recording), *MAP, "--db", str(db), "--axis", "X7", "--json"]) == 0
    first = json.loads(capsys.readouterr().out)["motions"]
    assert [m["validated"] for m in first] == [True, True]
    # a recording states no R, L, K: the first motion had none to isolate with (it needed none: no pair disagreed)
    assert first[0]["reference"] == "none" and first[1]["reference"] == "last validated"
    assert first[0]["start"] == pytest.approx(1000 * H)
    for name, truth in (("R", 0.6), ("K", 1.05), ("Jt", 0.1), ("Cd", 1.2)):
        assert first[0]["parameters"][name]["value"] == pytest.approx(truth, rel=0.01), name
    (fault,) = first[1]["sensor_faults"]
    assert fault["sensor"] == "Im1" and fault["kind"] == "offset" and fault["offset"] == pytest.approx(0.3, abs=0.02)
    # a later recording of the axis (the same samples, stamped a day later)
    later = ["--start-time", "2030-01-02T00:00:00Z"]
    assert main(["monitor", str(recording), *MAP, "--db", str(db), "--axis", "X7", *later]) == 0
    out = capsys.readouterr().out
    assert "motion 1:" in out and "sensor fault Im1: offset" in out and "NOT validated" not in out
    with History(db) as h:
        stored = h.motions("X7")
    assert len(stored) == 4 and stored[2]["reference"] == "last validated"
    assert stored[0]["scenario"] == str(recording)
    # the same recording again would count its motions twice in the baseline and trends: refused, nothing stored
    assert main(["monitor", str(recording), *MAP, "--db", str(db), "--axis", "X7", *later]) == 2
    err = capsys.readouterr().err
    assert f"axis X7 already holds motion 1, 2 of the 2 of {recording} (history id 3, 4" in err
    assert err.count("\n") == 1 and "--db :memory: to look without storing" in err
    with History(db) as h:
        assert len(h.motions("X7")) == 4


def test_plots_and_errors(recording, tmp_path, capsys):
    db = str(tmp_path / "h.sqlite")
    assert main(["monitor", str(recording), *MAP, "--db", db, "--plots", str(tmp_path / "p")]) == 0
    assert sorted(p.name for p in (tmp_path / "p").iterdir()) == \
        ["monitor_correlation1.png", "monitor_correlation2.png", "monitor_motion1.png", "monitor_motion2.png",
         "monitor_trends.png"]
    capsys.readouterr()
    assert main(["monitor", str(recording), *MAP, "--db", db, "--plots", str(tmp_path / "p")]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert main(["monitor", str(recording), "--map", "voltage=u", "--db", db]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "missing required role(s): current1 (or torque), speed or position" in err
    assert main(["monitor", str(recording), "--map", "volt=u", "--db", db]) == 2
    assert "unknown role(s) ['volt']" in capsys.readouterr().err
    assert main(["monitor", str(recording), *MAP[:-4], "--map", "current2=nope", "--db", db]) == 2
    assert "column 'nope'" in capsys.readouterr().err


@pytest.mark.parametrize("blocker", ["file", "parent_file"])
def test_unusable_plot_folder_is_refused_before_the_history_is_written(recording, tmp_path, capsys, blocker):
    """A plot step failing after the history was written would store the motions twice on a re-run."""
    (tmp_path / "taken").write_text("not a folder")
    plots = tmp_path / "taken" / ("" if blocker == "file" else "p")
    db = tmp_path / "h.sqlite"
    assert main(["monitor", str(recording), *MAP, "--db", str(db), "--plots", str(plots)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--plots {plots}:" in err
    assert not db.exists()  # nothing stored: running it again stores each motion once
    # (without plots: drawing them, checked in test_plots_and_errors, was most of this test's CPU)
    assert main(["monitor", str(recording), *MAP, "--db", str(db)]) == 0
    with History(db) as h:
        assert [m["motion"] for m in h.motions("X")] == [1, 2]
