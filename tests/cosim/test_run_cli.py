"""``cosim run`` and ``cosim info`` end to end: files, physics of the example, exit codes, one-line errors."""
from __future__ import annotations

import gc
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from feeddrive.cosim.cli import main
from feeddrive.cosim.scenario import load_scenario

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

SHORT = """\
name: short
plant: {{fmu: builtin}}
nc:
  program:
    - rapid: {{to: 0.02}}
{extra}"""


def read_csv(path: Path) -> dict[str, np.ndarray]:
    header = path.read_text().split("\n", 1)[0].split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {name: data[:, k] for k, name in enumerate(header)}


@pytest.mark.slow
def test_tool_change_example_runs_end_to_end(example_runs):
    """The session's ``cosim run examples/tool_change.yaml`` (tests/conftest.py example_runs), read only."""
    out = example_runs["out"]["tool_change"]
    summary = example_runs["stdout"]["tool_change"]
    assert summary.startswith("tool-change: ") and "position:" in summary
    s = read_csv(out / "signals.csv")
    t, x, w, state = s["time [s]"], s["plant.position [m]"], s["plant.speed [rad/s]"], s["nc.state [1]"]
    np.testing.assert_allclose(np.diff(t), 1e-4, rtol=1e-6)
    # out to the tool-change position and back: the speed reverses at about the paper's 70 rad/s
    assert abs(x.max() - 0.27) < 1e-4 and abs(x[-1] - s["nc.x_ref [m]"][-1]) < 1e-5
    assert 65 < w.max() < 75 and -75 < w.min() < -65
    assert (state == 1).sum() * 1e-4 == pytest.approx(3.49, abs=0.01)  # one ~3.5 s high-speed motion
    assert abs(s["plant.voltage [V]"]).max() < 100 and abs(s["plant.current [A]"]).max() < 30
    report = json.loads((out / "report.json").read_text())
    assert report["status"] == "ok" and report["steps"] == len(t) - 1
    assert report["plant"]["sha256"] and set(report["components"]) == {"nc", "plant", "sensors", "monitor"}
    assert len(report["motions"]) == 1 and report["motions"][0]["validated"] is True  # healthy axis
    assert {"motion_1_currents.png", "motion_1_profiles.png"} <= {p.name for p in (out / "plots").iterdir()}
    assert sorted(report["files"]["plots"]) == sorted(f"plots/{p.name}" for p in (out / "plots").iterdir())
    resolved = yaml.safe_load((out / "scenario.resolved.yaml").read_text())
    assert Path(resolved["plant"]["fmu"]).is_absolute() and resolved["stop_time"] == pytest.approx(t[-1])
    assert resolved["connections"]["nc.position"] == "plant.position"
    assert load_scenario(out / "scenario.resolved.yaml").to_dict() == resolved  # reproducible as written
    # written by libyaml's emitter (cosim/run.py _SAFE_DUMPER): the pure-Python safe dumper's text, byte for byte
    assert (out / "scenario.resolved.yaml").read_text() == yaml.safe_dump(resolved, sort_keys=False)


