"""Plots of the monitor (matplotlib, Agg backend).

* per motion: the current residue ``Im1 - Im2`` with its window means (paper Fig. 9, 10), the
  measured and model-simulated current (Fig. 12), the measured and simulated speed and the residues
  against the sensor noise, titled with the test that decided (Fig. 13, 14); the correlation of the
  residues with past inputs and its band (``monitor_correlation<k>.png``, as MATLAB's ``resid``);
* per axis: each parameter's trend over the motions with its 95 % confidence interval, the healthy
  baseline and the diagnosis' alarm band (cosim/trends.py).
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from feeddrive.cosim.figure_data import motion_figure  # noqa: E402
from feeddrive.cosim.figure_jobs import monitor_figure_jobs  # noqa: E402
from feeddrive.cosim.plots import DPI, draw_concurrently, subplots, wrapped, write_png  # noqa: E402
from feeddrive.cosim.plots import prepare_figures as _prepare  # noqa: E402
from feeddrive.cosim.trends import PARAMETERS, TRENDS_LAYOUT  # noqa: E402, F401 - re-exported
from feeddrive.cosim.trends import plot_trends as _plot_trends  # noqa: E402
from feeddrive.estimator.pvalue_text import p_text  # noqa: E402


def motion_layout(panels: int) -> tuple[tuple, dict]:
    """``plt.subplots``' arguments of :func:`plot_motion` with ``panels`` panels."""
    return (panels, 1), {"figsize": (9, 2.4 * panels), "sharex": True, "squeeze": False, "dpi": DPI}


def correlation_layout(checks: int) -> tuple[tuple, dict]:
    """``plt.subplots``' arguments of :func:`plot_correlation` with ``checks`` residues."""
    return (1, checks), {"figsize": (10, 3.2), "squeeze": False, "dpi": DPI}


#: the figures made at a drawing process's warm-up (cosim.plots.prepare_figures): a DC drive's motion (4 panels) and
#: correlation (2 residues: current, speed), and the trends
LAYOUTS = ((motion_layout(4), (9, 6)), (correlation_layout(2), (8, 7)), (TRENDS_LAYOUT, (4, 7)))


def prepare_figures(layouts: Sequence = LAYOUTS) -> None:
    """This module's figures made in advance by a drawing process (cosim.plots.prepare_figures)."""
    _prepare(layouts)


