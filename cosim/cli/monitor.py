"""``cosim monitor DATA.csv --map ROLE=COLUMN ...``: the monitor's pipeline on a recorded CSV.

Roles: ``time``, ``voltage`` (terminal) and ``voltage_ref`` (regulator reference) [V], ``current1`` and
``current2`` [A], ``torque`` [N.m] (instead of current and voltage: only the mechanical equation, Jt, ft,
Cd and an offset T0) and ``torque_ref`` [N.m] (the drive's torque command: checked against ``torque`` as a
redundant pair, like ``voltage_ref``), ``speed`` (tachometer) [rad/s], ``position`` (encoder motor angle) [rad; a table
position in m with ``--pitch``/``--ratio``], ``state`` (NC state, 1 = rapid). Required: a current or a
torque, and ``speed`` or ``position``; everything else is optional (cosim/monitor_checks.py): each check
that cannot run says "not checked" with the missing sensor. The encoder angle is differentiated
(central differences) into the second speed. The monitor's thresholds are options (``--known``,
``--min-motion``, ``--alpha``, ``--window``, ...: ``monitor_checks.CLI_OPTIONS``), mapped onto the same
``MonitorConfig`` as a scenario's ``monitor:`` section.

Each high-speed motion (``--segment``: the NC state when mapped, else the speed profile) goes through
validation, estimation, model validation and diagnosis, and is stored in the history (``--db``) of
``--axis``, continuing from what the history already holds. Machine time of a motion: from
``--start-time``, or the time column's calendar time stamps, else the file's modification time taken as the
end of the recording (``recorded.start_clock``; said in the console's ``time:`` line and the JSON's
``time_source``).

``--out DIR`` writes ``report.json`` (the motions' results, the diagnosis thresholds, versions),
``plots/`` (the figures of the last ``keep_traces`` = 5 motions, as in a run, and the trends) and
``report.html`` (cosim.report) into DIR; with ``--no-plots`` no figure (the same report.json and page without
figures).

Exit status: 0 when at least one motion was judged (any verdict but ``not estimated``); 3 (``NOTHING_JUDGED``)
when none was: no high-speed motion found (a recording at rest: ``segmentation.at_rest``, the threshold said) or
every motion not estimated; the last line (stderr with ``--json``) and report.json's ``nothing_judged`` say why;
2 bad input (one line on stderr).
"""
from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import sys
from pathlib import Path

from feeddrive.cosim.axis import parameter_units
from feeddrive.cosim.cli.history import DEFAULT_DB
from feeddrive.cosim.errors import InputError
from feeddrive.cosim.monitor import MonitorConfig, MonitorPipeline
from feeddrive.cosim.monitor_checks import add_config_arguments, config_with_options
from feeddrive.cosim.recorded import (
    add_recording_arguments,
    filter_cutoff,
    mapped_roles,
    no_motion,
    read_recording,
    recording_json,
    sampling_modes,
    start_clock,
)
from feeddrive.cosim.recorded import (
    motions as record_motions,
)
from feeddrive.cosim.recorded_servo import PMSM_ROLES, missing_roles, second_phase, servo_signals, unit_notes
from feeddrive.cosim.run import _versions
from feeddrive.estimator.pvalue_text import p_text

#: units of the monitor's parameters (motor side)
UNITS = parameter_units("motor")
#: role -> monitor signal (the DC drive's; a PMSM's: ``recorded_servo.PMSM_ROLES``)
ROLES = {"time": None, "voltage": "u", "voltage_ref": "u_ref", "current1": "Im1", "current2": "Im2",
         "speed": "w_tach", "position": None, "torque": "torque", "torque_ref": "torque_ref", "state": None} | PMSM_ROLES
