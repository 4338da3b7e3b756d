"""``cosim run SCENARIO.yaml [--out DIR] [--db PATH] [--overwrite] [--no-progress] [--no-plots]``: one
co-simulation run.

Writes signals.csv, scenario.resolved.yaml, report.json and plots/ into the output directory
(default ``runs/<name>-<YYYYmmdd-HHMMSS>``) and prints a short summary, with the monitor's history
file and axis and the state of its healthy baseline. ``--no-plots`` draws no plots/*.png (report.html then
has no figures; the numbers, the verdicts and the history are the same): the drawing is much of a short run's CPU.

The history does not depend on ``--out``: ``--db``, else the scenario's ``monitor.db``, else
``runs/history.sqlite`` in the current directory (``DEFAULT_DB``, which ``cosim history`` and
``cosim monitor`` read too). Its key is the scenario's axis.
Exit status: 0 success, 2 bad input, 1 simulation failure (see cosim/cli.py), including an FMU that
crashes or hangs: the run is a supervised child process (cosim/supervise.py).
"""
from __future__ import annotations

import argparse
import datetime as _dt
import gc
import logging
import os
import sys
from pathlib import Path

from feeddrive.cosim.cli.history import DEFAULT_DB
from feeddrive.cosim.errors import InputError


class _ReportedElsewhere(logging.Filter):
    """FMU error messages end up in the one-line failure message: do not print them twice."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not (record.name.startswith("cosim.fmu.") and record.levelno >= logging.ERROR)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", type=Path, help="scenario YAML file")
    parser.add_argument("--out", type=Path, default=None,
                        help="output directory (default: runs/<name>-<YYYYmmdd-HHMMSS>)")
    parser.add_argument("--db", type=Path, default=None, metavar="PATH",
                        help=f"the monitor's SQLite history (default: the scenario's monitor.db, else {DEFAULT_DB} "
                             "in the current directory, whatever --out is)")
    parser.add_argument("--overwrite", action="store_true", help="replace the files of a non-empty output directory")
    parser.add_argument("--no-progress", action="store_true",
                        help="no progress bar (there is none either when stderr is not a terminal or under CI)")
    parser.add_argument("--no-plots", action="store_true",
                        help="draw no plots/*.png (report.html shows none; the same signals, estimates, verdicts "
                             "and history)")


def main(args: argparse.Namespace) -> int:
    handler = logging.StreamHandler(sys.stderr)
    handler.addFilter(_ReportedElsewhere())
    handler.setFormatter(logging.Formatter("cosim run: %(name)s: %(levelname)s: %(message)s"))
    logging.basicConfig(level=logging.WARNING, handlers=[handler])
    workers = None
    if not args.no_plots:
        # the drawing processes first, before this run's imports: their own import of matplotlib and their first
        # figures (cosim.plot_workers) take the other CPU while this one imports and loads the scenario, instead of
        # while it simulates (the run's figures are then drawn as each motion ends, not queued behind a warm-up)
        from feeddrive.cosim.figure_jobs import FIGURE_MODULES
        from feeddrive.cosim.plot_workers import PlotWorkers

        workers = PlotWorkers(preload=FIGURE_MODULES)
    try:
        code = _run(args, workers)
    except BaseException:
        if workers is not None:  # a bad scenario, or a run that failed: no figure is wanted, no warm-up waited for
            workers.abandon()
        raise
    if workers is not None:
        workers.close()  # the supervised child drew with them and told them to exit: they have, or are about to
    return code


def _run(args: argparse.Namespace, workers) -> int:  # noqa: ANN001 - PlotWorkers or None
    # the collector is off while the run's modules are imported and the scenario is loaded: what they make lives
    # as long as the run, and the collector's passes over it were 15 % of that time (0.70 -> 0.60 s CPU, best of 7)
    collecting = gc.isenabled()
    gc.disable()
    try:
        from feeddrive.cosim.progress import enabled
        from feeddrive.cosim.run import with_history
        from feeddrive.cosim.scenario import load_scenario
        from feeddrive.cosim.supervise import run_supervised

        scenario = load_scenario(args.scenario)
    finally:
        if collecting:
            gc.enable()
    for note in scenario.unit_notes:  # a unit taken on trust is said, once
        print(f"plant.map: {note}")
    from feeddrive.cosim.scenario import stop_note

    note = stop_note(scenario)  # a motion the stop time cuts is never judged: said before the run
    if note:
        print(note)
    if args.db is not None:
        if scenario.monitor is None:
            raise InputError(f"--db {args.db}: the scenario {args.scenario} has no monitor (monitor: section)")
        scenario = with_history(scenario, history_db(args.db), replace=True)
        if scenario is None:
            raise InputError(f"--db {args.db}: the scenario's monitor is a user class; its history is its own")
    out = args.out or _fresh_run_dir(Path("runs") / f"{scenario.name}-{_dt.datetime.now():%Y%m%d-%H%M%S}")
    # in a supervised child process: an FMU that crashes or hangs is reported in one line (exit 1)
    result = run_supervised(scenario, out, progress=enabled(not args.no_progress), overwrite=args.overwrite,
                            default_history=Path(DEFAULT_DB), plots=not args.no_plots, workers=workers)
    print(summary(result))
    return 0


def history_db(db: Path) -> Path:
    """``--db``'s file, absolute; ``:memory:`` (SQLite's name for no file) as it is: resolved, it became a file
    ``./:memory:`` that every later ``--db :memory:`` run continued (a baseline learnt from other runs)."""
    return db if str(db) == ":memory:" else db.expanduser().resolve()


def history_line(monitor: dict) -> str | None:
    """Where the monitor's history is, for which axis, and what its healthy baseline is now.

    ``monitor`` is the monitor's entry of report.json ``components`` (None or not the built-in
    monitor: no line)."""
    if not isinstance(monitor, dict) or "axis" not in monitor:
        return None
    db = monitor.get("db")
    if not db or db == ":memory:":
        where = "in memory (nothing kept after the run)"
    else:
        rel = os.path.relpath(db)
        where = db if rel.startswith("..") else rel
    text = f"  history: {where}, axis {monitor['axis']}"
    t = monitor.get("diagnosis_thresholds") or {}
    if t.get("baseline_mode") == "nominal":
        return text + "; healthy baseline: the nominal parameters (monitor.baseline: nominal)"
    if t.get("baseline_mode") not in (None, "motions"):
        return text + f"; healthy baseline: stated in {t['baseline_mode']} (monitor.baseline)"
    n, k = t.get("baseline_motions"), t.get("baseline_learnt")
    if n is None or k is None:
        return text
    if k < n:
        return text + (f"; learning the healthy baseline: {k} of {n} motions (until then, drift is judged "
                       "against the healthy motions so far)")
    return text + f"; healthy baseline: {n} motion{'' if n == 1 else 's'}"


def _unit(name: str) -> str:
    """A known parameter's unit, from the drive models' names (DC and PMSM share R, Jt, ft, Cd)."""
    from feeddrive.cosim.cli.estimate import model_units

    return (model_units("dc") | model_units("pmsm")).get(name, "")


def _metres(x: float) -> str:
    """A position to the micrometre; a diverged plant's in significant digits (``%.6f`` of 8e28 m printed 29 digits)."""
    return f"{x:.6f}" if abs(x) < 1e6 else f"{x:.4g}"


