"""Diagnosis while the healthy baseline is being learnt (and kept out of it), across restarts.

A worn axis (paper Table I: Cd +50 %, ft +75 %) seen while the baseline holds fewer than
``baseline_motions`` healthy motions is diagnosed against the healthy motions accepted so far, with
the usual drift test, and is not added to the baseline; the history's baseline skips it, so a monitor
started later on the same database does not learn it either.

Plant data: the closed-loop CasADi model with redundant sensors of tests/estimator/test_validation.py.
"""
from __future__ import annotations

import importlib.util
import json
import shutil
from pathlib import Path

import pytest

from feeddrive.cosim.cli import main
from feeddrive.cosim.monitor import MonitorConfig, MonitorPipeline
from feeddrive.estimator.diagnosis import DiagnosisOptions
from feeddrive.estimator.history import History

_spec = importlib.util.spec_from_file_location(
    "validation_plant", Path(__file__).parents[1] / "estimator" / "test_validation.py")
plant = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(plant)
H = plant.H
EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
WEAR = {"bearing or slide-way wear", "lack or ageing of lubricating oil"}
CD, FT = plant.NOMINAL["Cd"], plant.NOMINAL["ft"]
WORN = (("Cd", 1.5 * CD, 0.0), ("ft", 1.75 * FT, 0.0))


def process(pipeline: MonitorPipeline, motion: int, changes=()) -> dict:
    signals = plant.measure(plant.plant_motion(changes), seed=40 + motion)
    return pipeline.process(signals, H, 0.0, motion, time=1000.0 * motion).result


def assert_wear(result: dict) -> None:
    """Wear / lubrication from Cd and ft, each sized against the healthy reference."""
    assert result["validated"] and {d["fault"] for d in result["diagnosis"]} == WEAR
    for d in result["diagnosis"]:
        assert d["parameters"] == ["Cd", "ft"]
        for ev, truth in zip(d["evidence"], (0.5, 0.75)):
            assert ev["relative_change"] == pytest.approx(truth, abs=0.03)
            assert ev["z_baseline"] > DiagnosisOptions().z_crit


def test_worn_motion_during_baseline_is_diagnosed_and_kept_out(tmp_path):
    db = tmp_path / "history.sqlite"
    config = MonitorConfig(db=str(db), baseline_motions=3)
    with History(db) as history:
        pipe = MonitorPipeline(config, history, "X")
        first = process(pipe, 1)
        assert first["diagnosis"] == [] and "healthy baseline: motion 1 of 3" in first["notes"]
        worn = process(pipe, 2, WORN)
        assert_wear(worn)
        assert ("healthy baseline incomplete (1 of 3): drift diagnosed against the 1 healthy motion(s) so far; "
                "not added to the baseline") in worn["notes"]
        assert len(pipe.baseline_sets) == 1 and pipe.last_validated is worn["parameters"]  # theta_{j-1} is worn
    with History(db) as history:  # a restart reads the same memory back from SQLite
        pipe = MonitorPipeline(config, history, "X")
        assert pipe.baseline_sets == [first["parameters"]] and pipe.last_validated == worn["parameters"]
        # still worn: unchanged against theta_{j-1}, but diagnosed against the healthy motion
        again = process(pipe, 3, WORN)
        assert_wear(again)
        for d in again["diagnosis"]:
            assert all(abs(ev["relative_change"]) > 0.4 and abs(ev["z_last"]) < 5 for ev in d["evidence"])
        # a healthy motion after the worn ones joins the baseline (no drift against the healthy reference)
        healthy = process(pipe, 4)
        assert healthy["diagnosis"] == [] and "healthy baseline: motion 2 of 3" in healthy["notes"]
        assert [b["motion"] for b in history.baseline("X", 3)] == [1, 4]


