"""Wall time of the command line as a user meets it, against the simulation's own time (issue 23).

* ``cosim --version`` and ``cosim --help``: a fresh interpreter each time (best of ``--repeat``);
  target under 0.3 s (the dispatcher imports a subcommand's module only when it is chosen).
* The README's main command, ``cosim run examples/tool_change.yaml``, in a fresh temporary directory
  (its own runs/ and history): the command's wall time against the simulation with the monitor in the
  loop (report.json ``wall_time_s``: ``Master.run``, which includes the monitor's processing of each
  motion; ``processing_s`` of the motions is printed too); target ratio <= 2. The rest is start-up
  (imports, scenario and FMU check), the supervised child, report.json/report.html and the plots.
* The floor under that ratio: a bare interpreter importing the third-party modules the run imports
  (numpy, scipy's linalg, special and fft, fmpy, pydantic, casadi, jinja2, ...: read from the run's
  ``-X importtime``), against the same simulation: no change in the project's own code goes below it.

    python benchmarks/bench_cli.py [--repeat 3] [--scenario examples/tool_change.yaml] [--phases]

``--phases``: where the run's wall time goes, in a fresh interpreter running what ``cosim run`` runs (the
drawing processes forked first, then ``run_scenario``), with the time at which each phase ends and the run
process's CPU time in it: drawing processes forked, imports, scenario, the monitor made (its imports),
simulation, figures (with report.html's preparation meanwhile), report.json and report.html; and when each
drawing process warmed up and drew each figure (wall time and CPU time of the figure).

Times depend on the machine's load: compare the ratios, measured in the same run. The project's modules are
compiled first (``compileall``, as an installed package's are): with ``PYTHONDONTWRITEBYTECODE`` set and no
``__pycache__`` (a fresh clone), every run compiled them from source again (0.1-0.2 s of CPU a user does not spend).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: the project's package folders (pyproject.toml's package-dir)
PACKAGES = ("cosim", "estimator", "models", "fmu_build")


def wall(command: list[str], cwd: Path | None = None) -> tuple[float, subprocess.CompletedProcess]:
    """Seconds of wall time of ``command`` (a fresh process) and its result."""
    env = os.environ | {"OPENBLAS_NUM_THREADS": "1"}
    t0 = time.perf_counter()
    proc = subprocess.run(command, cwd=cwd, capture_output=True, text=True, env=env)
    elapsed = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(command)}: exit {proc.returncode}: {proc.stderr.strip()[-500:]}")
    return elapsed, proc


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="repetitions (best is reported)")
    parser.add_argument("--scenario", type=Path, default=ROOT / "examples" / "tool_change.yaml")
    parser.add_argument("--phases", action="store_true", help="where a run's wall time goes (module docstring)")
    args = parser.parse_args(argv)
    cosim = [sys.executable, "-m", "feeddrive.cosim"]
    wall([sys.executable, "-m", "compileall", "-q", *(str(ROOT / d) for d in PACKAGES)])
    if args.phases:
        wall([*cosim, "info", "builtin"])  # the FMU built and cached first
        print(wall([sys.executable, str(ROOT / "benchmarks" / "cli_phases.py"), str(args.scenario.resolve())])[1].stdout,
              end="")
        return 0

    for option in ("--version", "--help"):
        best = min(wall([*cosim, option])[0] for _ in range(args.repeat))
        print(f"cosim {option:9s} {best:6.3f} s   (target < 0.3 s) {'ok' if best < 0.3 else 'OVER'}")

    # the FMU is built (and cached) before the first timed run: the first hour's build is a one-off
    wall([*cosim, "info", "builtin"])
    rows = []
    for _ in range(args.repeat):
        with tempfile.TemporaryDirectory(prefix="bench_cli_") as tmp:
            elapsed, _proc = wall([*cosim, "run", str(args.scenario.resolve()), "--no-progress", "--out", "run"],
                                  cwd=Path(tmp))
            report = json.loads((Path(tmp) / "run" / "report.json").read_text())
        simulation = report["wall_time_s"]
        monitor = sum(m.get("processing_s") or 0.0 for m in report.get("motions") or [])
        rows.append((elapsed / simulation, elapsed, simulation, monitor))
    ratio, elapsed, simulation, monitor = min(rows)
    print(f"cosim run {args.scenario.name}: {elapsed:.2f} s wall; simulation with the monitor in the loop "
          f"{simulation:.2f} s (of which monitor {monitor:.2f} s); rest {elapsed - simulation:.2f} s")
    print(f"ratio wall / (simulation + monitoring) = {ratio:.2f}   (target <= 2) {'ok' if ratio <= 2 else 'OVER'}")
    floor, names = import_floor(args.scenario, args.repeat)
    print(f"floor: a bare interpreter importing the {len(names)} third-party packages the run's process imports "
          f"({', '.join(names)}) takes {floor:.2f} s; with the simulation, {(floor + simulation) / simulation:.2f} times "
          "the simulation, whatever the project's own code does")
    return 0


def import_floor(scenario: Path, repeat: int) -> tuple[float, list[str]]:
    """Seconds for a fresh interpreter to import the third-party modules ``cosim run scenario --no-plots``
    imports (best of ``repeat``), and their packages' names: the part of the run's start-up that no change
    in this project can remove while it uses them. The modules are read from ``-X importtime`` (its
    supervised child's imports too); third-party: their package is found in a site-packages folder."""
    import importlib.util

    with tempfile.TemporaryDirectory(prefix="bench_cli_") as tmp:
        _, proc = wall([sys.executable, "-X", "importtime", "-m", "feeddrive.cosim", "run", str(scenario.resolve()),
                        "--no-progress", "--no-plots", "--out", "run"], cwd=Path(tmp))
    modules = [line.rsplit("|", 1)[1].strip() for line in proc.stderr.splitlines()
               if line.startswith("import time:") and line.count("|") == 2]
    packages = []
    for name in sorted({m.split(".")[0] for m in modules} - {"feeddrive"}):
        spec = importlib.util.find_spec(name) if name.isidentifier() and not name.startswith("_") else None
        if spec is not None and "site-packages" in (spec.origin or ""):
            packages.append(name)
    wanted = [m for m in modules if m.split(".")[0] in packages]
    # a module importtime lists may not be importable by name (a missing optional one, tried and skipped)
    code = f"import importlib\nfor m in {wanted!r}:\n    try:\n        importlib.import_module(m)\n" \
           "    except ImportError:\n        pass"
    best = min(wall([sys.executable, "-c", code])[0] for _ in range(repeat))
    return best, packages


if __name__ == "__main__":
    sys.exit(main())
