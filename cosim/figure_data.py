"""What the figures draw, without matplotlib: long traces as their min/max envelope at the figure's width
(:func:`envelope`, for every figure of a run) and the monitor's figures' data of one processed motion
(:class:`MotionFigure`, drawn by cosim.monitor_plots).

A :class:`cosim.monitor_pipeline.MotionTrace` holds every sample of the motion (MB on a 10 kHz axis); the
figures draw each long series as its min/max envelope at the figure's width (:func:`envelope`).
:func:`motion_figure` reduces the trace to that where the trace is, so a drawing process is sent kB and the
figure is the one drawn from the whole trace. The results of the estimator become plain namespaces with the
values the figures read: a drawing process unpickles them without importing the estimator (and scipy).
"""
from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np

#: PNG options of every figure (``savefig(..., pil_kwargs=PNG)``): zlib level 3 instead of Pillow's 6 encodes the
#: same pixels in 60 % of the time (5 figures of a tool change: 0.55 -> 0.34 s) into 9 % more bytes
PNG = {"compress_level": 3}

#: samples drawn per trace at most, as min/max pairs: the figures' width in pixels (9 in at 110 dpi: 990)
DISPLAY_BUCKETS = 1000


def envelope(t: np.ndarray, y: np.ndarray, buckets: int = DISPLAY_BUCKETS) -> tuple[np.ndarray, np.ndarray]:
    """The samples of a long trace that a figure can show: the first and last, and the minimum and maximum
    of each of ``buckets`` runs of consecutive samples, in time order.

    A line through them covers the same pixels as the whole trace at a width of ``buckets`` pixels or less:
    a one-sample spike is kept at its time and value. Agg's rendering of a 35 000-sample trace was a third
    of a figure's time, and sending the whole traces to the drawing processes 0.8 s of a run. Shorter
    traces are returned whole.

    Parameters
    ----------
    t, y : ndarray, shape (n,)
        Times [s] and values of the trace.
    buckets : int
        Number of runs (at least the drawing's width in pixels).

    Returns
    -------
    t, y : ndarray, shape (m,), m <= 2 * buckets + 2 + n % buckets
    """
    y = np.asarray(y)
    n = y.shape[0]
    size = n // buckets
    if size < 3:  # no fewer samples to draw
        return np.asarray(t), y
    head = y[: size * buckets].reshape(buckets, size)
    offsets = np.arange(buckets) * size
    keep = np.concatenate(([0], offsets + np.argmin(head, axis=1), offsets + np.argmax(head, axis=1),
                           np.arange(size * buckets, n), [n - 1]))
    keep = np.unique(keep)
    return np.asarray(t)[keep], y[keep]



@dataclass(frozen=True)
class MotionFigure:
    """The data of ``monitor_motion<k>.png`` and ``monitor_correlation<k>.png``.

    Attributes
    ----------
    motion : int
    lines : dict name -> (t, y)
        Each long series as its envelope: times [s] and values, shape (m,). ``r``: the current residue
        Im1 - Im2 [A] (absent with one current sensor); per check of the model (``current``, ``speed``, or a
        model's ``i_q``, ``i_d``, ``w``): ``<name> measured`` (filtered), ``<name> simulated``, ``<name> residue``.
    windows : ndarray, shape (n_windows,) or None
        Times [s] of the current residue's windows (``residue.centers`` at the motion's sample spacing).
    residue : SimpleNamespace or None
        The current pair's window test (``estimator.validation.ResidueTest``): ``kind``, ``means``, ``levels``
        (one value per window), ``offset``, ``gain_diff``.
    mismatch : SimpleNamespace or None
        The model check (``estimator.mismatch.MismatchResult``): ``test``, ``statistic``, ``p_value``, ``alpha``,
        ``passed`` and ``checks``: name -> ``signal``, ``rms``, ``noise_std``, ``tests`` (name -> ``p_value``),
        ``correlation``, ``band`` and ``inputs`` (the names of the correlated inputs); the per-sample
        ``simulated`` and ``residue`` are in ``lines``.
    result : dict
        The motion's result (report.json ``motions[k]``).
    """

    motion: int
    lines: dict[str, tuple[np.ndarray, np.ndarray]]
    windows: np.ndarray | None
    residue: Any
    mismatch: Any
    result: dict


def motion_figure(trace: Any) -> MotionFigure:
    """The figures' data of ``trace`` (``cosim.monitor_pipeline.MotionTrace``); a MotionFigure is returned as is."""
    if isinstance(trace, MotionFigure):
        return trace
    t = np.asarray(trace.t)
    lines = {}
    im1, im2 = trace.signals.get("Im1"), trace.signals.get("Im2")
    if im1 is not None and im2 is not None:
        lines["r"] = envelope(t, np.asarray(im1) - np.asarray(im2))
    elif im1 is not None or im2 is not None:  # one current sensor: its signal drawn where the pair's residue is
        lines["current"] = envelope(t, np.asarray(im1 if im1 is not None else im2))
    elif trace.signals.get("torque") is not None and trace.signals.get("torque_ref") is not None:  # the torque pair
        lines["r torque"] = envelope(t, np.asarray(trace.signals["torque"]) - np.asarray(trace.signals["torque_ref"]))
    elif trace.signals.get("torque") is not None:  # a torque signal instead of a current
        lines["torque"] = envelope(t, np.asarray(trace.signals["torque"]))
    v, res, windows = trace.validation, None, None
    if v is not None and v.pairs["current"].residue is not None:
        r = v.pairs["current"].residue
        windows = t[0] + r.centers * (t[1] - t[0])
        res = SimpleNamespace(kind=r.kind, means=r.means, levels=r.levels, offset=r.offset, gain_diff=r.gain_diff)
    mm, shown = trace.mismatch, None
    if mm is not None:
        from feeddrive.estimator.mismatch import INPUTS  # loaded with the monitor that made the trace

        checks = {}
        for name, check in mm.checks.items():
            lines[f"{name} measured"] = envelope(t, check.simulated + check.residue)
            lines[f"{name} simulated"] = envelope(t, check.simulated)
            lines[f"{name} residue"] = envelope(t, check.residue)
            inputs = INPUTS.get(name) or [f"{j + 1}" for j in range(check.correlation.shape[1])]  # a model's own
            checks[name] = SimpleNamespace(
                signal=check.signal, rms=check.rms, noise_std=check.noise_std, correlation=check.correlation,
                band=check.band, inputs=list(inputs), tests={k: SimpleNamespace(p_value=r.p_value)
                                                             for k, r in check.tests.items()})
        shown = SimpleNamespace(test=mm.test, statistic=mm.statistic, p_value=mm.p_value, alpha=mm.alpha,
                                passed=mm.passed, checks=checks)
    return MotionFigure(trace.motion, lines, windows, res, shown, trace.result)
