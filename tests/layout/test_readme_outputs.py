"""The README's shown outputs are what the commands print (issue 23: its figures had drifted).

Every fenced block of README.md whose first line starts with ``$ `` is a session: each ``$ COMMAND`` line
is run (in a fresh directory holding a copy of examples/ and the test data generator: ``cosim ...`` by the
console script's ``main`` in this process, other commands in a shell), and for
a ``$ cosim ...`` command the lines after it, up to the next ``$`` line or the block's end, must equal
what it prints (other commands prepare its input: their exit status is checked), line by line,
with numbers within a tolerance, wall times (``simulated in X s``) free, and the time stamp of a run
directory (``runs/<name>-<YYYYmmdd-HHMMSS>`` or ``runs/<name>-...``) free.
"""
from __future__ import annotations

import math
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from feeddrive.cosim.cli import main

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
#: relative tolerance of a shown number, and the absolute one for numbers near zero
REL, ABS = 0.02, 2e-5
NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
RUN_DIR = re.compile(r"runs/([\w.-]+?)-(?:\d{8}-\d{6}(?:-\d+)?|\.\.\.)")
WALL = re.compile(r"simulated in \S+ s")


def sessions(text: str) -> list[tuple[int, list[tuple[str, list[str]]]]]:
    """``[(line number, [(command, expected lines), ...]), ...]`` of the README's ``$`` blocks."""
    out = []
    lines = text.splitlines()
    k = 0
    while k < len(lines):
        if lines[k].startswith("```") and k + 1 < len(lines) and lines[k + 1].startswith("$ "):
            start, k = k + 2, k + 1
            steps: list[tuple[str, list[str]]] = []
            while not lines[k].startswith("```"):
                if lines[k].startswith("$ "):
                    steps.append((lines[k][2:], []))
                else:
                    steps[-1][1].append(lines[k])
                k += 1
            out.append((start, steps))
        k += 1
    return out


def normalise(line: str) -> str:
    """Run-directory stamps and wall times masked, runs of spaces (column alignment) as one."""
    return " ".join(WALL.sub("simulated in <wall> s", RUN_DIR.sub(r"runs/\1-<time>", line)).split())


def same_line(expected: str, actual: str) -> bool:
    """Equal text around the numbers, and each number within REL (or ABS near zero); a shown line that ends in
    ``(...)`` is the start of the printed one (as many words)."""
    e, a = normalise(expected), normalise(actual)
    if e.endswith("(...)"):
        e = e[:-5].rstrip()
        a = " ".join(a.split()[:len(e.split())])
    if NUMBER.sub("#", e) != NUMBER.sub("#", a):
        return False
    for x, y in zip(NUMBER.findall(e), NUMBER.findall(a)):
        if not math.isclose(float(x), float(y), rel_tol=REL, abs_tol=ABS):
            return False
    return True


def test_the_parser_and_the_comparison():
    text = "x\n```\n$ cosim a\nfoo 1.00 s\n$ cosim b\n```\n```\nnot a session\n```\n"
    assert sessions(text) == [(3, [("cosim a", ["foo 1.00 s"]), ("cosim b", [])])]
    assert same_line("R=0.6 L=0.003998 in runs/tool-change-20261123-013811",
                     "R=0.6001 L=0.004001 in runs/tool-change-20261124-172502-2")
    assert same_line("-> runs/vendor-axis-10mm-...", "-> runs/vendor-axis-10mm-20261124-172502")
    assert same_line("3.988 s simulated in 1.65 s (39879 steps)", "3.988 s simulated in 12.4 s (39879 steps)")
    assert not same_line("Cd=1.201", "Cd=1.25")  # 4 % off
    assert not same_line("motion 1: validated", "motion 1: not validated")
    assert same_line("position: 0.000001 m", "position: 0.000000 m")
    assert same_line("  ft        199.82 N.s/m", "  ft       199.841 N.s/m")  # columns as wide as the digits
    assert same_line("adequate (p = 0.257): no mismatch found (...)", "adequate (p = 0.2571): no mismatch found (p = 1)")
    assert not same_line("adequate (p = 0.257): no mismatch (...)", "adequate (p = 0.2571): a mismatch (p = 1)")


STEPS = sessions(README.read_text(encoding="utf-8"))


#: a session that is only ``cosim run examples/<name>.yaml`` in a fresh directory
EXAMPLE_RUN = re.compile(r"cosim run examples/(\w+)\.yaml")
#: the README's examples among those the test session runs once (tests/conftest.py EXAMPLE_RUNS, example_runs)
SESSION_EXAMPLES = ("tool_change", "worn_axis")