def summary(result) -> str:  # noqa: ANN001 - cosim.run.RunResult
    """A few lines: simulated time and speed, final position against the NC's target, motions, files."""
    from feeddrive.cosim.report.verdict import fault_values, verdict_line

    r, s = result.report, result.signals
    lines = [f"{r['scenario']}: {r['stop_time_s']:.4g} s simulated in {r['wall_time_s']:.3g} s "
             f"({r['steps']} steps of {r['step_s']:.3g} s) -> {result.out_dir}"]
    if "plant.position" in s and "nc.x_ref" in s:
        unit = "rad" if (r.get("drive_chain") or {}).get("kind") == "rotary" else "m"
        lines.append(f"  position: {_metres(s['plant.position'][-1])} {unit} (NC target {_metres(s['nc.x_ref'][-1])} {unit})")
        if r.get("following"):  # the axis did not follow its NC (cosim.axis.following_note, on every sample)
            lines.append(f"  {r['following']}")
    for k, m in enumerate(r.get("motions") or [], 1):
        if isinstance(m, dict):
            params = m.get("parameters") or {}
            text = " ".join(f"{p}={v['value']:.4g}" for p, v in params.items() if isinstance(v, dict) and "value" in v)
            verdict = verdict_line(m)
            lines.append(f"  motion {k}: {verdict}")  # the verdict first (cosim/report/verdict.py)
            if text:  # a motion not estimated has no values: its verdict says why
                lines.append(f"    {'validated' if m.get('validated') else 'not validated'} {text}")
            for name, why in (m.get("refused") or {}).items():  # no number: the rule that refused it
                lines.append(f"    {name} refused: {why}")
            if m.get("known"):  # fixed, not estimated (monitor.known), as cosim monitor's --known
                lines.append("    known " + " ".join(f"{p}={v:.4g} {_unit(p)}".rstrip() for p, v in m["known"].items())
                             + " (monitor.known)")
            if m.get("servo_checks"):  # a PMSM axis (cosim/monitor_servo.py)
                from feeddrive.cosim.monitor_servo import servo_line

                lines.append(f"    {servo_line(m['servo_checks'])}")
            for f in m.get("sensor_faults") or []:
                lines.append(f"    sensor fault: {f.get('sensor', '?')} {f.get('kind', 'fault')} ({fault_values(f)})")
            if isinstance(m.get("mismatch"), dict) and not m["mismatch"].get("passed", True):
                lines.append(f"    model mismatch ({m['mismatch']['test']} test): parameters not validated")
            for d in m.get("diagnosis") or []:
                if d["fault"] not in verdict:  # the verdict line names it already
                    lines.append(f"    diagnosis: {d['fault']} ({', '.join(d['parameters'])})")
            if m.get("error") and m["error"] not in verdict:
                lines.append(f"    {m['error']}")
    monitor = (r.get("components") or {}).get("monitor") or {}
    unfinished = monitor.get("unfinished_motion")
    if isinstance(unfinished, (int, float)):  # the run stopped inside it: never judged (it said nothing before)
        lines.append(f"  motion {int(unfinished)}: not judged: the run stopped inside it at {r['stop_time_s']:.4g} s "
                     "(stop_time)")
    elif "motions" in monitor and not r.get("motions"):
        # a monitored run whose axis never made a high-speed motion: it said nothing of its motions
        lines.append("  monitor: nothing judged: no high-speed motion (NC state 1) in this run")
    if r.get("held_inputs"):  # a rejection the set-up's sampling explains (cosim/held_inputs.py)
        lines.append(f"  set-up: {r['held_inputs']}")
    if r.get("sampling_bias"):  # L's discretisation error the set-up's sampling leaves (cosim/held_inputs.py)
        lines.append(f"  set-up: {r['sampling_bias']}")
    line = history_line(monitor)
    if line:
        lines.append(line)
    n = len(result.paths["plots"])
    lines.append(f"  files: signals.csv, scenario.resolved.yaml, report.json, report.html, {n} plot{'s' * (n != 1)}")
    return "\n".join(lines)


def _fresh_run_dir(base: Path) -> Path:
    """``base``, or ``base-2``, ``base-3``, ... when runs started in the same second."""
    candidate, k = base, 1
    while candidate.exists():
        k += 1
        candidate = base.with_name(f"{base.name}-{k}")
    return candidate
