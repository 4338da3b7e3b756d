"""Parameter trends with the healthy baseline and the alarm band the diagnosis uses (matplotlib, Agg).

The alarm band. A validated parameter ``v`` (standard error ``s``) is diagnosed as drifted against a
reference ``b`` (standard error ``s_b``) when ``|v - b| > z_crit * hypot(s, s_b)`` AND
``|v - b| > min_relative * |b|`` (estimator/diagnosis.py), i.e. when it lies outside

    b +- max(z_crit * hypot(s, s_b), min_relative * |b|).

That interval is drawn per motion: a point outside it is a diagnosed drift, a point inside is not.
The reference ``b`` is the one the diagnosis used for that motion (``drift_reference`` of the motion's
result: the healthy baseline, or the healthy motions so far while the baseline was being learnt);
for a motion that was not diagnosed (the first one, one that was not validated) it is the axis's
healthy baseline as it stands now (``thresholds["baseline"]``), so a reader still sees where the
alarm would be.

``thresholds`` (report.json ``diagnosis_thresholds``)::

    {"alpha", "z_crit", "min_relative": {name: fraction}, "baseline_motions",
     "baseline": {name: {"value", "std"}} or None}
"""
from __future__ import annotations

import datetime as _dt
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from feeddrive.cosim.errors import InputError

if TYPE_CHECKING:
    import matplotlib.pyplot as plt

#: the six monitored parameters and their SI units (a report's own ``unit`` wins when present)
PARAMETERS = (("R", "Ohm"), ("L", "H"), ("K", "N.m/A"), ("Jt", "kg.m2"), ("ft", "N.m.s/rad"), ("Cd", "N.m"))
UNITS = dict(PARAMETERS)
#: a history spanning more than this [s] is plotted against calendar time
DATE_SPAN_S = 86400.0
#: ``plt.subplots``' arguments of :func:`trend_figure` for the DC drive's six (at the figure's own 100 dpi)
TRENDS_LAYOUT = ((3, 2), {"figsize": (11, 8.2), "sharex": True})
#: the order of the trend panels: the DC drive's six with the PMSM's dq inductances and flux in their place; a
#: parameter not named here (a torque offset T0) after them
ORDER = ("R", "L", "L_d", "L_q", "K", "psi_f", "Jt", "ft", "Cd")


def trend_names(series: Mapping) -> list[str]:
    """The parameters of ``trend_series``' result in the panels' and the history table's order (``ORDER``, then the
    others by name)."""
    return [n for n in ORDER if n in series] + sorted(set(series) - set(ORDER))