def test_the_session_of_an_example_run_is_recognised():
    assert [_example_run(steps) for _, steps in STEPS[:2]] == ["tool_change", "worn_axis"]
    assert _example_run([("cosim run examples/tool_change.yaml --db x", [])]) is None
    assert _example_run([("cosim run examples/tool_change.yaml", []), ("cosim history", [])]) is None
    assert _example_run([("cosim run examples/pmsm_axis.yaml", [])]) is None  # not one of the session's runs


def _example_run(steps: list[tuple[str, list[str]]]) -> str | None:
    """The example's name if the session is only ``cosim run examples/<name>.yaml`` of one of the examples the
    test session runs (``SESSION_EXAMPLES``), else None."""
    match = EXAMPLE_RUN.fullmatch(steps[0][0]) if len(steps) == 1 else None
    return match[1] if match and match[1] in SESSION_EXAMPLES else None


#: the example runs last: by then another worker may have made the session's runs of the examples
ORDERED = sorted(STEPS, key=lambda session: _example_run(session[1]) is not None)


@pytest.mark.slow
@pytest.mark.parametrize(("line", "steps"), ORDERED, ids=[f"README line {n}" for n, _ in ORDERED])
def test_readme_session_prints_what_it_shows(line, steps, tmp_path, feeddrive_fmu, request, monkeypatch, capsys):
    """Each session run as the README shows it; a session that is a single ``cosim run`` of an example the
    test session already ran in a fresh directory as a user does (tests/conftest.py example_runs: the same
    command in-process, its axis alone on its history) is compared with what that run printed, not run again
    (two runs with their figures less). In the other sessions a ``cosim ...`` line is the console script's
    ``main`` called in this process (the same code; a new interpreter and its imports cost ~1.5 s of CPU
    each), with the user's drawing processes, in the session's folder with ``CI`` set; the other lines
    (``python ...``, ``head``) run in a shell. The console script itself is run by tests/layout/test_layout.py
    and tests/cosim/test_cli_fast.py."""
    name = _example_run(steps)
    if name is not None:
        ((command, expected),) = steps
        assert_printed(line, command, expected, request.getfixturevalue("example_runs")["stdout"][name].splitlines())
        return
    # the session's folder, with ../shared beside it the project's (the real recordings), where that is present
    shared = ROOT.parent / "shared"
    if any("../shared" in command for command, _ in steps):
        if not (shared / "realdata").is_dir():
            pytest.skip(f"README line {line}: reads ../shared/realdata, absent here ({shared})")
        (tmp_path / "shared").symlink_to(shared)
    tmp_path = tmp_path / "work"
    shutil.copytree(ROOT / "examples", tmp_path / "examples", ignore=shutil.ignore_patterns("*.fmu", "runs"))
    (tmp_path / "tests" / "cosim").mkdir(parents=True)
    shutil.copy(ROOT / "tests" / "cosim" / "linear_axis.py", tmp_path / "tests" / "cosim")
    env = os.environ | {"PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
                        "OPENBLAS_NUM_THREADS": "1", "CI": "1"}
    monkeypatch.setenv("CI", "1")
    monkeypatch.delenv("FEEDDRIVE_PLOT_PROCESSES", raising=False)  # drawn as a user's run draws (conftest sets 1)
    env.pop("FEEDDRIVE_PLOT_PROCESSES", None)
    monkeypatch.chdir(tmp_path)
    for command, expected in steps:
        if command.startswith("cosim "):
            capsys.readouterr()
            status = main(shlex.split(command)[1:])
            out, err = capsys.readouterr()
            assert status == 0, f"README line {line}: {command}: exit {status}\n{err[-2000:]}"
            assert_printed(line, command, expected, out.splitlines())
            continue
        proc = subprocess.run(command, shell=True, cwd=tmp_path, capture_output=True, text=True, env=env, timeout=900)
        assert proc.returncode == 0, f"README line {line}: {command}: exit {proc.returncode}\n{proc.stderr[-2000:]}"


def assert_printed(line: int, command: str, expected: list[str], actual: list[str]) -> None:
    """What ``command`` printed is what the README shows at ``line``, line by line (:func:`same_line`)."""
    mismatch = [(e, a) for e, a in zip(expected, actual) if not same_line(e, a)]
    assert not mismatch and len(actual) == len(expected), (
        f"README line {line}: `{command}` printed\n" + "\n".join(actual) + "\n\nthe README shows\n"
        + "\n".join(expected))
