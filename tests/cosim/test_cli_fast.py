"""``cosim --help`` and ``cosim --version`` import nothing heavy: the dispatcher imports a subcommand's
module only when it is chosen (issue 23: ``--version`` took 2.3 to 3.9 s, importing scipy.signal and the
whole run stack). No timing is asserted (the machine is shared); ``benchmarks/bench_cli.py`` measures it."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from feeddrive.cosim.cli import COMMANDS, build_parser, chosen_command

#: what a bare --help or --version must not import (any of these costs 0.1 to 2 s)
HEAVY = ("numpy", "scipy", "matplotlib", "casadi", "fmpy", "pydantic", "yaml", "statsmodels", "pint", "dask",
         "distributed", "jinja2", "tqdm", "pandas", "feeddrive.estimator", "feeddrive.cosim.run",
         "feeddrive.cosim.scenario", "feeddrive.fmu_build", "feeddrive.models")


def imported_modules(*args: str) -> tuple[list[str], str]:
    """The modules ``python -X importtime -m feeddrive.cosim ARGS`` imports, and its stdout."""
    proc = subprocess.run([sys.executable, "-X", "importtime", "-m", "feeddrive.cosim", *args],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    names = [line.rsplit("|", 1)[1].strip() for line in proc.stderr.splitlines()
             if line.startswith("import time:") and line.count("|") == 2]
    assert "feeddrive.cosim" in names  # the parse found the import lines
    return names, proc.stdout


def loaded_modules(tmp_path, *args: str) -> list[str]:
    """Every module in ``sys.modules`` after ``cosim ARGS`` in a fresh interpreter (importtime does not
    list what ``importlib.import_module`` loads, sys.modules does)."""
    out = tmp_path / "modules.json"
    code = ("import json, sys\nfrom feeddrive.cosim.cli import main\ntry:\n    main(sys.argv[2:])\n"
            "except SystemExit:\n    pass\nopen(sys.argv[1], 'w').write(json.dumps(sorted(sys.modules)))\n")
    proc = subprocess.run([sys.executable, "-c", code, str(out), *args], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(out.read_text())


@pytest.mark.parametrize("option", ["--version", "--help"])
def test_version_and_help_import_nothing_heavy(option):
    names, out = imported_modules(option)
    heavy = sorted({n for n in names for h in HEAVY if n == h or n.startswith(h + ".")})
    assert heavy == []
    assert not [n for n in names if n.startswith("feeddrive.cosim.cli.")]  # no subcommand module either
    if option == "--version":
        assert out.startswith("cosim ")
    else:
        assert "run" in out and "history" in out


def test_a_subcommand_help_imports_only_its_module(tmp_path):
    names, out = imported_modules("history", "--help")
    assert "--db" in out and not [n for n in names if n in ("numpy", "scipy", "matplotlib", "fmpy", "casadi")]
    loaded = loaded_modules(tmp_path, "history", "--help")
    assert [n for n in loaded if n.startswith("feeddrive.cosim.cli.")] == ["feeddrive.cosim.cli.history"]
    for top in ("--version", "--help"):  # no subcommand module, nothing heavy
        assert not [n for n in loaded_modules(tmp_path, top) if n.startswith(("feeddrive.cosim.cli.", "numpy"))]


def test_the_chosen_command_is_the_first_word_not_an_option():
    assert chosen_command(["--version"]) is None
    assert chosen_command(["run", "x.yaml", "--out", "y"]) == "run"
    parser, modules = build_parser(["history", "--axis", "X"])
    assert list(modules) == ["history"]
    assert parser.parse_args(["history", "--axis", "X"]).axis == "X"
    _, every = build_parser(None)  # every subcommand still loads and registers its options
    assert sorted(every) == sorted(COMMANDS)


def test_top_level_help_is_for_users(capsys):
    """The help names the three jobs with runnable examples, not the dispatcher's docstring."""
    parser, _ = build_parser([])
    text = parser.format_help()
    assert "dispatcher" not in text and "``" not in text
    for job in ("co-simulate a feed drive", "your own plant", "recorded data"):
        assert job in text
    for example in ("cosim run examples/tool_change.yaml", "cosim info vendor.fmu --map examples/vendor_fmu.yaml",
                    "cosim monitor rec.csv", "cosim history --axis X"):
        assert example in text


def test_progress_only_on_a_terminal_and_not_under_ci(monkeypatch):
    """Progress bars (FMU build, run, design, campaigns) go to a terminal only: never into a pipe, a log
    or a CI job's output."""
    from feeddrive.cosim.progress import enabled

    class Terminal:
        def __init__(self, tty: bool) -> None:
            self.tty = tty

        def isatty(self) -> bool:
            return self.tty

    monkeypatch.delenv("CI", raising=False)
    monkeypatch.setattr(sys, "stderr", Terminal(True))
    assert enabled() and not enabled(False)
    monkeypatch.setenv("CI", "true")
    assert not enabled()
    monkeypatch.delenv("CI")
    monkeypatch.setattr(sys, "stderr", Terminal(False))
    assert not enabled()