def plot_motion(trace, path: Path) -> Path:
    """One motion's validation and model check into ``path`` (PNG).

    ``trace``: ``cosim.monitor_pipeline.MotionTrace``, or what the figure draws of it
    (``cosim.figure_data.MotionFigure``: its long series as envelopes, what a drawing process is sent)."""
    shown = motion_figure(trace)
    lines, mm = shown.lines, shown.mismatch
    generic = mm is not None and "current" not in mm.checks  # a model's own equations (the PMSM's i_q, i_d, w)
    panels = 1 + (mm is not None) * (len(mm.checks) if generic else 3)
    args, kwargs = motion_layout(panels)
    fig, axes = subplots(*args, **kwargs)
    axes = axes[:, 0]
    ylabel = "residue [A]"
    if "r" in lines:
        axes[0].plot(*lines["r"], lw=0.3, color="0.6", label="r = Im1 - Im2")
    elif "r torque" in lines:  # a torque measurement and the drive's command (cosim monitor --map torque_ref=...)
        ylabel = "residue [N.m]"
        axes[0].plot(*lines["r torque"], lw=0.3, color="0.6", label="r = torque - torque_ref")
        fault = next((f for f in shown.result.get("sensor_faults") or () if str(f.get("sensor")).startswith("torque")),
                     None)
        wrapped(axes[0].set_title("torque pair: " + (f"sensor fault, {fault['kind']} (not isolated)" if fault else
                                                     "agree"), fontsize=8, wrap=True))
    else:  # one current sensor or a torque signal: the pair is not checked, and the panel says so over the signal
        why = shown.result.get("not_checked", {}).get("current", "not checked")
        single = next((n for n in ("current", "torque") if n in lines), None)
        if single is None:
            axes[0].text(0.5, 0.5, f"current residue: {why}", transform=axes[0].transAxes, ha="center", va="center")
        else:  # the motion's one signal (the panel was an empty 0-1 axes with this sentence)
            ylabel = f"{single} [{'A' if single == 'current' else 'N.m'}]"
            axes[0].plot(*lines[single], lw=0.5, color="C0", label=f"{single}, one sensor")
            wrapped(axes[0].set_title(f"current residue: {why}", fontsize=8, wrap=True))
    if shown.residue is not None:
        res, tw = shown.residue, shown.windows
        axes[0].step(tw, res.means, where="mid", color="C0", label=f"window means ({res.kind})")
        axes[0].plot(tw, res.offset + res.gain_diff * res.levels, "C3--", lw=1, label="offset + gain diff x level")
    axes[0].set_ylabel(ylabel)
    if axes[0].get_legend_handles_labels()[0]:
        _legend_outside(axes[0])
    if generic:
        _plot_equations(axes[1:], lines, mm, shown.result)
    elif mm is not None:
        cur, speed = mm.checks["current"], mm.checks["speed"]
        axes[1].plot(*lines["current measured"], label="measured (filtered)")
        axes[1].plot(*lines["current simulated"], "--", label="simulated from the estimated model")
        axes[1].set_ylabel("current [A]")
        axes[2].plot(*lines["speed measured"], label="measured (filtered)")
        axes[2].plot(*lines["speed simulated"], "--", label="simulated on each constant-sign segment")
        axes[2].set_ylabel("speed [rad/s]")
        for ax, (name, check), unit, color in ((axes[3], ("speed", speed), "rad/s", "C3"),
                                               (axes[3].twinx(), ("current", cur), "A", "C0")):
            ax.plot(*lines[f"{name} residue"], color=color, lw=0.6, label=f"{check.signal} residue [{unit}]")
            if np.isfinite(check.noise_std):
                ax.axhline(check.noise_std, color=color, ls=":", lw=0.8)
                ax.axhline(-check.noise_std, color=color, ls=":", lw=0.8)
            ax.set_ylabel(f"{check.signal} residue [{unit}]", color=color)
        wrapped(axes[3].set_title(decision_text(mm), fontsize=8, wrap=True))
        for ax in axes[1:3]:
            _legend_outside(ax)
        handles = [h for a in (axes[3], *fig.axes[len(axes):]) for h in a.get_legend_handles_labels()[0]]
        axes[3].legend(handles, [h.get_label() for h in handles], loc="upper left", bbox_to_anchor=(1.12, 1),
                       fontsize=7, frameon=False)
    axes[-1].set_xlabel("time [s]")
    from feeddrive.cosim.report.verdict import verdict_line

    wrapped(fig.suptitle(f"motion {shown.motion}: {verdict_line(shown.result)}", fontsize=10, wrap=True))
    return write_png(fig, path)


def _plot_equations(axes, lines: dict, mm, result: dict) -> None:  # noqa: ANN001 - MismatchResult
    """Paper Fig. 13, 14 for any model's check (``estimator.model_check``: the PMSM's q and d currents and speed):
    per simulated state, the measured and simulated signal and, on the right axis, the residue with +- the
    sensor noise. On a PMSM the check is advisory (report.json ``output_error_check.deciding``): said so."""
    units = {"w": "rad/s"}
    for ax, (name, check) in zip(axes, mm.checks.items()):
        unit = units.get(name, "A")
        ax.plot(*lines[f"{name} measured"], label=f"{name} measured (filtered)")
        ax.plot(*lines[f"{name} simulated"], "--", label=f"{name} simulated from the estimated model")
        ax.set_ylabel(f"{name} [{unit}]")
        right = ax.twinx()
        right.plot(*lines[f"{name} residue"], color="C3", lw=0.6, label=f"{name} residue")
        if np.isfinite(check.noise_std):
            for y in (check.noise_std, -check.noise_std):
                right.axhline(y, color="C3", ls=":", lw=0.8)
        right.set_ylabel(f"residue [{unit}]", color="C3")
        handles = ax.get_legend_handles_labels()[0] + right.get_legend_handles_labels()[0]
        ax.legend(handles, [h.get_label() for h in handles], loc="upper left", bbox_to_anchor=(1.08, 1), fontsize=7,
                  frameon=False)
    deciding = (result.get("output_error_check") or {}).get("deciding", True)
    wrapped(axes[-1].set_title(decision_text(mm) + ("" if deciding else "\n(advisory: the residue check decides)"),
                               fontsize=8, wrap=True))


