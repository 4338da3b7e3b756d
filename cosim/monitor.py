"""The monitor: the paper's Fig. 4 as a co-simulation component (and as a pipeline on recorded data).

For every high-speed motion without machining (NC ``state == 1``, one ``motion`` index), the
monitor buffers the redundant measurements and, when the motion ends, runs in order:

    filtering (eq. 8) -> measurement validation (Fig. 5, 6) -> estimation (eq. 4, 5)
    -> model validation (IV.B.3) -> diagnosis (Table I) -> history (SQLite)

and measures its own processing time against the paper's budget (1-2 s between the end of the rapid
motion and the tool engaging the work-piece). theta_{j-1} (``last_validated``) and the healthy
baseline are read from the history at setup, so a second run on the same axis and database
continues where the first stopped. The output ``request`` is 1.0 while the identification is too old
(no validated identification for more than ``max_motions`` motions or ``max_age_s`` seconds of
machine time); the NC then inserts an identification motion.

Machine time is the wall-clock time at setup plus the simulated time, so ages are comparable across
runs. ``MonitorPipeline`` is the same treatment without the component (``cosim monitor`` on CSVs).
"""
from __future__ import annotations

import math
import time as _time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from feeddrive.cosim.component import Component
from feeddrive.cosim.errors import InputError, ScenarioError
from feeddrive.cosim.monitor_checks import centred_speed, interval_mean_speed
from feeddrive.cosim.monitor_config import MonitorConfig, resolve_files
from feeddrive.cosim.monitor_pipeline import MonitorPipeline, MotionTrace
from feeddrive.cosim.nc import describe_validation_error
from feeddrive.estimator.errors import HistoryError
from feeddrive.estimator.history import History

__all__ = ["MEASUREMENTS", "RAPID", "Monitor", "MonitorConfig", "MonitorPipeline", "MotionTrace", "centred_speed",
           "interval_mean_speed", "resolve_files"]

#: NC state of a high-speed motion without machining
RAPID = 1
#: measurement inputs, in the order the buffer stores them
MEASUREMENTS = ("Im1", "Im2", "u", "u_ref", "w_tach", "w_enc", "theta_enc")

