"""report.html: one self-contained page per run (``cosim run``, ``cosim monitor --out``) and per axis history.

The page is rendered with jinja2 from the data of report.json (or of the history); every figure is
embedded as a base64 PNG (``data:`` URI), so the file opens without network access or its folder.

Parameter colours: against the alarm band of the diagnosis (cosim/trends.py), a validated parameter is
``healthy`` within half the band, ``drifting`` beyond half of it and ``diagnosed`` when a diagnosis
names it; a parameter of a motion that was not validated is ``not judged`` (the monitor never
diagnoses it).
"""
from __future__ import annotations

import base64
import datetime as _dt
import json
import math
import os
import re
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import jinja2

from feeddrive.cosim.report import views
from feeddrive.cosim.report.verdict import motion_verdict, sensor_unit
from feeddrive.cosim.trends import UNITS, trend_names, trend_series, use_dates

PAGE = "report.html"


def cache_dir() -> Path:
    """Where the compiled template is kept: ``$FEEDDRIVE_CACHE/jinja2``, else ``~/.cache/feeddrive/jinja2`` (the
    root of the built-in FMU's cache)."""
    return Path(os.environ.get("FEEDDRIVE_CACHE") or Path.home() / ".cache" / "feeddrive") / "jinja2"


class TemplateCache(jinja2.FileSystemBytecodeCache):
    """jinja2's file cache of compiled templates that never fails a page.

    Compiling report.html's template took 0.7 s of every ``cosim run``; loading its cached code takes a few
    ms. jinja2 keys an entry by the template's name and checks it against the source's checksum (and its own
    and Python's versions): an edited template is compiled again. A directory that cannot be written or an
    unreadable entry only means the template is compiled, as without a cache. The directory is
    :func:`cache_dir` when the template is loaded (``$FEEDDRIVE_CACHE`` may be set after this import).
    """

    def __init__(self) -> None:
        super().__init__(".", "report-%s.cache")

    @property
    def directory(self) -> str:
        return str(cache_dir())

    @directory.setter
    def directory(self, value: str) -> None:  # jinja2's __init__ sets it; cache_dir() decides
        pass

    def load_bytecode(self, bucket: jinja2.bccache.Bucket) -> None:
        try:
            super().load_bytecode(bucket)
        except Exception:  # noqa: BLE001 - a truncated or foreign file: compiled as without a cache
            bucket.reset()

    def dump_bytecode(self, bucket: jinja2.bccache.Bucket) -> None:
        try:
            cache_dir().mkdir(parents=True, exist_ok=True)
            super().dump_bytecode(bucket)
        except OSError:  # read-only home, full disk: the next run compiles it again
            pass


_ENV = jinja2.Environment(loader=jinja2.PackageLoader("feeddrive.cosim.report", "templates"),
                          autoescape=jinja2.select_autoescape(default=True, default_for_string=True),
                          undefined=jinja2.ChainableUndefined, trim_blocks=True, lstrip_blocks=True,
                          bytecode_cache=TemplateCache())


def num(x: Any, digits: int = 6) -> str:
    """A number for the page: ``digits`` significant digits, ``-`` for None, yes/no for booleans."""
    if x is None:
        return "-"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int):
        return str(x)
    if isinstance(x, float):
        return "not computed" if not math.isfinite(x) else f"{x:.{digits}g}"  # never "nan" on the page
    if isinstance(x, (list, tuple)):
        return "[" + ", ".join(num(v, digits) for v in x) + "]"
    if isinstance(x, Mapping):
        return ", ".join(f"{k}: {num(v, digits)}" for k, v in x.items())
    return str(x)


def merged_evidence(diagnosis: Sequence[Mapping]) -> list[dict]:
    """The evidence of a motion's diagnoses, once per parameter, with the faults it points at.

    Faults that Table I cannot tell apart (wear, lubrication) share their evidence: listing it once reads better.
    """
    out: dict[str, dict] = {}
    for d in diagnosis or ():
        for ev in d.get("evidence", ()):
            out.setdefault(ev["parameter"], dict(ev) | {"faults": []})["faults"].append(d["fault"])
    return list(out.values())