def test_output_directory_is_never_overwritten_without_the_flag(tmp_path, feeddrive_fmu, capsys):
    path = tmp_path / "short.yaml"
    path.write_text(SHORT.format(extra="stop_time: 0.05\n"))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--no-progress"]) == 0
    assert gc.isenabled()  # paused for the imports and the scenario's load only
    before = (out / "signals.csv").read_text()
    capsys.readouterr()
    assert main(["run", str(path), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "is not empty" in err and "--overwrite" in err
    assert (out / "signals.csv").read_text() == before
    assert len(list((out / "plots").glob("*.png"))) == 2  # the motion's profiles and currents
    assert main(["run", str(path), "--out", str(out), "--no-progress", "--overwrite", "--no-plots"]) == 0
    assert (out / "signals.csv").read_text() == before  # deterministic rerun
    assert not list((out / "plots").glob("*.png"))  # no figure of the replaced run is left as if it were this one's


def test_db_memory_is_no_file(tmp_path, monkeypatch):
    # --db :memory: was resolved as a path: a file ./:memory: that the next --db :memory: run continued
    from feeddrive.cosim.cli.run import history_db, history_line
    from feeddrive.cosim.run import with_history

    monkeypatch.chdir(tmp_path)
    (tmp_path / "short.yaml").write_text(SHORT.format(extra="monitor: {}\n"))
    scenario = with_history(load_scenario(tmp_path / "short.yaml"), history_db(Path(":memory:")), replace=True)
    assert scenario.monitor.config.db == ":memory:"
    assert history_line({"axis": "X", "db": scenario.monitor.config.db}) == \
        "  history: in memory (nothing kept after the run), axis X"
    assert history_db(Path("h.sqlite")) == tmp_path / "h.sqlite"


def test_fmu_error_mid_run_exits_1_with_one_line_and_partial_signals(tmp_path, feeddrive_fmu, capsys):
    path = tmp_path / "broken.yaml"
    # an L in its declared range that overflows the current (R = 0 is refused when the scenario is read)
    path.write_text(SHORT.format(extra="events:\n  - {time: 0.05, target: plant.L, value: 1.0e-300}\n"))
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--no-progress"]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0, err
    assert err.startswith("cosim run: failed: plant: fmi2DoStep returned fmi2Error at t=0.05 s: ")
    s = read_csv(out / "signals.csv")
    assert s["time [s]"][-1] == pytest.approx(0.05) and np.abs(s["plant.speed [rad/s]"]).max() > 0
    report = json.loads((out / "report.json").read_text())
    assert report["status"] == "failed" and "fmi2Error" in report["error"]
    assert report["recorded_until_s"] == pytest.approx(0.05)


def test_bad_scenario_exits_2_with_one_line(tmp_path, capsys):
    path = tmp_path / "bad.yaml"
    path.write_text("name: bad\nstep: -1\nnc: {program: []}\n")
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"cosim run: error: {path}:2: step: Input should be greater than 0, got -1"
    assert not (tmp_path / "out").exists()


def test_info_lists_variables_and_checks_a_map(tmp_path, feeddrive_fmu, capsys):
    assert main(["info", "builtin"]) == 0
    lines = capsys.readouterr().out.splitlines()
    row = next(ln.split() for ln in lines if ln.split()[:1] == ["Cd"])
    assert row[:6] == ["Cd", "Real", "parameter", "tunable", "N.m", "1.2"]
    assert " ".join(row[6:]) == "total dry (Coulomb) friction torque"  # the description column
    assert main(["info", "builtin", "--map", str(EXAMPLES / "tool_change.yaml")]) == 0
    out = capsys.readouterr().out
    assert "map OK" in out and "note:" not in out  # the scenario's own plant
    assert main(["info", str(feeddrive_fmu), "--map", str(EXAMPLES / "vendor_fmu.yaml")]) == 2
    out, err = capsys.readouterr()
    # the map is checked against the FMU given; that it is not the scenario's plant is said (audit3)
    assert f"  note: {EXAMPLES / 'vendor_fmu.yaml'}'s plant is vendor_fmu/VendorDrive.fmu, not FeedDrive.fmu" in out
    err = err.strip()
    assert err.startswith(f"cosim info: error: {EXAMPLES / 'vendor_fmu.yaml'}:") and err.count("\n") == 0
    assert "plant.map.speed_ref.var: FMU 'FeedDrive.fmu' has no variable 'n_cmd'" in err
    assert main(["info", str(tmp_path / "none.fmu")]) == 2


@pytest.mark.slow
def test_summary_names_the_sensor_fault(example_runs):
    """examples/current_sensor_fault.yaml: Im1 gain 1.03 and offset 0.2 A from the 2nd tool change (the session's
    ``cosim run`` of the example, tests/conftest.py)."""
    lines = example_runs["stdout"]["current_sensor_fault"].splitlines()
    faults = [ln.strip() for ln in lines if ln.strip().startswith("sensor fault:")]
    assert len(faults) == 1 and faults[0] == "sensor fault: Im1 gain+offset (gain 1.03, offset 0.2 A)"
    # the motion's first line is its verdict, which names the fault
    assert any(ln.startswith("  motion 2: sensor fault: Im1 gain 1.03, offset 0.2 A") for ln in lines)
    assert lines.index(next(ln for ln in lines if ln.startswith("  motion 2:"))) < lines.index(
        next(ln for ln in lines if ln.strip().startswith("sensor fault:")))


def test_a_diverged_position_is_printed_in_significant_digits():
    """The summary's position line: micrometres as before; a plant that ran away (audit3: a Feedthrough FMU mapped
    onto the roles) printed '-82884587084383809020731850752.000000 m'."""
    from feeddrive.cosim.cli.run import _metres

    assert _metres(0.27) == "0.270000" and _metres(-1e-6) == "-0.000001"
    assert _metres(-8.2884587084383809e28) == "-8.288e+28"


def test_a_monitored_run_without_a_motion_says_nothing_was_judged(tmp_path, feeddrive_fmu, capsys):
    """A monitored axis that never moved (a dwell only): the summary said nothing of motions at all."""
    path = tmp_path / "still.yaml"
    path.write_text("name: still\nstep: 1.0e-4\nplant: {fmu: builtin}\nnc:\n  program:\n    - dwell: {time: 0.3}\n"
                    "monitor: {}\n")
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--no-progress", "--no-plots",
                 "--db", ":memory:"]) == 0
    out = capsys.readouterr().out
    assert "  monitor: nothing judged: no high-speed motion (NC state 1) in this run\n" in out
    assert out.rstrip().endswith("report.html, 0 plots")
