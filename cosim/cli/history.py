"""``cosim history``: print an axis's stored motions and plot each parameter's trend with its CI band.

    cosim history [DB | --db PATH] [--axis ID] [--plot [PNG]] [--html OUT.html] [--overwrite] [--json]
"""
from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
from pathlib import Path

from feeddrive.cosim.errors import InputError

#: The history file of ``cosim run``, ``cosim monitor`` and ``cosim history`` when neither --db nor the
#: scenario's ``monitor.db`` names one: relative to the current directory, whatever --out is, so the
#: three commands find the same file. Each axis has its own history in it (the key is the axis name).
DEFAULT_DB = "runs/history.sqlite"
NAMES = ("R", "L", "K", "Jt", "ft", "Cd")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("database", nargs="?", metavar="DB", help="SQLite history file, as --db")
    parser.add_argument("--db", default=None, help=f"SQLite history file (default: {DEFAULT_DB})")
    parser.add_argument("--axis", help="machine/axis id (default: every axis in the file)")
    parser.add_argument("--plot", nargs="?", const="", metavar="PNG",
                        help="draw the parameter trends (default file: history_<axis>.png)")
    parser.add_argument("--html", metavar="OUT.html", help="write the axis's history page (trends against "
                        "calendar time and motion number, healthy baseline, alarm band, diagnoses)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing plot or HTML file")
    parser.add_argument("--json", action="store_true", help="print the stored motions as JSON")


def main(args: argparse.Namespace) -> int:
    from feeddrive.estimator.history import History

    if args.database is not None and args.db is not None and Path(args.database) != Path(args.db):
        raise InputError(f"two history files: {args.database} and --db {args.db}; give one")
    db = Path(args.database or args.db or DEFAULT_DB)
    if not db.is_file():  # reading must not create an empty database
        raise InputError(f"history database {db} does not exist")
    with History(db) as history:
        held = history.axes()
        axes = [args.axis] if args.axis else held
        motions = {axis: history.motions(axis) for axis in axes}
    if args.axis and not motions[args.axis]:
        raise InputError(f"history database {db}: no motion for axis {args.axis!r} (axes in the file: "
                         f"{', '.join(held) or 'none'})")
    if args.plot and len(axes) > 1:
        raise InputError("--plot PNG names one file: choose an axis with --axis")
    if args.json:
        print(json.dumps({"db": str(db), "axes": motions}, indent=2))
    else:
        for axis in axes:
            print(format_table(axis, motions[axis]))
    if args.plot is not None:
        from feeddrive.cosim.monitor_plots import plot_trends

        for axis in axes:
            path = Path(args.plot or f"history_{axis}.png")
            if path.exists() and not args.overwrite:  # the table is printed all the same
                raise InputError(f"plot file {path} exists; use --overwrite to replace it")
            plot_trends(motions[axis], path, f"axis {axis}", thresholds(db, axis, motions[axis]))
            print(f"wrote {path}")
    if args.html is not None:
        from feeddrive.cosim.report import write_history_page

        if len(axes) != 1:
            raise InputError(f"--html: the history {db} holds the axes {', '.join(axes)}; choose one with --axis")
        html = Path(args.html)
        if html.exists() and not args.overwrite:
            raise InputError(f"--html {html}: the file exists; use --overwrite to replace it")
        write_history_page(html, axes[0], motions[axes[0]], thresholds(db, axes[0], motions[axes[0]]), str(db))
        print(f"wrote {html}")
    return 0


def thresholds(db: Path, axis: str, motions: list[dict]) -> dict:
    """The alarm band's thresholds for a history page: those of the newest judged motion (what the monitor used:
    its z, relative changes and baseline size), else the monitor's defaults; the healthy baseline as the monitor
    reads it from ``db``, or the one that motion was judged against when it was not learnt from the axis's motions
    (``monitor.baseline: nominal`` or a stated file)."""
    from feeddrive.cosim.monitor import MonitorConfig, MonitorPipeline
    from feeddrive.estimator.history import History

    used = next((m["drift_reference"] for m in reversed(motions) if m.get("drift_reference")), None)
    # the baseline's size the monitor used (stored with each judged motion since 2026-11-27; else the default)
    size = (used or {}).get("baseline_motions") if (used or {}).get("baseline_mode") == "motions" else None
    config = MonitorConfig(axis=axis) if size is None else MonitorConfig(axis=axis, baseline_motions=size)
    with History(db) as history:
        out = MonitorPipeline(config, history, axis).thresholds()
    if used is not None:
        from feeddrive.estimator.distributions import norm_sf

        out |= {"z_crit": used["z_crit"], "min_relative": used["min_relative"], "alpha": 2 * norm_sf(used["z_crit"])}
        if used.get("baseline_mode") not in (None, "motions") and used.get("baseline"):
            # judged against the nominal parameters or a stated file, not against the axis's learnt motions: the
            # page showed "not learnt yet" beside motions diagnosed against the nominal values
            out |= {"baseline": used["baseline"], "baseline_mode": used["baseline_mode"]}
    return out


def format_table(axis: str, motions: list[dict]) -> str:
    """One line per motion: its number on the axis (counted across runs), the run it came from and its
    motion number there, time, validation, each parameter as value +- half its 95 % CI, faults, diagnosis."""
    units = {n: p["unit"] for m in motions for n, p in m.get("parameters", {}).items() if "unit" in p}
    head = f"{'motion':>6} {'run:motion':24} {'time (UTC)':19} {'valid':5} " + " ".join(
        f"{n + (' [' + units[n] + ']' if n in units else '') + ' ±95%':>17}" for n in NAMES)
    lines = [f"axis {axis}: {len(motions)} motion(s); parameters as estimate ± half-width of the 95 % "
             "confidence interval", head + "  sensor faults / diagnosis"]
    for number, m in enumerate(motions, 1):
        when = _dt.datetime.fromtimestamp(m["time"], _dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S")
        cells = []
        for n in NAMES:
            p = m.get("parameters", {}).get(n)
            if p is None:
                cells.append(f"{'-':>17}")
            else:
                lo, hi = p["ci95"]
                half = (hi - lo) / 2 if lo is not None and hi is not None else math.nan
                cells.append(f"{p['value']:>9.4g} ±{half:<7.2g}")
        extra = [f"{f['sensor']}:{f['kind']}" for f in m.get("sensor_faults", [])]
        extra += [d["fault"] for d in m.get("diagnosis", [])]
        if m.get("error"):
            extra.append(m["error"])
        run = f"{(m.get('scenario') or '?')[:20]}:{m.get('motion', '')}"
        lines.append(f"{number:>6} {run:24} {when:19} {'yes' if m['validated'] else 'no':5} "
                     + " ".join(cells) + "  " + "; ".join(extra))
    return "\n".join(lines)
