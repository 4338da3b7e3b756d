"""``cosim run SCENARIO.yaml [--out DIR] [--overwrite] [--no-progress]``: one co-simulation run.

Writes signals.csv, scenario.resolved.yaml, report.json and plots/ into the output directory
(default ``runs/<name>-<YYYYmmdd-HHMMSS>``) and prints a short summary.
Exit status: 0 success, 2 bad input, 1 simulation failure (see cosim/cli.py), including an FMU that
crashes or hangs: the run is a supervised child process (cosim/supervise.py).
"""
from __future__ import annotations

import argparse
import datetime as _dt
import logging
import sys
from pathlib import Path

from feeddrive.cosim.run import DEFAULT_HISTORY
from feeddrive.cosim.scenario import load_scenario
from feeddrive.cosim.supervise import run_supervised


class _ReportedElsewhere(logging.Filter):
    """FMU error messages end up in the one-line failure message: do not print them twice."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not (record.name.startswith("cosim.fmu.") and record.levelno >= logging.ERROR)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", type=Path, help="scenario YAML file")
    parser.add_argument("--out", type=Path, default=None,
                        help="output directory (default: runs/<name>-<YYYYmmdd-HHMMSS>)")
    parser.add_argument("--overwrite", action="store_true", help="replace the files of a non-empty output directory")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def main(args: argparse.Namespace) -> int:
    handler = logging.StreamHandler(sys.stderr)
    handler.addFilter(_ReportedElsewhere())
    handler.setFormatter(logging.Formatter("cosim run: %(name)s: %(levelname)s: %(message)s"))
    logging.basicConfig(level=logging.WARNING, handlers=[handler])
    scenario = load_scenario(args.scenario)
    for note in scenario.unit_notes:  # a unit taken on trust is said, once
        print(f"plant.map: {note}")
    out = args.out or _fresh_run_dir(Path("runs") / f"{scenario.name}-{_dt.datetime.now():%Y%m%d-%H%M%S}")
    # in a supervised child process: an FMU that crashes or hangs is reported in one line (exit 1)
    result = run_supervised(scenario, out, progress=not args.no_progress, overwrite=args.overwrite,
                            default_history=Path(out).parent / DEFAULT_HISTORY)
    print(summary(result))
    return 0


def summary(result) -> str:  # noqa: ANN001 - cosim.run.RunResult
    """A few lines: simulated time and speed, final position against the NC's target, motions, files."""
    from feeddrive.cosim.report.verdict import verdict_line

    r, s = result.report, result.signals
    lines = [f"{r['scenario']}: {r['stop_time_s']:.4g} s simulated in {r['wall_time_s']:.3g} s "
             f"({r['steps']} steps of {r['step_s']:.3g} s) -> {result.out_dir}"]
    if "plant.position" in s and "nc.x_ref" in s:
        lines.append(f"  position: {s['plant.position'][-1]:.6f} m (NC target {s['nc.x_ref'][-1]:.6f} m)")
    for k, m in enumerate(r.get("motions") or [], 1):
        if isinstance(m, dict):
            params = m.get("parameters") or {}
            text = " ".join(f"{p}={v['value']:.4g}" for p, v in params.items() if isinstance(v, dict) and "value" in v)
            lines.append(f"  motion {k}: {verdict_line(m)}")  # the verdict first (cosim/report/verdict.py)
            lines.append(f"    {'validated' if m.get('validated') else 'not validated'} {text}".rstrip())
            for f in m.get("sensor_faults") or []:
                lines.append(f"    sensor fault: {f['sensor']} {f['kind']} (gain {f['gain']:.4g}, offset {f['offset']:.4g})")
            if isinstance(m.get("mismatch"), dict) and not m["mismatch"].get("passed", True):
                lines.append(f"    model mismatch ({m['mismatch']['test']} test): parameters not validated")
            for d in m.get("diagnosis") or []:
                lines.append(f"    diagnosis: {d['fault']} ({', '.join(d['parameters'])})")
            if m.get("error"):
                lines.append(f"    {m['error']}")
    lines.append(f"  files: signals.csv, scenario.resolved.yaml, report.json, report.html, {len(result.paths['plots'])} plots")
    return "\n".join(lines)


def _fresh_run_dir(base: Path) -> Path:
    """``base``, or ``base-2``, ``base-3``, ... when runs started in the same second."""
    candidate, k = base, 1
    while candidate.exists():
        k += 1
        candidate = base.with_name(f"{base.name}-{k}")
    return candidate