#: roles of both drives
COMMON = ("time", "speed", "position", "state")
#: exit status when no motion was judged: none found, or every one not estimated (each says why); 0 when at
#: least one motion has a verdict, 2 bad input (one line)
NOTHING_JUDGED = 3


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_recording_arguments(parser, ROLES, MonitorConfig().filter_cutoff_hz)
    parser.add_argument("--db", default=DEFAULT_DB, help=f"SQLite history file (default: {DEFAULT_DB})")
    parser.add_argument("--axis", default="X", help="machine/axis id in the history (default X)")
    parser.add_argument("--plots", metavar="DIR", help="write the monitor plots of every motion into DIR")
    parser.add_argument("--out", metavar="DIR", help="write report.json, report.html and plots/ into DIR")
    parser.add_argument("--no-plots", action="store_true",
                        help="with --out: draw no plots/*.png (report.html shows none; the same results)")
    parser.add_argument("--overwrite", action="store_true", help="replace existing plot files")
    parser.add_argument("--drive", choices=("dc", "pmsm", "pmsm-spm"), default="dc",
                        help="the motor: dc (default) or a PMSM with the roles " + ", ".join(PMSM_ROLES)
                        + " (a servo drive's trace, cosim/recorded_servo.py; the dq model and Table I of the PMSM)")
    parser.add_argument("--pole-pairs", type=int, default=None, metavar="N", help="a PMSM's pole pairs (default 4)")
    parser.add_argument("--angle-offset", type=float, default=None, metavar="RAD",
                        help="a PMSM's electrical angle at the encoder's zero: phi_el = p * position + RAD (default 0)")
    add_config_arguments(parser, MonitorConfig)
    parser.epilog = (f"exit status: 0 at least one motion judged; {NOTHING_JUDGED} nothing judged (no high-speed motion "
                     "found, or every motion not estimated: the last line says why); 2 bad input (one line)")