_ENV.filters["num"] = num
_ENV.filters["evidence"] = merged_evidence
_ENV.filters["sensor_unit"] = sensor_unit
_ENV.filters["pct"] = lambda x, d=3: "-" if x is None else f"{100 * x:+.{d}g} %"
_ENV.filters["percent"] = lambda x, d=3: "-" if x is None else f"{100 * x:.{d}g} %"
_ENV.filters["utc"] = lambda t: "-" if t is None else _dt.datetime.fromtimestamp(
    t, _dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S")


def embed_png(path: Path) -> str:
    """``data:image/png;base64,...`` URI of a PNG file."""
    return "data:image/png;base64," + base64.b64encode(Path(path).read_bytes()).decode("ascii")


def _caption(name: str) -> tuple[int | None, str]:
    """(motion or None, caption) of a plot file of a run."""
    if m := re.fullmatch(r"motion_(\d+)_profiles\.png", name):
        return int(m[1]), f"Motion {m[1]}: voltage, current and speed (paper Fig. 3, 8)"
    if m := re.fullmatch(r"motion_(\d+)_currents\.png", name):
        return int(m[1]), f"Motion {m[1]}: the redundant current sensors and their residue (paper Fig. 9, 10)"
    if m := re.fullmatch(r"monitor_motion(\d+)\.png", name):
        return int(m[1]), (f"Motion {m[1]}: residue windows, measured vs simulated current and speed "
                           "(paper Fig. 10-14)")
    if name == "monitor_trends.png":
        return None, "Parameter trends of the axis with the healthy baseline and the diagnosis' alarm band"
    return None, name


def motion_view(m: Mapping, thresholds: Mapping | None, units: Mapping[str, str], budget_s: float | None) -> dict:
    """What the page shows of one motion result (report.json ``motions[k]``)."""
    series = trend_series([m], thresholds)
    diagnosed = {p for d in m.get("diagnosis") or () for p in d.get("parameters", ())}
    rows = []
    for name, p in (m.get("parameters") or {}).items():
        s = series[name]
        ref, lo, hi = s["reference"][0], s["band_low"][0], s["band_high"][0]
        value = float(p["value"])
        status = parameter_status(bool(m.get("validated")), name in diagnosed, value, ref, lo, hi)
        rows.append({"name": name, "unit": p.get("unit") or units.get(name, ""), "value": value,
                     "repr": repr(value), "std": p.get("std"), "ci95": list(p.get("ci95") or (None, None)),
                     "reference": ref, "band": None if ref is None else (lo, hi),
                     "change": None if not ref else (value - ref) / abs(ref), "status": status})
    verdict = motion_verdict(m, {r["name"]: r["status"] for r in rows})
    # a refused parameter has no number: its row says which rule refused it and why
    refused = [{"name": n, "unit": units.get(n, ""), "reason": str(why)} for n, why in (m.get("refused") or {}).items()]
    not_checked = [(q, str(why)) for q, why in (m.get("not_checked") or {}).items() if q.startswith("model")]
    known = [{"name": n, "unit": units.get(n, ""), "value": v} for n, v in (m.get("known") or {}).items()]
    return {"m": m, "rows": rows, "verdict": verdict, "refused": refused, "known": known, "not_checked": not_checked,
            "processing": views.processing(m, budget_s), "check": views.model_check(m.get("mismatch")),
            "residues": views.residue_rows(m), "gain_ratio": views.gain_ratio(m), "servo": views.servo_rows(m),
            "adequacy": views.residue_check(m), "figures": []}


def parameter_status(validated: bool, diagnosed: bool, value: float, ref: float | None, lo: float | None,
                     hi: float | None) -> str:
    """``healthy``, ``drifting`` (beyond half the alarm band's half-width), ``diagnosed`` or ``not judged``."""
    if not validated:
        return "not judged"
    if diagnosed:
        return "diagnosed"
    if ref is not None and abs(value - ref) > (hi - lo) / 4:
        return "drifting"
    return "healthy"


def _units(report: Mapping) -> dict[str, str]:
    """Parameter units: the defaults, overridden by any ``unit`` a motion's parameters carry."""
    from feeddrive.models.drives import drive_model

    # a PMSM's names too (a known psi_f has no estimate to carry its unit)
    out = {v.name: v.unit for v in drive_model("pmsm").of_kind("physical")} | dict(UNITS)
    for m in report.get("motions") or ():
        out |= {k: p["unit"] for k, p in (m.get("parameters") or {}).items() if p.get("unit")}
    return out


def _figures(out_dir: Path, report: Mapping) -> list[dict]:
    files = (report.get("files") or {}).get("plots")
    paths = [out_dir / f for f in files] if files else sorted((out_dir / "plots").glob("*.png"))
    out = []
    for p in paths:
        if p.is_file():
            motion, caption = _caption(p.name)
            out.append({"motion": motion, "caption": caption, "file": p.name, "src": embed_png(p)})
    return out


def render_run(report: Mapping, out_dir: Path) -> str:
    """The page of one run (or one ``cosim monitor`` call) from its report.json data."""
    monitor = (report.get("components") or {}).get("monitor") or {}
    thresholds = report.get("diagnosis_thresholds") or monitor.get("diagnosis_thresholds")
    units = _units(report)
    budget = monitor.get("budget_s")
    motions = [motion_view(m, thresholds, units, budget) for m in report.get("motions") or ()]
    figures = _figures(out_dir, report)
    by_motion = {v["m"].get("motion"): v for v in motions}
    general = []
    for f in figures:
        if f["motion"] in by_motion:
            by_motion[f["motion"]]["figures"].append(f)
        else:
            general.append(f)
    return _ENV.get_template("report.html.j2").render(
        kind="run", title=f"{report.get('scenario') or report.get('source') or 'run'}", report=report,
        motions=motions, figures=general, thresholds=thresholds, units=units, history=None, rows=[], data_json=None)


def prepare() -> None:
    """Compile the page's template now (a third of a second), e.g. while a run's figures are drawn;
    jinja2 keeps it for the pages rendered later."""
    _ENV.get_template("report.html.j2")


def write_run_page(out_dir: str | Path, report: Mapping | None = None) -> Path:
    """Write ``out_dir/report.html`` from ``report`` (default: ``out_dir/report.json``); returns its path."""
    out_dir = Path(out_dir)
    if report is None:
        report = json.loads((out_dir / "report.json").read_text(encoding="utf-8"))
    path = out_dir / PAGE
    path.write_text(render_run(report, out_dir), encoding="utf-8")
    return path


def write_history_page(path: str | Path, axis: str, motions: Sequence[Mapping], thresholds: Mapping | None,
                       db: str = "") -> Path:
    """Write the page of an axis's whole history to ``path``.

    Parameters
    ----------
    path : path
        The HTML file.
    axis : str
    motions : sequence of dict
        The stored motions (``History.motions(axis)``), oldest first.
    thresholds : mapping or None
        ``diagnosis_thresholds`` with the axis's healthy baseline (cosim/trends.py).
    db : str
        The history file, shown in the summary.
    """
    from feeddrive.cosim.trends import plot_trends

    path = Path(path)
    figures = []
    with tempfile.TemporaryDirectory() as tmp:
        kinds = (["date"] if use_dates(motions) else []) + ["motion"]
        for x in kinds:
            png = plot_trends(motions, Path(tmp) / f"trends_{x}.png", f"axis {axis}", thresholds, x=x)
            what = "machine time (UTC)" if x == "date" else "motion number"
            figures.append({"motion": None, "file": png.name, "src": embed_png(png),
                            "caption": f"Parameter trends against {what}: 95 % CIs, healthy baseline, alarm band, "
                                       "diagnoses"})
    units = _units({"motions": motions})
    series = trend_series(motions, thresholds)
    times = [m["time"] for m in motions if m.get("time") is not None]
    history = {"axis": axis, "db": db, "n": len(motions), "validated": sum(bool(m.get("validated")) for m in motions),
               "first": min(times, default=None), "last": max(times, default=None),
               "diagnosed": [m for m in motions if m.get("diagnosis")],
               "sensor_faults": sum(bool(m.get("sensor_faults")) or m.get("measurements_valid") is False
                                    for m in motions),
               "mismatches": sum(isinstance(m.get("mismatch"), Mapping) and m["mismatch"].get("passed") is False
                                 for m in motions)}
    index = {name: {k: j for j, k in enumerate(s["number"])} for name, s in series.items()}
    # a column per parameter this axis has given, in the trends' order: a DC axis has no L_d, L_q, psi_f columns
    columns = trend_names(series)
    rows = []
    for k, m in enumerate(motions, 1):
        cells = {}
        for name in columns:
            s, j = series.get(name), index.get(name, {}).get(k)
            if j is None:
                continue
            cells[name] = {"value": s["value"][j], "status": parameter_status(
                s["validated"][j], s["diagnosed"][j], s["value"][j], s["reference"][j], s["band_low"][j],
                s["band_high"][j])}
        rows.append({"number": k, "m": m, "cells": cells,
                     "verdict": motion_verdict(m, {n: c["status"] for n, c in cells.items()})})
    html = _ENV.get_template("report.html.j2").render(
        kind="history", title=f"axis {axis}", report={}, motions=[], figures=figures, thresholds=thresholds,
        units=units, columns=columns, history=history, rows=rows, data_json=json.dumps({"axis": axis, "thresholds": thresholds, "trends": series}).replace("</", "<\\/"))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(html, encoding="utf-8")
    return path