class Monitor(Component):
    """Co-simulation component of the monitor; see the module docstring.

    Inputs: ``Im1, Im2, u, u_ref, w_tach, w_enc, theta_enc`` (sensors), ``state, motion`` (NC); on a PMSM axis
    (``config.drive``) also ``monitor_servo.SERVO_INPUTS`` (the ``servo`` component's phase currents, dq
    voltages, motor encoder and linear scale positions).
    Output: ``request`` (1.0 while the identification is too old).
    """

    input_names = MEASUREMENTS + ("state", "motion")
    output_names = ("request",)
    output_units = ("1",)

    def __init__(self, name: str, config: MonitorConfig | Mapping | None = None) -> None:
        if not isinstance(config, MonitorConfig):
            try:
                config = MonitorConfig.model_validate(config or {})
            except ValidationError as exc:
                raise ScenarioError(describe_validation_error(exc, name)) from None
        super().__init__(name, config)
        if config.drive != "dc":  # a PMSM axis: the servo drive's measurements too (cosim/monitor_servo.py)
            from feeddrive.cosim.monitor_servo import SERVO_INPUTS

            self.input_names = Monitor.input_names + SERVO_INPUTS
        self.axis = config.axis or "X"
        self.history: History | None = None
        self.pipeline: MonitorPipeline | None = None
        self.traces: list[MotionTrace] = []
        self.results: list[dict] = []
        #: called as ``motion_ended(motion, t_last)`` when a motion ends, before the monitor treats it: ``t_last`` is
        #: the time of its last sample [s] (``cosim run`` sends the motion's figures to a drawing process then)
        self.motion_ended: Callable[[int, float], None] | None = None

    def setup(self, t0: float, h: float, n_steps: int) -> None:
        cfg = self.config
        self.t0, self.h = t0, h
        try:
            self.history = History(cfg.db or ":memory:")
        except HistoryError as exc:  # an unusable monitor.db is bad input (exit 2), found before the run
            raise InputError(f"monitor.db: {exc}") from None
        self.pipeline = MonitorPipeline(cfg, self.history, self.axis)
        self.clock0 = _time.time() - t0  # machine time of simulated time 0
        capacity = min(n_steps + 1, int(round(cfg.max_motion_s / h)) + 1)
        self._rows = np.empty((capacity, len(self.input_names)))  # the motion's samples, one row per step
        self._k = 0  # samples buffered in the current motion
        self._motion = None  # index of the motion being buffered
        self._start = 0
        self._in: tuple = (0.0,) * len(self.input_names)
        self._update_request(t0)

    def _update_request(self, t: float) -> None:
        age = self.history.age(self.axis, self.clock0 + t)
        self._request = 1.0 if age.too_old(self.config.max_motions, self.config.max_age_s) else 0.0
        # the step from which the age in seconds exceeds max_age_s: one integer compare per step
        remaining = self.config.max_age_s - age.seconds
        self._age_step = math.inf if self._request else math.floor((t - self.t0 + remaining) / self.h) + 1

    def set_inputs(self, values: Sequence[float]) -> None:
        self._in = values if type(values) is tuple else tuple(values)

    def step(self, n: int) -> None:
        values = self._in
        if values[7] == RAPID:
            if self._motion is None:
                self._motion, self._start, self._k = values[8], n + 1, 0
            elif values[8] != self._motion:
                self._end_motion(n)
                self._motion, self._start, self._k = values[8], n + 1, 0
            if self._k < len(self._rows):
                self._rows[self._k] = values
                self._k += 1
        elif self._motion is not None:
            self._end_motion(n)
        if n >= self._age_step:
            self._request, self._age_step = 1.0, math.inf

    def block_state(self) -> tuple[float | None, float]:
        """``(motion, age_step)``: the motion being buffered (None: none) and the step from which the request
        rises. Until then a step whose ``state`` is RAPID with that ``motion`` only buffers its inputs, and one
        whose state is not RAPID while no motion is buffered does nothing: :meth:`step_block` takes such steps."""
        return self._motion, self._age_step

    def step_block(self, rows: np.ndarray) -> None:
        """``step`` over consecutive steps that continue the buffered motion (see :meth:`block_state`), with
        their inputs ``rows``, shape (steps, inputs): buffers them (as many as fit, as ``step``). The compiled
        fine loop (cosim/fastloop) calls it for the steps inside a block."""
        take = min(len(rows), len(self._rows) - self._k)
        self._rows[self._k:self._k + take] = rows[:take]
        self._k += take

    def _end_motion(self, n: int) -> None:
        """The motion ended at step ``n`` (its last sample is step ``n - 1``'s, at ``t0 + n * h``): treat it."""
        if self.motion_ended is not None:
            self.motion_ended(int(self._motion), self.t0 + n * self.h)
        rows = self._rows[:self._k].copy()  # the buffer serves the next motion
        motion, self._motion = int(self._motion), None
        if rows.shape[0] < 2:
            return
        signals = dict(zip(MEASUREMENTS, rows[:, :len(MEASUREMENTS)].T))
        signals |= dict(zip(self.input_names[len(MEASUREMENTS) + 2:], rows[:, len(MEASUREMENTS) + 2:].T))
        signals["w_enc"] = centred_speed(signals["theta_enc"], signals["w_enc"], self.h, self.config.encoder_window_s)
        start = self.t0 + self._start * self.h
        end = start + (rows.shape[0] - 1) * self.h
        trace = self.pipeline.process(signals, self.h, start, motion, self.clock0 + end, self.config.scenario)
        if self._k == len(self._rows):
            trace.result["notes"].append(f"motion longer than max_motion_s = {self.config.max_motion_s} s: cut")
        self.results.append(trace.result)
        if self.config.keep_traces:
            self.traces = (self.traces + [trace])[-self.config.keep_traces:]
        self._update_request(end)

    def get_outputs(self) -> list[float]:
        return [self._request]

    def report(self) -> dict:
        times = [r["processing_s"] for r in self.results]
        return {"axis": self.axis, "db": self.config.db, "budget_s": self.config.budget_s,
                "max_processing_s": max(times, default=None),
                "max_processing_cpu_s": max((r["processing_cpu_s"] for r in self.results), default=None),
                "within_budget": all(r["within_budget"] for r in self.results),
                "request": self._request, "unfinished_motion": self._motion,
                "diagnosis_thresholds": self.pipeline.thresholds() if self.pipeline else None,
                "motions": self.results}

    def write_plots(self, folder: str | Path) -> list[Path]:
        """Monitor plots of the kept motions and the parameter trends of the axis into ``folder``."""
        from feeddrive.cosim.plots import draw_concurrently

        return draw_concurrently(self.plot_jobs(folder))

    def plot_jobs(self, folder: str | Path) -> list:
        """The figures of :meth:`write_plots` as ``cosim.figure_jobs.FigureJob`` s, drawn by the run's
        drawing processes (``cosim run``)."""
        from feeddrive.cosim.figure_jobs import monitor_figure_jobs

        Path(folder).mkdir(parents=True, exist_ok=True)
        if self.config.db:
            with History(self.config.db) as history:
                motions = history.motions(self.axis)
        else:
            motions = self.results
        return monitor_figure_jobs(self.traces, motions, Path(folder), self.pipeline.thresholds() if self.pipeline else None)

    def terminate(self) -> None:
        if self.history is not None:
            self.history.close()
            self.history = None
