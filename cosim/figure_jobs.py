"""The figures a run draws, as jobs for the drawing processes (cosim.plot_workers): which function draws what.

A :class:`FigureJob` names its drawing function (found by name where it runs: pickling a job does not import
matplotlib in the run's process) and holds what the figure draws, each long trace as its envelope
(cosim.figure_data): tens of kB to send, not the motion's MB. :func:`run_figure_jobs` makes the run's figures
(cosim.plots), per high-speed motion, :func:`monitor_figure_jobs` the monitor's (cosim.monitor_plots).
"""
from __future__ import annotations

import importlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from feeddrive.cosim.figure_data import envelope, motion_figure

#: the modules of the run's figures (:class:`FigureJob`), loaded by the drawing processes at their start
FIGURE_MODULES = ("feeddrive.cosim.plots", "feeddrive.cosim.monitor_plots")
#: the figures of a run, per high-speed motion: (file name, drawing function of cosim.plots, cost)
RUN_FIGURES = (("motion_{k}_profiles.png", "profiles_figure", 3.0), ("motion_{k}_currents.png", "currents_figure", 2.0))
#: rows of the profiles figure: (label, unit, candidate signals in order of preference: measured first)
PROFILES = (("voltage u", "V", ("sensors.u", "plant.voltage")),
            ("current i", "A", ("sensors.Im2", "sensors.Im1", "plant.current")),
            ("speed w", "rad/s", ("sensors.w_tach", "plant.speed")))
#: the redundant current sensors of the currents figure
CURRENTS = ("sensors.Im1", "sensors.Im2")


@dataclass(frozen=True)
class FigureJob:
    """One figure (or a few) drawn by ``module.function(*args)``, which returns the file(s) it wrote.

    The function is found by name where the job runs: pickling the job does not import its module (and
    matplotlib) in the run's process. ``cost`` is the figure's drawing time relative to the others' (about
    its number of panels and texts): the costliest are sent first, so that the workers end together.
    """

    module: str
    function: str
    args: tuple = ()
    cost: float = 1.0

    def __call__(self) -> list[Path]:
        out = getattr(importlib.import_module(self.module), self.function)(*self.args)
        return [out] if isinstance(out, Path) else list(out)


@dataclass(frozen=True)
class FigureBatch:
    """Figures drawn one after the other by one process (a motion's run figures, sent while the simulation
    runs: one drawing process beside it, not two); returns their files in order."""

    jobs: tuple[FigureJob, ...]

    @property
    def cost(self) -> float:
        return sum(job.cost for job in self.jobs)

    def __call__(self) -> list[Path]:
        return [path for job in self.jobs for path in job()]


def motions(signals: Mapping[str, np.ndarray], only: int | None = None) -> dict[int, np.ndarray]:
    """``motion index -> sample indices`` of each high-speed motion (NC state 1), from nc.state/nc.motion; of
    motion ``only`` alone when given (one pass over the record, not one per motion: it is asked at each motion's
    end while the run goes on)."""
    if "nc.state" not in signals or "nc.motion" not in signals:
        return {}
    state, motion = signals["nc.state"], signals["nc.motion"]
    rapid = state == 1
    if only is not None:
        idx = np.flatnonzero(rapid & (motion == only))
        return {int(only): idx} if idx.size else {}
    return {int(k): np.flatnonzero(rapid & (motion == k)) for k in np.unique(motion[rapid])}


def run_figure_jobs(time: np.ndarray, signals: Mapping[str, np.ndarray], folder: str | Path,
                    title: str = "", only: int | None = None, done: Mapping[int, Sequence] | None = None) -> list:
    """The run's figures (cosim.plots) as jobs, each with what it draws of its motion: every trace already reduced
    to its min/max envelope at the figure's width (:func:`envelope`), so a job is tens of kB, not MB.

    Parameters
    ----------
    time : ndarray, shape (n,)
        Sample times [s].
    signals : mapping name -> ndarray, shape (n,)
        Recorded signals (``component.port``).
    folder : path
        Directory of the PNG files.
    title : str
        Prefix of the figure titles (the scenario name).
    only : int or None
        Only this motion's jobs (sent while the run goes on, :meth:`PlotWorkers.submit`).
    done : mapping motion -> jobs, or None
        Motions whose jobs were made already: those are put in their place instead.
    """
    folder = Path(folder)
    wanted = [name for _, _, names in PROFILES for name in names] + list(CURRENTS)
    jobs: list = []
    for k, idx in motions(signals, only).items():
        if idx.size < 2:
            continue
        if done and k in done:
            jobs += done[k]
            continue
        t = time[idx]
        part = {name: signals[name][idx] for name in wanted if name in signals}
        traces = {name: envelope(t, y) for name, y in part.items()}
        args = {"profiles_figure": (k, traces), "currents_figure": (k, traces, None)}
        if all(name in part for name in CURRENTS):  # the residue and its mean from every sample
            residue = part[CURRENTS[0]] - part[CURRENTS[1]]
            args["currents_figure"] = (k, traces | {"residue": envelope(t, residue)}, float(np.mean(residue)))
        for pattern, function, cost in RUN_FIGURES:
            path = folder / pattern.format(k=k)
            jobs.append(FigureJob("feeddrive.cosim.plots", function, (*args[function], path, title), cost))
    return jobs


def monitor_figure_jobs(traces: Sequence, motions: Sequence[Mapping], folder: str | Path,
                        thresholds: Mapping | None = None) -> list[FigureJob]:
    """The monitor's figures (cosim.monitor_plots) as jobs: ``monitor_motion<k>.png`` and
    ``monitor_correlation<k>.png`` of each kept trace, ``monitor_trends.png`` of the axis."""
    folder = Path(folder)
    module = "feeddrive.cosim.monitor_plots"
    # what the figures draw of each trace: its long series as envelopes (kB to send, not the motion's MB)
    shown = [motion_figure(tr) for tr in traces]
    # costs measured against the run's figures (cosim.plots): 4 and 2 panels, and 6 panels for the trends
    jobs = [FigureJob(module, "plot_motion", (f, folder / f"monitor_motion{f.motion}.png"), 6.0) for f in shown]
    jobs += [FigureJob(module, "plot_correlation", (f, folder / f"monitor_correlation{f.motion}.png"), 4.0)
             for f in shown if f.mismatch is not None]
    if any(m.get("parameters") for m in motions):
        axis = motions[-1].get("axis")
        jobs.append(FigureJob(module, "plot_trends", (list(motions), folder / "monitor_trends.png",
                                                      f"axis {axis}" if axis else "", thresholds), 6.0))
    return jobs
