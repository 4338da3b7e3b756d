"""Issue 23's rough edges, each as a new user met it on main, and what they get now."""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from feeddrive.cosim.cli import build_parser, main
from feeddrive.cosim.recorded import load_recording

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from linear_axis import linear_axis, write_csv  # noqa: E402


def test_build_fmu_takes_overwrite_and_hides_force():
    parser, _ = build_parser(["build-fmu"])
    help_text = parser._subparsers._group_actions[0].choices["build-fmu"].format_help()
    assert "--overwrite" in help_text and "--force" not in help_text
    for flag in ("--overwrite", "--force"):  # --force: the old name, still accepted
        assert parser.parse_args(["build-fmu", flag]).overwrite is True
    assert parser.parse_args(["build-fmu"]).overwrite is False


def test_delimiter_and_decimal_choices_are_named(tmp_path):
    """The help read ``{,,;,tab}`` and ``{.,,}``; the names (and the characters) are accepted."""
    parser, _ = build_parser(["estimate"])
    help_text = " ".join(parser._subparsers._group_actions[0].choices["estimate"].format_help().split())
    assert "--delimiter {comma,semicolon,tab}" in help_text and "--decimal {point,comma}" in help_text
    assert "{,,;,tab}" not in help_text and "{.,,}" not in help_text
    args = parser.parse_args(["estimate", "x.csv", "--delimiter", "semicolon", "--decimal", "comma"])
    assert (args.delimiter, args.decimal) == (";", ",")
    assert parser.parse_args(["estimate", "x.csv", "--delimiter", ";", "--decimal", "."]).decimal == "."
    assert parser.parse_args(["estimate", "x.csv", "--delimiter", "tab"]).delimiter == "tab"
    # read back exactly: 1.5 written as "1,5" in a semicolon file
    path = tmp_path / "d.csv"
    path.write_text("t [s];u [V]\n" + "".join(f"{k * 0.001:.3f};{1.5 + k}\n".replace(".", ",") for k in range(30)))
    rec = load_recording(path, {"time": "t", "voltage": "u"}, None, args.delimiter, args.decimal)
    assert rec.signals["voltage"][:3].tolist() == [1.5, 2.5, 3.5] and rec.h == pytest.approx(0.001)


def test_bad_delimiter_name_is_one_argparse_line(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["estimate", "x.csv", "--delimiter", "pipe"])
    assert exc.value.code == 2
    assert "'pipe': expected one of comma, semicolon, tab" in capsys.readouterr().err