def trends_layout(n: int) -> tuple[tuple[int, int], dict]:
    """``plt.subplots``' arguments for ``n`` panels, filled column by column: the DC drive's 3 x 2 for six, two
    columns from four (a PMSM's seven: 4 x 2), one column below (a torque-only axis's ft and Cd)."""
    if n == 6:
        return TRENDS_LAYOUT
    cols = 2 if n >= 4 else 1
    rows = -(-n // cols)
    return (rows, cols), {"figsize": (11, max(3.4, 8.2 * rows / 3)), "sharex": True}


def alarm_half_width(std: float | None, ref: Mapping, z_crit: float, min_relative: float) -> float:
    """Half-width of the no-alarm interval around the reference value [parameter unit].

    Parameters
    ----------
    std : float or None
        Standard error of the motion's estimate (None: 0).
    ref : mapping
        ``{"value", "std"}`` of the reference.
    z_crit, min_relative : float
        The drift test's critical value [standard errors] and smallest relative change.
    """
    s = math.hypot(float(std or 0.0), float(ref.get("std") or 0.0))
    return max(z_crit * s, min_relative * abs(float(ref["value"])))


def trend_series(motions: Sequence[Mapping], thresholds: Mapping | None = None) -> dict[str, dict[str, list]]:
    """Per parameter, the points of the trend plot and the alarm band at each of them.

    Parameters
    ----------
    motions : sequence of dict
        Stored motion results (history or report.json ``motions``), oldest first.
    thresholds : mapping or None
        ``diagnosis_thresholds`` (see the module docstring); None: only the motions' own references.

    Returns
    -------
    dict name -> dict of lists
        ``number`` (motion in history order, from 1), ``time`` [s since the epoch] or None, ``value``,
        ``ci_low``, ``ci_high``, ``validated``, ``diagnosed`` (the parameter is in one of the motion's
        diagnoses), ``any_diagnosis`` (the motion has one), ``sensor_fault`` (the motion has a sensor fault or an
        untrusted measurement), ``mismatch`` (its model check rejected the model), ``reference``, ``band_low``,
        ``band_high`` (None where no reference exists).
    """
    thresholds = thresholds or {}
    out: dict[str, dict[str, list]] = {}
    rows = [m for m in motions if m.get("parameters")]
    for k, m in enumerate(rows, 1):
        own = m.get("drift_reference") or {}
        diagnosed = {p for d in m.get("diagnosis") or () for p in d.get("parameters", ())}
        for name, p in m["parameters"].items():
            s = out.setdefault(name, {key: [] for key in ("number", "time", "value", "ci_low", "ci_high", "validated",
                                                          "diagnosed", "any_diagnosis", "sensor_fault", "mismatch",
                                                          "reference", "band_low", "band_high")})
            ref = (own.get("baseline") or {}).get(name)
            z, rel = own.get("z_crit"), (own.get("min_relative") or {}).get(name)
            if ref is None:  # not diagnosed: where the current baseline would put the alarm
                ref = (thresholds.get("baseline") or {}).get(name)
                z, rel = thresholds.get("z_crit"), (thresholds.get("min_relative") or {}).get(name)
            lo, hi = (p.get("ci95") or (None, None))[:2]
            s["number"].append(k)
            s["time"].append(m.get("time"))
            s["value"].append(float(p["value"]))
            s["ci_low"].append(lo)
            s["ci_high"].append(hi)
            s["validated"].append(bool(m.get("validated")))
            s["diagnosed"].append(name in diagnosed)
            s["any_diagnosis"].append(bool(diagnosed))
            s["sensor_fault"].append(bool(m.get("sensor_faults")) or m.get("measurements_valid") is False)
            s["mismatch"].append(isinstance(m.get("mismatch"), Mapping) and m["mismatch"].get("passed") is False)
            if ref is None or z is None or rel is None:
                for key in ("reference", "band_low", "band_high"):
                    s[key].append(None)
                continue
            half = alarm_half_width(p.get("std"), ref, float(z), float(rel))
            s["reference"].append(float(ref["value"]))
            s["band_low"].append(float(ref["value"]) - half)
            s["band_high"].append(float(ref["value"]) + half)
    return out


def use_dates(motions: Sequence[Mapping]) -> bool:
    """True when the motions' machine times span more than a day."""
    times = [m["time"] for m in motions if m.get("time") is not None]
    return bool(times) and max(times) - min(times) > DATE_SPAN_S


def _steps(x: np.ndarray, y: np.ndarray, pad: float) -> tuple[np.ndarray, np.ndarray]:
    """A step curve holding y[j] from halfway to the previous x to halfway to the next (``pad`` at the ends)."""
    mids = (x[1:] + x[:-1]) / 2
    edges = np.concatenate([[x[0] - pad], mids, [x[-1] + pad]])
    return np.repeat(edges, 2)[1:-1], np.repeat(y, 2)


def plot_trends(motions: Sequence[Mapping], path: Path, title: str = "", thresholds: Mapping | None = None,
                x: str = "auto", units: Mapping[str, str] | None = None) -> Path:
    """Draw ``trend_figure`` into ``path`` (PNG); returns ``path``."""
    from feeddrive.cosim.plots import write_png

    # drawn at the figure's own 100 dpi: the layout's renderer is the PNG's
    return write_png(trend_figure(motions, title, thresholds, x, units), path, dpi=100, layout=False)


def trend_figure(motions: Sequence[Mapping], title: str = "", thresholds: Mapping | None = None,
                 x: str = "auto", units: Mapping[str, str] | None = None) -> plt.Figure:
    """Each parameter's value with its 95 % CI, the healthy baseline, the alarm band and the diagnoses.

    Parameters
    ----------
    motions : sequence of dict
        Stored motion results, oldest first (``time`` [s since the epoch] used for dates).
    title : str
        Figure title suffix (e.g. ``axis X``).
    thresholds : mapping or None
        ``diagnosis_thresholds`` (module docstring).
    x : {"auto", "motion", "date"}
        Horizontal axis: motion number in history order, or calendar time (UTC); ``auto``: dates when the
        history spans more than a day.
    units : mapping or None
        Parameter units overriding ``UNITS``.

    Returns
    -------
    matplotlib.figure.Figure
        A panel per parameter with a trend, column by column (``trends_layout``): the DC drive's 3 x 2 (R, L, K |
        Jt, ft, Cd); the caller closes it.
    """
    # matplotlib here, not at the top: report.html reads the trends' data (trend_series) without drawing
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.dates as mdates
    from matplotlib.ticker import MaxNLocator, ScalarFormatter

    series = trend_series(motions, thresholds)
    if not series:
        raise InputError(f"no motion with estimated parameters to plot{' for ' + title if title else ''}")
    dates = use_dates(motions) if x == "auto" else x == "date"
    # the unit stored with the newest motion (a linear axis's Jt is in kg), then the caller's
    stored = {n: p["unit"] for m in motions for n, p in (m.get("parameters") or {}).items()
              if isinstance(p, dict) and p.get("unit")}
    units = {**UNITS, **stored, **(units or {})}
    from feeddrive.cosim.plots import subplots, tight_layout

    # a panel per parameter with a trend: a PMSM's L_d, L_q and psi_f (demagnetisation) among them, no empty one
    # for a parameter the axis never gives (a torque-only axis: ft and Cd)
    names = trend_names(series)
    (rows, cols), layout = trends_layout(len(names))
    fig, axes = subplots(rows, cols, **layout)
    axes = np.asarray(axes, dtype=object).reshape(rows, cols)
    slots = list(axes.T.ravel())  # column by column: R, L, K over Jt, ft, Cd
    for ax in slots[len(names):]:
        ax.set_visible(False)
    for ax, name in zip(slots, names):
        s = series[name]
        if dates:
            xs = mdates.date2num([_dt.datetime.fromtimestamp(t, _dt.timezone.utc) for t in s["time"]])
            # half a motion spacing, but at least 2 % of the span: points at the ends stay visible
            pad = max(0.5 * float(np.median(np.diff(xs))), 0.02 * float(xs[-1] - xs[0])) if len(xs) > 1 else 0.5
        else:
            xs, pad = np.asarray(s["number"], dtype=float), 0.5
        _draw_parameter(ax, xs, s, pad)
        ax.set_ylabel(f"{name} [{units.get(name, '?')}]")
        fmt = ScalarFormatter(useOffset=False)  # "1e-5+1e-1" tick labels read badly
        fmt.set_scientific(False)
        ax.yaxis.set_major_formatter(fmt)
        ax.grid(alpha=0.3)
    # each column's lowest panel carries the time axis (a column one short of the other has its own)
    for ax in (slots[min(len(names), (c + 1) * rows) - 1] for c in range(cols) if c * rows < len(names)):
        ax.tick_params(labelbottom=True)
        if dates:
            loc = mdates.AutoDateLocator()
            ax.xaxis.set_major_locator(loc)
            ax.xaxis.set_major_formatter(mdates.ConciseDateFormatter(loc, tz=_dt.timezone.utc))
            ax.set_xlabel("machine time (UTC)")
        else:
            ax.xaxis.set_major_locator(MaxNLocator(integer=True, min_n_ticks=1))
            ax.set_xlabel("motion number (history order)")
    handles: dict = {}
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(lab, h)
    fig.legend(handles.values(), handles.keys(), loc="lower center", ncol=min(len(handles), 4), fontsize=8,
               frameon=False)
    fig.suptitle(f"parameter trends {title}".strip(), fontsize=11)
    tight_layout(fig, rect=(0, 0.06, 1, 1))  # fig.tight_layout, each panel measured once, not once per pass
    return fig


def _draw_parameter(ax: plt.Axes, xs: np.ndarray, s: Mapping[str, list], pad: float) -> None:
    val = np.asarray(s["value"], dtype=float)
    ref = np.array([np.nan if r is None else r for r in s["reference"]], dtype=float)
    blo = np.array([np.nan if r is None else r for r in s["band_low"]], dtype=float)
    bhi = np.array([np.nan if r is None else r for r in s["band_high"]], dtype=float)
    if np.isfinite(ref).any():
        sx, slo = _steps(xs, blo, pad)
        _, shi = _steps(xs, bhi, pad)
        _, sref = _steps(xs, ref, pad)
        ax.fill_between(sx, slo, shi, color="C2", alpha=0.12, lw=0, label="no alarm (inside the diagnosis thresholds)")
        ax.plot(sx, slo, color="C3", ls="--", lw=0.9, label="alarm threshold")
        ax.plot(sx, shi, color="C3", ls="--", lw=0.9)
        ax.plot(sx, sref, color="C2", lw=1.2, label="healthy baseline")
    lo = np.array([np.nan if v is None else v for v in s["ci_low"]], dtype=float)
    hi = np.array([np.nan if v is None else v for v in s["ci_high"]], dtype=float)
    err = np.vstack([np.clip(val - lo, 0, None), np.clip(hi - val, 0, None)])
    err = np.nan_to_num(err)
    ok = np.asarray(s["validated"], dtype=bool)
    diag = np.asarray(s["diagnosed"], dtype=bool)
    if len(xs) > 1:
        ax.plot(xs, val, color="C0", lw=0.6, alpha=0.6)
    if ok.any():
        ax.errorbar(xs[ok], val[ok], yerr=err[:, ok], fmt="o", color="C0", ms=4, capsize=3, elinewidth=1,
                    label="validated estimate, 95 % CI")
    if (~ok).any():
        ax.errorbar(xs[~ok], val[~ok], yerr=err[:, ~ok], fmt="o", mfc="white", color="0.5", ms=4, capsize=3,
                    elinewidth=1, label="not validated (not diagnosed)")
    if diag.any():
        ax.plot(xs[diag], val[diag], "X", color="C3", ms=9, mec="k", mew=0.5, label="diagnosis")
    for xd in xs[np.asarray(s["any_diagnosis"], dtype=bool)]:  # where a diagnosis occurred, on every panel
        ax.axvline(xd, color="C3", lw=4, alpha=0.12, zorder=0)
    for key, color, marker, label in (("sensor_fault", "C1", "s", "sensor fault"),
                                      ("mismatch", "C4", "D", "model mismatch")):
        flag = np.asarray(s.get(key) or [False] * len(xs), dtype=bool)
        if flag.any():  # on every panel: the estimate of that motion is not what a healthy axis shows
            ax.plot(xs[flag], val[flag], marker, mfc="none", mec=color, mew=1.6, ms=11, ls="none", label=label)
            for xd in xs[flag]:
                ax.axvline(xd, color=color, lw=1.2, ls=":", zorder=0)
    _set_ylim(ax, np.concatenate([lo, val, hi, ref]), blo, bhi)
    ax.set_xlim(xs[0] - pad, xs[-1] + pad)


#: the band is drawn whole when it is at most this many times the data's spread
BAND_ZOOM = 8.0


def _set_ylim(ax: plt.Axes, data: np.ndarray, blo: np.ndarray, bhi: np.ndarray) -> None:
    """Limits from the data and the band together.

    The estimates with their CIs and the baseline always fill a readable part of the axes. The alarm band
    is drawn whole when it is at most ``BAND_ZOOM`` times their spread; a wider band (5 % of R against a CI
    of 0.01 %) would put every estimate on one line, so the scale follows the data and the off-scale
    thresholds are written in the panel.
    """
    lo_d, hi_d = np.nanmin(data, initial=np.inf), np.nanmax(data, initial=-np.inf)
    if not np.isfinite(lo_d) or not np.isfinite(hi_d):
        return
    lo_b, hi_b = np.nanmin(blo, initial=np.inf), np.nanmax(bhi, initial=-np.inf)
    span = hi_d - lo_d if hi_d > lo_d else max(abs(hi_d), 1e-12) * 1e-3
    if np.isfinite(lo_b) and np.isfinite(hi_b) and max(hi_b, hi_d) - min(lo_b, lo_d) <= BAND_ZOOM * span:
        lo_d, hi_d = min(lo_b, lo_d), max(hi_b, hi_d)
        span = hi_d - lo_d
    elif np.isfinite(lo_b) and np.isfinite(hi_b):
        ax.text(0.01, 0.97, f"alarm thresholds {lo_b:.4g} / {hi_b:.4g}: off this scale", transform=ax.transAxes,
                fontsize=7, va="top", color="C3")
    ax.set_ylim(lo_d - 0.15 * span, hi_d + 0.2 * span)
