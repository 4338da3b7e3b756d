"""A vendor FMU that crashes, hangs, fails or returns NaN at t = 0.5 s never takes `cosim run` down.

The FMU (tests/cosim/data/faulty.c) is compiled here with the system C compiler. For each failure the
CLI exits 1 with exactly one stderr line naming the FMI function, signals.csv holds every step up to the
failure (an ideal axis: its position is the integral of the NC's speed reference, checked against the
recorded reference), report.json has the status and the history database passes PRAGMA integrity_check.
"""
from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import numpy as np
import pytest
import yaml
from faulty import MAP, MODES, build
from markupsafe import escape

from feeddrive.cosim.cli import main
from feeddrive.cosim.component import Component
from feeddrive.cosim.supervise import last_recorded_time, supervise

FAIL_TIME = 0.5


@pytest.fixture(scope="module")
def faulty_fmu(built_once) -> Path:
    return built_once("Faulty", lambda folder: build(folder / "Faulty.fmu"))


def scenario(tmp_path: Path, fmu: Path, mode: str, **plant) -> Path:
    data = {"name": f"faulty-{mode}", "axis": "X", "step": 1e-4, "stop_time": 0.6,
            "plant": {"fmu": str(fmu), "parameters": {"mode": MODES[mode]}, "map": MAP, **plant},
            "nc": {"program": [{"rapid": {"to": 0.01, "v_max": 0.05, "accel": 0.5}}]},
            "monitor": {"db": str(tmp_path / "history.sqlite")}}
    path = tmp_path / f"{mode}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def read_signals(path: Path) -> dict[str, np.ndarray]:
    header = path.read_text().split("\n", 1)[0].split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {name.split(" [")[0]: data[:, k] for k, name in enumerate(header)}


CASES = [  # mode, report.json status, the one line's content
    ("segfault", "crashed", "plant: the process crashed by signal SIGSEGV in fmi2DoStep at t=0.5 s"),
    ("abort", "crashed", "plant: the process crashed by signal SIGABRT in fmi2DoStep at t=0.5 s"),
    ("loop", "hung", "plant: hung in fmi2DoStep at t=0.5 s: exceeded plant.call_timeout = 1 s"),
    ("error", "failed", "plant: fmi2DoStep returned fmi2Error at t=0.5 s: motor model diverged"),
    ("discard", "failed", "plant: fmi2DoStep returned fmi2Discard at t=0.5 s"),
    ("fatal", "failed", "plant: fmi2DoStep returned fmi2Fatal at t=0.5 s: internal state corrupted"),
    ("nan", "failed", "plant: fmi2GetReal returned nan for current (FMU variable i) at t=0.5 s"),
]


@pytest.mark.parametrize("mode, status, line", CASES, ids=[c[0] for c in CASES])
def test_a_failing_fmu_is_one_line_exit_1_and_keeps_its_signals(tmp_path, faulty_fmu, capfd, mode, status, line):
    path = scenario(tmp_path, faulty_fmu, mode, call_timeout=1.0)
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--no-progress"]) == 1
    err = capfd.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith(f"cosim run: failed: {line}"), err

    report = json.loads((out / "report.json").read_text())
    assert report["status"] == status and line in report["error"]
    page = (out / "report.html").read_text()  # a crash or hang had no page
    assert f'id="status">{status}</span>' in page and str(escape(line)) in page
    table = read_signals(out / "signals.csv")
    t = table["time"]
    # every step up to the failure: the last row is t = 0.5 s (NaN: 0.5 s - h, the row before the bad outputs)
    assert t[-1] == pytest.approx(FAIL_TIME - (1e-4 if mode == "nan" else 0), abs=1e-9)
    assert np.allclose(np.diff(t), 1e-4) and t[0] == 0
    assert last_recorded_time(out / "signals.csv") == pytest.approx(t[-1])
    # the ideal axis: x(t_n) = pitch * h * sum of the NC's speed reference over steps 1..n (the NC runs
    # before the plant in each step), i.e. every recorded row is the FMU's, none is padding
    pitch = 0.01 / (2 * np.pi)
    w = table["nc.speed_ref"]
    expected = pitch * np.concatenate([[0.0], np.cumsum(w[1:] * 1e-4)])
    np.testing.assert_allclose(table["plant.position"], expected, rtol=0, atol=1e-11)
    assert table["plant.position"][-1] == pytest.approx(0.01, abs=1e-4)  # the rapid to 0.01 m was done
    if status in ("crashed", "hung"):
        assert report["failure"]["function"] == "fmi2DoStep" and report["failure"]["time_s"] == pytest.approx(0.5)
        assert report["recorded_until_s"] == pytest.approx(FAIL_TIME)
        log = (out / "run.log").read_text()
        assert "supervisor: " + line in log
    with sqlite3.connect(tmp_path / "history.sqlite") as db:
        assert db.execute("PRAGMA integrity_check").fetchone() == ("ok",)


