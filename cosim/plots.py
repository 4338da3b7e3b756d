"""Run plots (matplotlib, Agg): per high-speed motion, the paper's profiles and current residue.

For each high-speed motion (NC ``state == 1``, one ``motion`` index):

* ``motion_<k>_profiles.png``: voltage, current and speed against time (paper Fig. 3 and 8);
* ``motion_<k>_currents.png``: the two current measurements and their residue r = Im1 - Im2
  (paper Fig. 9 and 10).

A figure is drawn only when its signals were recorded.
"""
from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import matplotlib
import matplotlib.text

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from feeddrive.cosim.figure_data import PNG  # noqa: E402
from feeddrive.cosim.figure_jobs import CURRENTS, PROFILES, motions  # noqa: E402, F401 - re-exported
from feeddrive.cosim.plot_workers import PlotWorkers, drawing_processes  # noqa: E402

#: resolution of the run's and the monitor's PNGs [dots per inch]. Their figures are made at it: the layout
#: (tight_layout) and the PNG then share one Agg renderer, and each text is measured once (with the figure's
#: default 100 dpi every text was measured again at 110 dpi when the PNG was drawn)
DPI = 110


def profiles_layout(rows: int) -> tuple[tuple, dict]:
    """``plt.subplots``' arguments of :func:`profiles_figure` with ``rows`` rows."""
    return (rows, 1), {"sharex": True, "figsize": (9, 2.2 * rows + 0.6), "dpi": DPI}


#: ``plt.subplots``' arguments of :func:`currents_figure`
CURRENTS_LAYOUT = ((2, 1), {"sharex": True, "figsize": (9, 5), "dpi": DPI})
#: the figures made at a drawing process's warm-up (:func:`prepare_figures`): layout and major ticks per axis (x, y)
LAYOUTS = ((profiles_layout(3), (9, 6)), (CURRENTS_LAYOUT, (9, 6)))
#: figures made at a drawing process's warm-up, each taken by the first figure of its layout (:func:`subplots`)
_PREPARED: dict[str, list] = {}


def prepare_figures(layouts: Sequence[tuple[tuple[tuple, dict], tuple[int, int]]] = LAYOUTS) -> None:
    """Make a figure of each layout (default: this module's) now, with its axes and their first ticks, for :func:`subplots` to hand out.

    Called by a drawing process while the run simulates (cosim.plot_workers): making the axes and the ticks (each
    tick two lines, a grid line and two texts) was 15 to 25 % of a figure's time, then spent after the simulation.
    A figure made in advance is the one made when asked for: the same calls, the same PNG bytes (the 23 PNGs of a
    tool change, a PMSM run and a current-sensor fault compared); the ticks are laid out from the data as before,
    the first ones made beforehand (``Axis.get_major_ticks`` makes the missing ones, as it copies their style).
    """
    for (args, kwargs), (nx, ny) in layouts:
        fig, axes = plt.subplots(*args, **kwargs)
        for ax in np.ravel(axes):
            ax.xaxis.get_major_ticks(nx)
            ax.yaxis.get_major_ticks(ny)
        _PREPARED.setdefault(_layout_key(args, kwargs), []).append((fig, axes))


def subplots(*args, **kwargs) -> tuple:
    """``plt.subplots(*args, **kwargs)``, or the figure of that layout made by :func:`prepare_figures`."""
    ready = _PREPARED.get(_layout_key(args, kwargs))
    return ready.pop() if ready else plt.subplots(*args, **kwargs)


def _layout_key(args: tuple, kwargs: dict) -> str:
    return repr((args, sorted(kwargs.items())))


def plot_run(time: np.ndarray, signals: Mapping[str, np.ndarray], out_dir: str | Path,
             title: str = "") -> list[Path]:
    """Draw the figures of a run into ``out_dir`` (created); returns the files written.

    Parameters
    ----------
    time : ndarray, shape (n,)
        Sample times [s].
    signals : mapping name -> ndarray, shape (n,)
        Recorded signals (``component.port``).
    out_dir : path
        Directory for the PNG files.
    title : str
        Prefix of the figure titles (the scenario name).
    """
    from feeddrive.cosim.figure_jobs import run_figure_jobs

    return [path for job in run_figure_jobs(time, signals, out_dir, title) for path in job()]