def test_campaign_on_a_scenario_file_says_what_it_is(capsys):
    """On main: "base: Field required (and 6 more)"."""
    assert main(["campaign", str(EXAMPLES / "tool_change.yaml"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "this is a scenario, not a campaign file: a campaign needs base:" in err
    assert "examples/campaign_wear.yaml" in err and f"cosim run {EXAMPLES / 'tool_change.yaml'}" in err


def test_a_tab_in_yaml_is_named(tmp_path, capsys):
    """On main: "invalid YAML: found character that cannot start any token"."""
    path = tmp_path / "tab.yaml"
    path.write_text("name: t\nplant:\n  fmu: builtin\nnc:\n  program:\n\t- rapid: {to: 0.02}\n")
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err == (f"cosim run: error: {path}:6: a tab character (column 1): YAML indents with "
                                       "spaces; replace the tab by spaces\n")


def test_linear_axis_help_writes_no_file(tmp_path):
    """On main, ``python tests/cosim/linear_axis.py --help`` wrote a recording called ``--help``."""
    proc = subprocess.run([sys.executable, str(HERE / "linear_axis.py"), "--help"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and proc.stdout.startswith("usage:") and list(tmp_path.iterdir()) == []
    proc = subprocess.run([sys.executable, str(HERE / "linear_axis.py"), "rec.csv"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0
    lines = (tmp_path / "rec.csv").read_text().splitlines()
    assert lines[0] == "t [s],x [m],F [N]" and len(lines) == 25_001  # 25 s at 1 kHz
    again = subprocess.run([sys.executable, str(HERE / "linear_axis.py"), "rec.csv"], cwd=tmp_path,
                           capture_output=True, text=True, timeout=60)
    assert again.returncode == 2 and "exists; use --overwrite" in again.stderr


def test_position_only_recording_says_which_roles_are_needed(tmp_path, capsys):
    """On main: "no model equation can be used with the signals ['position']", and nothing to do about it."""
    path = write_csv(tmp_path / "rec.csv", linear_axis())
    assert main(["estimate", str(path), "--map", "time=t", "position=x", "--segment", "none"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    for part in ("['position']", "electrical equation (u = L di/dt + R i + K w) needs voltage, current and speed",
                 "needs current or torque, and speed", "speed is derived from the position",
                 "torque=COLUMN"):
        assert part in err


def test_info_builtin_shows_descriptions(feeddrive_fmu, capsys):
    assert main(["info", str(feeddrive_fmu)]) == 0
    rows = {line.split()[0]: line for line in capsys.readouterr().out.splitlines()[2:]}
    assert rows["name"].split()[-1] == "description"
    assert rows["R"].rstrip().endswith("armature resistance") and "motor speed" in rows["w"]


def test_info_warns_on_an_fmu_without_a_binary_here(feeddrive_fmu, tmp_path, capsys):
    """On main ``cosim info`` printed the variables and exited 0 without a word; ``cosim run`` refuses it."""
    import fmpy

    other = tmp_path / "win_only.fmu"
    with zipfile.ZipFile(feeddrive_fmu) as src, zipfile.ZipFile(other, "w") as dst:
        for item in src.infolist():
            name = item.filename
            if name.startswith(f"binaries/{fmpy.platform}/"):
                name = name.replace(f"binaries/{fmpy.platform}/", "binaries/win64/").replace(
                    fmpy.sharedLibraryExtension, ".dll")
            dst.writestr(name, src.read(item))
    assert main(["info", str(other)]) == 0
    out, err = capsys.readouterr()
    assert "armature resistance" in out  # the variables are shown, to write a map
    assert err.startswith(f"cosim info: warning: {other}: no binary for this platform: expected binaries/"
                          f"{fmpy.platform}/FeedDrive") and "(it has binaries for win64)" in err
    assert "cosim run refuses it" in err
    scenario = tmp_path / "s.yaml"
    scenario.write_text(f"name: s\nplant: {{fmu: {other}}}\nnc:\n  program:\n    - rapid: {{to: 0.02}}\n")
    assert main(["run", str(scenario), "--out", str(tmp_path / "out")]) == 2
    assert "no binary for this platform" in capsys.readouterr().err


@pytest.mark.slow
def test_drift_script_runs_from_another_directory(tmp_path, monkeypatch, capsys):
    """On main, ``python examples/drift_500/drift.py`` from the repository root ended in a traceback: its
    relative history path was read against examples/drift_500/, where the folder did not exist."""
    spec = importlib.util.spec_from_file_location("drift_example", EXAMPLES / "drift_500" / "drift.py")
    drift = importlib.util.module_from_spec(spec)
    sys.modules["drift_example"] = drift
    spec.loader.exec_module(drift)
    monkeypatch.chdir(tmp_path)
    assert drift.main(["--motions", "1", "--out", "runs/drift"]) == 0
    assert capsys.readouterr().out.startswith("1 motions (1 validated; 1 simulated now")
    assert (tmp_path / "runs" / "drift" / "history.db").is_file()
    assert not (EXAMPLES / "drift_500" / "runs").exists()


def test_a_campaign_in_this_process_leaves_the_environment_as_it_was(tmp_path, monkeypatch):
    """``cosim campaign`` tells its runs to draw in turn through FEEDDRIVE_PLOT_PROCESSES=1; run in-process it
    left that set, and a later ``cosim run`` in the same process drew its figures on one process only."""
    monkeypatch.delenv("FEEDDRIVE_PLOT_PROCESSES", raising=False)
    campaign = tmp_path / "c.yaml"
    campaign.write_text("name: tiny\nrepetitions: 1\nbase:\n  name: tiny\n  step: 1.0e-4\n  plant: {fmu: builtin}\n"
                        "  nc:\n    program:\n      - rapid: {to: 0.02}\n  monitor: {db: ':memory:'}\n")
    assert main(["campaign", str(campaign), "--no-plots", "--no-progress", "--out", str(tmp_path / "out")]) == 0
    assert "FEEDDRIVE_PLOT_PROCESSES" not in os.environ
    monkeypatch.setenv("FEEDDRIVE_PLOT_PROCESSES", "3")  # a value the user set is the user's
    assert main(["campaign", str(campaign), "--no-plots", "--no-progress", "--out", str(tmp_path / "out2")]) == 0
    assert os.environ["FEEDDRIVE_PLOT_PROCESSES"] == "3"


@pytest.mark.slow
def test_a_campaign_with_workers_leaks_no_semaphore(tmp_path):
    """On main a campaign ended with "resource_tracker: There appear to be N leaked semaphore objects"."""
    campaign = tmp_path / "c.yaml"
    campaign.write_text("name: tiny\nrepetitions: 2\nbase:\n  name: tiny\n  step: 1.0e-4\n  plant: {fmu: builtin}\n"
                        "  nc:\n    program:\n      - rapid: {to: 0.02}\n  monitor: {db: ':memory:'}\n")
    proc = subprocess.run([sys.executable, "-m", "feeddrive.cosim", "campaign", str(campaign), "--workers", "2",
                           "--no-plots", "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "tiny: 2 runs (2 run now, 0 failed)" in proc.stdout
    assert "leaked" not in proc.stderr and "resource_tracker" not in proc.stderr