def test_healthy_run_is_unchanged_by_the_supervision(tmp_path, faulty_fmu, capfd):
    """The same FMU without failure: exit 0, the whole run recorded, the summary printed by the parent (no
    figures: their drawing is not what the supervision changes; tests/cosim/test_run_cli.py's run draws them)."""
    path = scenario(tmp_path, faulty_fmu, "none")
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--no-progress", "--no-plots"]) == 0
    captured = capfd.readouterr()
    table = read_signals(out / "signals.csv")  # the summary's last sample crossed the pipe intact
    assert f"  position: {table['plant.position'][-1]:.6f} m (NC target 0.010000 m)" in captured.out, captured.out
    assert captured.err == ""
    report = json.loads((out / "report.json").read_text())
    assert report["status"] == "ok" and last_recorded_time(out / "signals.csv") == pytest.approx(0.6)


def _raise_value_error(x):
    raise ValueError(f"bad {x}")


def _return(x):
    return {"x": x, "array": np.arange(3.0)}


def test_supervise_returns_values_and_exceptions_and_whole_run_timeouts():
    ok = supervise(_return, 2)
    assert ok.status == "ok" and ok.value["x"] == 2 and ok.value["array"].tolist() == [0, 1, 2]
    err = supervise(_raise_value_error, 3)
    assert err.status == "error" and isinstance(err.error, ValueError) and str(err.error) == "bad 3"
    import time

    hung = supervise(time.sleep, 30, timeout=0.3)
    assert hung.status == "hung" and "timeout of 0.3 s" in hung.describe() and hung.function == ""


def test_history_written_before_a_crash_is_kept(tmp_path, faulty_fmu, capfd):
    """A healthy run stores its motion; a crashing run on the same history loses nothing of it."""
    good = scenario(tmp_path, faulty_fmu, "none")
    assert main(["run", str(good), "--out", str(tmp_path / "a"), "--no-progress", "--no-plots"]) == 0
    with sqlite3.connect(tmp_path / "history.sqlite") as db:
        before = db.execute("SELECT id, result FROM motions").fetchall()
    assert len(before) == 1
    bad = scenario(tmp_path, faulty_fmu, "segfault")
    assert main(["run", str(bad), "--out", str(tmp_path / "b"), "--no-progress"]) == 1
    capfd.readouterr()
    with sqlite3.connect(tmp_path / "history.sqlite") as db:
        assert db.execute("PRAGMA integrity_check").fetchone() == ("ok",)
        after = db.execute("SELECT id, result FROM motions").fetchall()
    # nothing lost, and the crashing run's own motion (it ended at 0.3 s, before the crash) was stored whole
    assert after[:1] == before and len(after) == 2 and json.loads(after[1][1])["end"] == pytest.approx(0.2999)




def _cli(argv: list[str]) -> None:
    import os

    os._exit(main(argv))


def test_two_cosim_runs_at_once_on_one_history_both_store_their_motions(tmp_path, faulty_fmu, capfd):
    import multiprocessing

    ctx = multiprocessing.get_context("fork")
    path = scenario(tmp_path, faulty_fmu, "none")
    procs = [ctx.Process(target=_cli, args=(["run", str(path), "--out", str(tmp_path / f"out{k}"), "--no-progress",
                                             "--no-plots"],)) for k in (1, 2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
    capfd.readouterr()
    assert [p.exitcode for p in procs] == [0, 0]
    with sqlite3.connect(tmp_path / "history.sqlite") as db:
        assert db.execute("PRAGMA integrity_check").fetchone() == ("ok",)
        ends = [json.loads(r)["end"] for (r,) in db.execute("SELECT result FROM motions").fetchall()]
    reports = [json.loads((tmp_path / f"out{k}" / "report.json").read_text()) for k in (1, 2)]
    assert len(ends) == 2 and ends == pytest.approx([r["motions"][0]["end"] for r in reports])


class BrokenReport(Component):
    """A user component with a bug in report(): a Python exception outside the stepping loop."""

    output_names = ("n",)
    output_units = ("1",)

    def setup(self, t0, h, n_steps):
        pass

    def step(self, n):
        pass

    def get_outputs(self):
        return [1.0]

    def report(self):
        return {}["missing"]


def test_a_bug_in_the_run_is_one_line_and_its_traceback_is_in_the_log(tmp_path, faulty_fmu, capfd):
    path = scenario(tmp_path, faulty_fmu, "none")
    text = path.read_text() + "components:\n- {name: broken, class: 'test_containment:BrokenReport'}\n"
    path.write_text(text)
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--no-progress"]) == 1
    err = capfd.readouterr().err
    assert err == f"cosim run: failed: KeyError: 'missing' (the traceback is in {out / 'run.log'})\n"
    log = (out / "run.log").read_text()
    assert "Traceback (most recent call last)" in log and "return {}[\"missing\"]" in log
