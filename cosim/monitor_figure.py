"""What the monitor's figures draw of one processed motion, without matplotlib (cosim.monitor_plots draws it).

A :class:`cosim.monitor_pipeline.MotionTrace` holds every sample of the motion (MB on a 10 kHz axis); the
figures draw each long series as its min/max envelope at the figure's width (``cosim.plot_workers.envelope``).
:func:`motion_figure` reduces the trace to that where the trace is, so a drawing process is sent kB and the
figure is the one drawn from the whole trace.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from feeddrive.cosim.plot_workers import envelope


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
    residue : estimator.validation.ResidueTest or None
        The current pair's window test (small: one value per window).
    mismatch : estimator.mismatch.MismatchResult or None
        The model check, its checks without their per-sample ``simulated`` and ``residue`` (in ``lines``).
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
    v, res, windows = trace.validation, None, None
    if v is not None and v.pairs["current"].residue is not None:
        res = v.pairs["current"].residue
        windows = t[0] + res.centers * (t[1] - t[0])
    mm = trace.mismatch
    if mm is not None:
        for name, check in mm.checks.items():
            lines[f"{name} measured"] = envelope(t, check.simulated + check.residue)
            lines[f"{name} simulated"] = envelope(t, check.simulated)
            lines[f"{name} residue"] = envelope(t, check.residue)
        mm = replace(mm, checks={name: replace(check, simulated=None, residue=None) for name, check in mm.checks.items()})
    return MotionFigure(trace.motion, lines, windows, res, mm, trace.result)