@pytest.mark.slow
def test_cosim_run_tool_change_then_worn_axis_whatever_the_out_dir(tmp_path, monkeypatch, example_runs, capsys):
    """The README's runs on the default history runs/history.sqlite: the worn axis is another axis
    (worn-X), diagnosed on its own against the nominal parameters (``baseline: nominal``); axis X's
    history holds the two healthy tool changes only (the worn machine never mixes into it). Each run
    names the history, its axis and the baseline's state.

    The first tool change and the worn axis are the session's ``cosim run`` of the examples (tests/conftest.py,
    with the sensor-fault example's axis sensor-X on the same history), continued here in a copy of their folder."""
    shutil.copytree(example_runs["work"], tmp_path, dirs_exist_ok=True)
    monkeypatch.chdir(tmp_path)
    printed = [next(ln for ln in example_runs["stdout"][name].splitlines() if ln.startswith("  history:"))
               for name in ("worn_axis", "tool_change")]
    # the second tool change writes elsewhere (--out): the history stays runs/history.sqlite (on main, --out
    # elsewhere/run2 silently switched to elsewhere/history.sqlite); drawn without its figures (--no-plots)
    assert main(["run", str(EXAMPLES / "tool_change.yaml"), "--no-progress", "--out", "elsewhere/run2",
                 "--no-plots"]) == 0
    summary = capsys.readouterr().out.splitlines()
    printed.append(next(ln for ln in summary if ln.startswith("  history:")))
    assert not Path("elsewhere/history.sqlite").exists()
    # --no-plots: no plots/*.png and none listed, report.html still written, the same estimate (bit for bit)
    assert summary[-1].endswith("report.html, 0 plots") and not Path("elsewhere/run2/plots").exists()
    assert json.loads(Path("elsewhere/run2/report.json").read_text())["files"]["plots"] == []
    assert Path("elsewhere/run2/report.html").is_file()
    assert printed[0] == ("  history: runs/history.sqlite, axis worn-X; healthy baseline: the nominal parameters "
                          "(monitor.baseline: nominal)")
    assert printed[1].startswith("  history: runs/history.sqlite, axis X; learning the healthy baseline: 1 of 3")
    assert printed[2].startswith("  history: runs/history.sqlite, axis X; learning the healthy baseline: 2 of 3")
    reports = {p.parent.name: json.loads(p.read_text())["motions"] for p in Path("runs").glob("*/report.json")}
    (healthy,) = next(m for k, m in reports.items() if k.startswith("tool-change"))
    (again,) = json.loads(Path("elsewhere/run2/report.json").read_text())["motions"]
    # the second motion is checked against the first one's validated parameters
    assert [healthy["reference"], again["reference"]] == ["nominal", "last validated"]
    assert again["parameters"] == healthy["parameters"]  # the same plant and noise: figures or not, the same fit
    (worn,) = next(m for k, m in reports.items() if k.startswith("worn-axis"))
    assert healthy["validated"] and healthy["diagnosis"] == []
    assert worn["validated"] and {d["fault"] for d in worn["diagnosis"]} == WEAR
    for d in worn["diagnosis"]:  # the plant: Cd 1.2 -> 1.8 N m (+50 %), ft 0.02 -> 0.035 N m s/rad (+75 %)
        assert [ev["relative_change"] for ev in d["evidence"]] == pytest.approx([0.5, 0.75], abs=0.03)
    assert again["diagnosis"] == [] and "healthy baseline: motion 2 of 3" in again["notes"]
    with History("runs/history.sqlite") as history:
        stored = history.motions("X")
        assert [m["scenario"] for m in stored] == ["tool-change", "tool-change"]
        assert [m["scenario"] for m in history.motions("worn-X")] == ["worn-axis"]
        assert [b["id"] for b in history.baseline("X", 3)] == [stored[0]["id"], stored[1]["id"]]
    # `cosim history` finds them by default; --db puts a run's motions into another file, and only there
    assert main(["history", "--axis", "X"]) == 0
    assert capsys.readouterr().out.startswith("axis X: 2 motion(s)")
    assert main(["run", str(EXAMPLES / "tool_change.yaml"), "--no-progress", "--out", "run3", "--db", "other.sqlite",
                 "--no-plots"]) == 0
    assert "  history: other.sqlite, axis X; learning the healthy baseline: 1 of 3" in capsys.readouterr().out
    with History("other.sqlite") as other, History("runs/history.sqlite") as default:
        assert len(other.motions("X")) == 1 and len(default.motions("X")) == 2