def main(args: argparse.Namespace) -> int:
    from feeddrive.estimator.history import History

    drive = getattr(args, "drive", "dc")
    pmsm = drive != "dc"
    if getattr(args, "pole_pairs", None) is not None and (not pmsm or args.pole_pairs < 1):
        raise InputError(f"--pole-pairs {args.pole_pairs}: expected a positive integer with --drive pmsm or pmsm-spm")
    if getattr(args, "angle_offset", None) is not None and not pmsm:
        raise InputError("--angle-offset: a PMSM's electrical angle; expected --drive pmsm or pmsm-spm")
    role_map = mapped_roles(args, [r for r in ROLES if r in COMMON or (r in PMSM_ROLES) == pmsm])
    if pmsm:
        missing = missing_roles(role_map)
    else:
        missing = [] if {"current1", "current2", "torque"} & set(role_map) else ["current1 (or torque)"]
    if not {"speed", "position"} & set(role_map):
        missing.append("speed or position")
    if missing:
        raise InputError(f"--map: missing required role(s): {', '.join(missing)}")
    columns = {"voltage": role_map.get("u_q") or role_map.get("u_q_ref") if pmsm else role_map.get("voltage"),
               "current": role_map.get("i_q") or role_map.get("I_U") if pmsm
               else role_map.get("current1") or role_map.get("current2"),
               "speed": role_map.get("speed")}
    drive_keys = {"drive": drive} | ({"pole_pairs": args.pole_pairs} if pmsm and args.pole_pairs else {})
    drive_keys |= {"second_sensor_on": second_phase(role_map)} if pmsm else {}
    config = config_with_options(args, MonitorConfig, axis=args.axis, db=args.db, method=args.method,
                                 speed_threshold=args.speed_threshold, **drive_keys,
                                 sampling=sampling_modes(args, {q: c for q, c in columns.items() if c}))
    rec = read_recording(args, role_map)
    if rec.side == "table":  # the monitor's model is the motor's: u = R i + L di/dt + K w, w in rad/s
        raise InputError(f"{args.data}: the position/speed columns are on the table side ({rec.units}); the "
                         "monitor needs the motor side: give --pitch (and --ratio) to convert them")
    sig = {ROLES[r]: v for r, v in rec.signals.items() if ROLES[r] and r not in PMSM_ROLES}
    if pmsm:  # a servo drive's trace: the monitor completes what it lacks (monitor_servo.complete_signals)
        sig |= servo_signals(rec.signals, args, args.pole_pairs or 4)
    if "Im1" not in sig and "Im2" in sig:  # a single current sensor, whatever it is called
        sig["Im1"] = sig.pop("Im2")
    if "position" in rec.signals:
        w_enc = rec.gradient(rec.signals["position"])  # within each record of a split recording
        sig["w_enc" if "w_tach" in sig else "w_tach"] = w_enc
    segments = record_motions(args, rec, sig["w_tach"], rec.signals.get("state"))
    # none found: the report and the exit status say so (NOTHING_JUDGED), as when every motion is refused
    found = "" if segments else no_motion(args, rec, sig["w_tach"], rec.signals.get("state"))
    plots = _plot_folder(args.plots, args.overwrite) if args.plots else None
    out = _out_folder(args.out, args.overwrite) if args.out else None
    clock0, clock_source = start_clock(rec, args.start_time)  # machine time of sample 0, and where it came from
    ends = [clock0 + rec.time(seg.stop - 1) - rec.t0 for seg in segments]  # each motion's machine time
    if args.db == DEFAULT_DB:
        Path(DEFAULT_DB).parent.mkdir(exist_ok=True)
    started = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    config = config.model_copy(update={"scenario": str(rec.path), "filter_cutoff_hz": filter_cutoff(args, rec.h)})
    traces = []
    with History(args.db) as history:
        stored = history.stored_at(args.axis, ends)  # a replay would count its motions twice (baseline, trends)
        if stored:
            again = [k for k, t in enumerate(ends, 1) if any(abs(t - st) <= 1e-3 for _, st in stored)]
            raise InputError(f"{args.db}: axis {args.axis} already holds motion {', '.join(map(str, again))} of "
                             f"the {len(ends)} of {rec.path} (history id {', '.join(str(i) for i, _ in stored)}: "
                             f"the same machine times, {clock_source.split(' (')[0]}); storing them again would "
                             "count them twice in the baseline and the trends: use another --axis or --db (--db "
                             ":memory: to look without storing)")
        pipeline = MonitorPipeline(config, history, args.axis)
        for k, seg in enumerate(segments, 1):
            part = {name: x[seg.start:seg.stop] for name, x in sig.items()}
            traces.append(pipeline.process(part, rec.h, rec.time(seg.start), k, ends[k - 1], str(rec.path)))
        motions = history.motions(args.axis)
        thresholds = pipeline.thresholds()
    results = [t.result for t in traces]
    nothing = nothing_judged(results, found)
    # the conversions a reader must know (an rms current) and the units assumed (no unit in the header or the map)
    units = unit_notes(rec.columns, rec.units) + list(rec.notes)
    if plots is not None:
        from feeddrive.cosim.monitor_plots import plot_monitor

        for p in plot_monitor(traces, motions, plots, thresholds):
            print(f"wrote {p}")
    if out is not None:
        report = {"kind": "monitor", "source": str(rec.path), "axis": args.axis, "db": args.db, "started": started,
                  "status": "ok", "versions": _versions(), "method": args.method, **recording_json(rec, clock_source),
                  "components": {"monitor": {"budget_s": config.budget_s}}, "diagnosis_thresholds": thresholds,
                  "unit_notes": units, "motions": results} | ({"nothing_judged": nothing} if nothing else {})
        kept = traces[-config.keep_traces:] if config.keep_traces else []  # as the co-simulation monitor keeps
        print(f"wrote {write_monitor_report(out, report, kept, motions, thresholds, plots=not args.no_plots)}")
    if args.json:
        print(json.dumps({"axis": args.axis, "db": args.db, **recording_json(rec, clock_source), "unit_notes": units,
                          "motions": results} | ({"nothing_judged": nothing} if nothing else {}), default=_jsonable))
    else:
        from feeddrive.cosim.cli.run import history_line

        print(f"time: {clock_source}")
        for note in units:
            print(f"units: {note}")
        from feeddrive.cosim.cli.estimate import model_units

        if results:
            print(table(results, UNITS | model_units(drive)))
        print(history_line({"axis": args.axis, "db": args.db if args.db == ":memory:" else str(Path(args.db).resolve()),
                            "diagnosis_thresholds": thresholds}).strip())
    if nothing:  # the last line, and a status a script cannot take for success
        print(nothing, file=sys.stderr if args.json else sys.stdout)
        return NOTHING_JUDGED
    return 0