def profiles_figure(k: int, traces: Mapping[str, tuple[np.ndarray, np.ndarray]], path: Path, title: str = ""
                    ) -> list[Path]:
    """Voltage, current and speed of high-speed motion ``k`` against time (paper Fig. 3 and 8) into ``path``.

    Parameters
    ----------
    k : int
        The motion's index.
    traces : mapping name -> (t, y)
        The motion's recorded signals as drawn (``run_figure_jobs``: their envelopes): times [s] and values,
        shape (m,) each.
    path : Path
        The PNG file.
    title : str
        Prefix of the title (the scenario name).

    Returns
    -------
    list of Path
        ``[path]``, or ``[]`` when none of the signals was recorded.
    """
    rows = [(label, unit, [s for s in names if s in traces]) for label, unit, names in PROFILES]
    rows = [(label, unit, names[0], names[-1]) for label, unit, names in rows if names]
    if not rows:
        return []
    args, kwargs = profiles_layout(len(rows))
    fig, axes = subplots(*args, **kwargs)
    for ax, (label, unit, measured, true) in zip(np.atleast_1d(axes), rows):
        ax.plot(*traces[measured], lw=0.6, label=measured)
        if true != measured:
            ax.plot(*traces[true], lw=0.9, label=true)
        ax.set_ylabel(f"{label} [{unit}]")
        ax.grid(alpha=0.3)
        _legend_outside(ax)
    np.atleast_1d(axes)[-1].set_xlabel("time [s]")
    fig.suptitle(f"{title} high-speed motion {k}: voltage, current and speed")
    return [_save(fig, path)]


def currents_figure(k: int, traces: Mapping[str, tuple[np.ndarray, np.ndarray]], residue_mean: float | None,
                    path: Path, title: str = "") -> list[Path]:
    """The two current measurements of high-speed motion ``k`` and their residue r = Im1 - Im2 (paper
    Fig. 9 and 10) into ``path``; ``traces`` as :func:`profiles_figure`, with ``residue``: r's envelope [A],
    and ``residue_mean``: r's mean over every sample [A] (``[]``: a sensor is missing)."""
    if not all(name in traces for name in CURRENTS) or "residue" not in traces:
        return []
    fig, (ax1, ax2) = subplots(*CURRENTS_LAYOUT[0], **CURRENTS_LAYOUT[1])
    ax1.plot(*traces[CURRENTS[0]], lw=0.6, label="Im1")
    ax1.plot(*traces[CURRENTS[1]], lw=0.6, label="Im2")
    ax1.set_ylabel("current [A]")
    _legend_outside(ax1)
    ax2.plot(*traces["residue"], lw=0.6, color="C3")
    ax2.axhline(residue_mean, color="k", lw=0.8, ls="--", label="mean")
    ax2.set_ylabel("residue Im1 - Im2 [A]")
    ax2.set_xlabel("time [s]")
    _legend_outside(ax2)
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    fig.suptitle(f"{title} high-speed motion {k}: redundant current sensors")
    return [_save(fig, path)]


def draw_concurrently(jobs: Sequence[Callable[[], list[Path]]], processes: int | None = None) -> list[Path]:
    """Run figure-drawing ``jobs`` at the same time; returns their files, in the order of ``jobs``.

    The run's mechanism (:class:`cosim.plot_workers.PlotWorkers`), forked now that the jobs exist: the
    workers inherit the jobs, the data and the imported matplotlib (nothing is pickled but the lists of files
    written, and the figures are the same as drawn one after the other), and this process draws its share
    too. Without ``fork`` (not POSIX) or in a daemonic process the jobs run here in turn; a worker that
    dies without a result has its job drawn again here. An exception of a job is raised here.

    Parameters
    ----------
    jobs : sequence of callables
        Each draws its figures and returns the list of files it wrote.
    processes : int or None
        Processes drawing at once, this one included (default: ``$FEEDDRIVE_PLOT_PROCESSES``, else the
        number of CPUs; a campaign sets 1, its runs already use every CPU).
    """
    k = min(max(1, len(jobs)), drawing_processes(processes))
    with PlotWorkers(k, jobs=jobs, here=True, warm=False) as workers:
        return workers.draw(jobs)