def _legend_outside(ax: plt.Axes) -> None:
    """The legend right of the axes, off the traces."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=7, frameon=False)


def _noise_text(check) -> str:  # noqa: ANN001 - estimator.mismatch.SignalCheck
    """``RMS 0.03 vs noise 0.05``, or why the noise is unknown (never ``nan``)."""
    rms = f"RMS {check.rms:.3g}" if np.isfinite(check.rms) else "RMS not computed"
    if np.isfinite(check.noise_std):
        return f"{rms} vs noise {check.noise_std:.3g}"
    return f"{rms}, noise not checked: no confirmed redundant {'current' if check.signal == 'current' else 'speed'} pair"


def decision_text(mm) -> str:
    """What decided the model check: the deciding test, its statistic and p-value against alpha, and for
    each residue its RMS (nuisance removed) against the sensor noise (dotted lines: +- that noise)."""
    size = "; ".join(f"{k} {_noise_text(c)}" for k, c in mm.checks.items())
    symbol = "max |z|" if mm.test.endswith("peak") else "F"  # the peak test's statistic is in MAD units
    m = sum(len(c.tests) for c in mm.checks.values())
    return (f"{'passed' if mm.passed else 'MISMATCH'}: {mm.test} {symbol} = {mm.statistic:.3g}, Bonferroni-adjusted p = "
            f"{mm.p_value:.3g} {'>=' if mm.passed else '<'} alpha = {mm.alpha:g} ({m} tests)\n{size}")


def plot_correlation(trace, path: Path) -> Path:
    """Correlation of each prewhitened residue with each prewhitened input against the lag, with the band
    of independence at the check's level (as MATLAB's ``resid``), into ``path`` (PNG); ``trace`` as
    :func:`plot_motion`."""
    trace = motion_figure(trace)
    mm = trace.mismatch
    args, kwargs = correlation_layout(len(mm.checks))
    fig, axes = subplots(*args, **kwargs)
    for ax, (name, check) in zip(axes[0], mm.checks.items()):
        lags = np.arange(check.correlation.shape[0])
        for j, x in enumerate(check.inputs):  # a model's own check: 1, 2, ...
            ax.stem(lags + 0.15 * j, check.correlation[:, j], linefmt=f"C{j}-", markerfmt=f"C{j}o",
                    basefmt=" ", label=f"input {x}")
        ax.axhspan(-check.band, check.band, color="0.9", zorder=0, label=f"{100 * (1 - mm.alpha):g} % band")
        for y in (-check.band, check.band):  # the band's edges, inside the axes: limits from the data and the band
            ax.axhline(y, color="0.4", ls="--", lw=0.8)
        top = max(float(np.nanmax(np.abs(check.correlation), initial=0.0)), float(check.band))
        ax.set_ylim(-1.35 * top, 1.35 * top)
        p = check.tests["independence"].p_value
        ax.set_title(f"{name} residue vs past inputs: F-test {p_text(p)}", fontsize=8)
        ax.set_xlabel("lag [blocks of 20 ms]")
        _legend_outside(ax)
    axes[0, 0].set_ylabel("correlation")
    fig.suptitle(f"motion {trace.motion}: residue-input correlation", fontsize=10)
    return write_png(fig, path)


def plot_trends(motions: Sequence[dict], path: Path, title: str = "", thresholds: dict | None = None,
                x: str = "auto") -> Path:
    """Each parameter's trend with its 95 % CI, healthy baseline and alarm band (``cosim.trends.plot_trends``)."""
    return _plot_trends(motions, path, title, thresholds, x)


def plot_monitor(traces: Sequence, motions: Sequence[dict], folder: Path, thresholds: dict | None = None
                 ) -> list[Path]:
    """``monitor_motion<k>.png`` for each kept trace and ``monitor_trends.png`` into ``folder``.

    ``thresholds``: the diagnosis thresholds and healthy baseline of the trends' alarm band
    (``MonitorPipeline.thresholds()``).
    """
    folder.mkdir(parents=True, exist_ok=True)
    # one job per figure, drawn at the same time in forked processes (cosim.plots.draw_concurrently)
    return draw_concurrently(monitor_figure_jobs(traces, motions, folder, thresholds))