def nothing_judged(results: list[dict], found: str = "") -> str:
    """The line saying that no motion was judged and why ('' when one was): a motion is judged when its verdict is
    not ``not estimated`` (a sensor fault found without parameters is a verdict). ``found``: why no motion was found
    (``recorded.no_motion``), when none was."""
    from feeddrive.cosim.report.verdict import motion_verdict

    if not results:
        return f"nothing judged: {found or 'no high-speed motion found'}"
    if any(motion_verdict(r)["kind"] != "not estimated" for r in results):
        return ""
    reasons: dict[str, list[int]] = {}  # the same reason once, with the motions it holds for
    for r in results:
        reasons.setdefault(str(r.get("error") or "no parameters"), []).append(int(r["motion"]))
    why = "; ".join(f"motion{'s' * (len(ks) > 1)} {', '.join(map(str, ks))}: {text}" for text, ks in reasons.items())
    if len(results) == 1:
        return f"nothing judged: {why}"
    return f"nothing judged: none of the {len(results)} motions could be estimated ({why})"


def _plot_folder(name: str, overwrite: bool) -> Path:
    """The ``--plots`` folder, created now: a plot step failing after the history was written would store
    the motions twice when the command is run again."""
    plots = Path(name)
    if plots.exists() and not plots.is_dir():
        raise InputError(f"--plots {plots}: is a file; expected a folder for the plots")
    try:
        plots.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"--plots {plots}: cannot create the plot folder ({exc.strerror or exc}); "
                         "expected a writable folder") from None
    if not os.access(plots, os.W_OK | os.X_OK):
        raise InputError(f"--plots {plots}: the plot folder is not writable")
    if not overwrite and any(plots.glob("monitor_*.png")):
        raise InputError(f"--plots {plots}: the folder already holds monitor plots; use --overwrite to replace them")
    return plots


def _out_folder(name: str, overwrite: bool) -> Path:
    """The ``--out`` folder, created (and checked) before the history is written, as for ``--plots``."""
    out = _plot_folder(name, True)
    if not overwrite and any((out / f).exists() for f in ("report.json", "report.html", "plots")):
        raise InputError(f"--out {out}: the folder already holds a report; use --overwrite to replace it")
    return out


def write_monitor_report(out: Path, report: dict, traces: list, motions: list[dict], thresholds: dict, *,
                         plots: bool = True) -> Path:
    """``out/plots/*.png`` (none if not ``plots``), ``out/report.json`` and ``out/report.html`` of one
    ``cosim monitor`` call."""
    from feeddrive.cosim.report import write_run_page

    for old in (out / "plots").glob("monitor_*.png"):
        old.unlink()
    drawn = []
    if plots:
        from feeddrive.cosim.monitor_plots import plot_monitor

        drawn = plot_monitor(traces, motions, out / "plots", thresholds)
    report["files"] = {"report": "report.json", "page": "report.html",
                       "plots": [os.path.relpath(p, out) for p in drawn]}
    (out / "report.json").write_text(json.dumps(report, indent=2, default=_jsonable), encoding="utf-8")
    # the page is drawn from the JSON just written, so that it shows exactly report.json's values
    return write_run_page(out, json.loads((out / "report.json").read_text(encoding="utf-8")))