def tight_layout(fig: plt.Figure, **kwargs) -> None:
    """``fig.tight_layout(**kwargs)`` with each Axes' extent measured once.

    With ``rect`` (the trends' room for the figure's legend), matplotlib computes the margins twice from the Axes'
    extents, which do not change in between (the Axes are placed after): each tick label, axis label and title was
    measured twice, 12 % of the trends figure's time. The extents of the first pass are reused: the same layout.
    """
    for ax in fig.axes:
        ax.get_tightbbox = functools.partial(_tightbbox_once, ax.get_tightbbox, {})
    try:
        fig.tight_layout(**kwargs)
    finally:
        for ax in fig.axes:
            del ax.get_tightbbox  # the method again


def _tightbbox_once(get: Callable, seen: dict, *args, **kwargs):  # noqa: ANN202 - a Bbox or None
    try:
        key = (tuple(map(id, args)), tuple(sorted(kwargs.items())))
        hash(key)
    except TypeError:  # e.g. a list of extra artists: measured each time
        return get(*args, **kwargs)
    if key not in seen:
        seen[key] = get(*args, **kwargs)
    return seen[key]


def wrapped(text: matplotlib.text.Text) -> matplotlib.text.Text:
    """``text`` (made with ``wrap=True``) wrapped as matplotlib wraps it, with fewer measurements; returns ``text``.

    matplotlib breaks a line after the most words that fit the width it allows (``Text._get_wrap_line_width``),
    measuring the line with one more word at a time, at each layout of the text: the long titles of the monitor's
    figure (a decision and its numbers) were measured 126 times, 9 % of that figure's time. The width of a line
    grows with its words, so the most that fit is found by bisection (a few measurements a line): the same lines.
    Without those (private) methods, matplotlib's own wrapping is kept.
    """
    if not (callable(getattr(text, "_get_wrap_line_width", None))
            and callable(getattr(text, "_get_rendered_text_width", None))):
        return text
    text._get_wrapped_text = functools.partial(_wrapped_text, text)
    return text


def _wrapped_text(text: matplotlib.text.Text) -> str:
    """``Text._get_wrapped_text`` of matplotlib (3.7 to 3.11) with a bisection for each line's last word."""
    if not text.get_wrap() or text.get_usetex():
        return text.get_text()
    width, measure = text._get_wrap_line_width(), text._get_rendered_text_width
    lines = []
    for line in text.get_text().split("\n"):  # the text's own line breaks stay
        words = line.split(" ")
        while words:
            fit, wide = 1, len(words) + 1  # the first word always starts a line; all words may fit
            while wide - fit > 1:  # invariant: the first `fit` words fit (or fit == 1), the first `wide` do not
                mid = (fit + wide) // 2
                if measure(" ".join(words[:mid])) > width:
                    wide = mid
                else:
                    fit = mid
            lines.append(" ".join(words[:fit]))
            words = words[fit:]
    return "\n".join(lines)


def _legend_outside(ax: plt.Axes) -> None:
    """The legend right of the axes, off the traces."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=7, frameon=False)


def _save(fig: plt.Figure, path: Path) -> Path:
    for ax in fig.axes:  # plain tick labels: an offset ("1e-5+1e-1") reads badly
        ax.ticklabel_format(useOffset=False, style="plain")
    return write_png(fig, path)


def write_png(fig: plt.Figure, path: Path, dpi: float = DPI, layout: bool = True) -> Path:
    """Lay ``fig`` out (``tight_layout``; ``layout=False``: done already) and write it to ``path`` (PNG at ``dpi``,
    the parent folder made); the figure is closed. Returns ``path``.

    ``tight_layout`` leaves a placeholder layout engine on the figure, for which ``savefig`` lays every artist out
    once more (ticks, texts, legends) before drawing it, to the same pixels: the engine is dropped first. With
    :data:`DPI`, the 5 figures of examples/tool_change.yaml took 22 % less CPU time (2.83 -> 2.20 s, best of 6,
    each drawn once in a fresh drawing process).
    """
    from matplotlib.layout_engine import PlaceHolderLayoutEngine

    path.parent.mkdir(parents=True, exist_ok=True)
    if layout:
        fig.tight_layout()
    if isinstance(fig.get_layout_engine(), PlaceHolderLayoutEngine):
        with matplotlib.rc_context({"figure.autolayout": False, "figure.constrained_layout.use": False}):
            fig.set_layout_engine(None)  # None, not an engine that the rc settings would name
    fig.savefig(path, dpi=dpi, pil_kwargs=dict(PNG))
    plt.close(fig)
    return path