def _jsonable(x):  # noqa: ANN001, ANN202 - numpy scalars in the results
    if hasattr(x, "item"):
        return x.item()
    raise TypeError(f"cosim monitor: {type(x).__name__} is not JSON-serialisable")


def adequacy_line(a: dict) -> str:
    """The residue model check's line from its report.json dict (``AdequacyResult.to_dict``)."""
    p = "" if a["p_value"] is None else f" ({p_text(a['p_value'])} at alpha = {a['alpha']:g})"
    verdict = "MODEL MISMATCH" if a["verdict"] == "model mismatch" else a["verdict"]
    return f"model check (own residue): {verdict}{p}: {a['reason']}"


def table(results: list[dict], units: dict[str, str] | None = None) -> str:
    """One block per motion: verdicts, sensor faults, parameters with 95 % CIs, model check, diagnosis."""
    from feeddrive.cosim.report.verdict import finite, verdict_line

    lines = []
    for r in results:
        verdict = "validated" if r["validated"] else "NOT validated"
        lines.append(f"motion {r['motion']}: {verdict_line(r)}")  # the verdict first (cosim/report/verdict.py)
        cpu = r.get("processing_cpu_s")
        lines.append(f"  {r['start']:.4g}-{r['end']:.4g} s, {verdict}, processing "
                     + (f"{cpu:.3g} s CPU ({r['processing_s']:.3g} s wall)" if cpu is not None
                        else f"{r['processing_s']:.3g} s wall"))
        for quantity, why in (r.get("not_checked") or {}).items():
            lines.append(f"  {quantity}: {why}")
        if r["error"]:
            lines.append(f"  not identified: {r['error']}")
        for f in r["sensor_faults"]:
            lines.append(f"  sensor fault {f['sensor']}: {f['kind']}, gain {f['gain']:.4f} "
                         f"[{f['gain_ci95'][0]:.4f}, {f['gain_ci95'][1]:.4f}], offset {f['offset']:.4g} "
                         f"[{f['offset_ci95'][0]:.4g}, {f['offset_ci95'][1]:.4g}]")
        if finite(r["gain_ratio"]):
            lines.append(f"  current gain ratio a1/a2 = {r['gain_ratio']:.4f}")
        elif r.get("gain_ratio_reason"):  # why, never a bare "not computed"
            lines.append(f"  current gain ratio a1/a2: {r['gain_ratio_reason']}")
        elif r["gain_ratio"] is not None:
            lines.append("  current gain ratio a1/a2: not checked (one current sensor)")
        for name, p in r["parameters"].items():
            lines.append(f"  {name:3} {p['value']:12.6g} {p.get('unit', ''):10} 95 % CI "
                         f"[{p['ci95'][0]:.6g}, {p['ci95'][1]:.6g}]")
        for name, why in (r.get("refused") or {}).items():
            lines.append(f"  {name:3} refused: {why}")
        for name, value in r.get("known", {}).items():
            lines.append(f"  {name:3} {value:12.6g} {(units or UNITS).get(name, ''):10} known (--known)")
        if r["mismatch"]:
            m = r["mismatch"]
            lines.append(f"  model check: {'passed' if m['passed'] else 'MISMATCH'} (decided by the {m['test']} "
                         f"test: statistic {m['statistic']:.3g}, {p_text(m['p_value'])} at alpha = {m['alpha']:g})")
        if r.get("adequacy"):
            lines.append(f"  {adequacy_line(r['adequacy'])}")
        if r.get("servo_checks"):  # a PMSM's redundancies, as the co-simulation's console shows them
            from feeddrive.cosim.monitor_servo import servo_line

            lines.append(f"  {servo_line(r['servo_checks'])}")
        for d in r["diagnosis"]:
            lines.append(f"  diagnosis: {d['fault']} ({', '.join(d['parameters'])})")
        lines += [f"  derived: {n}" for n in r.get("derived", ())]
        lines += [f"  note: {n}" for n in r["notes"]]
    return "\n".join(lines)
