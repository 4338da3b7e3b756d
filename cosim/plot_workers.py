"""Processes that draw a run's figures, forked when the run starts (issue 23).

A run's five PNGs and the import of matplotlib they need took longer than the co-simulation itself, and
the user waited for them after it. :class:`PlotWorkers` forks its processes at the start of the run: each
imports matplotlib and draws a first, throw-away figure (fonts, the Agg renderer) while the simulation
runs in the parent, then waits for figures. At the end of the run the parent sends each figure as a
:class:`FigureJob` (the drawing function's name and what it draws, pickled: each long trace as its
envelope, tens of kB) to the next idle process; the run itself never imports matplotlib.

Jobs that are not :class:`FigureJob` (a user component's own ``write_plots``) are drawn in this process,
while the workers draw theirs, unless they were given when the workers were forked (``jobs``): the
workers inherit them and are sent their index. :func:`cosim.plots.draw_concurrently` (``cosim monitor``,
the figures known before any fork) is that use: the same workers, forked with the jobs, this process
drawing its share too (``here``). Without ``fork`` (not POSIX), in a daemonic process (a campaign's Pool or
Dask worker) or with one process asked for, there are no workers and every job is drawn here in turn.
A worker that dies has its figure drawn here; a job's exception is raised here.
"""
from __future__ import annotations

import gc
import importlib
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from multiprocessing.connection import wait
from pathlib import Path
from typing import Any

import numpy as np

from feeddrive.cosim.figure_data import envelope, motion_figure

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


class Submitted:
    """A job handed to :meth:`PlotWorkers.submit` before the run's end: its place in :meth:`PlotWorkers.draw`'s
    list, where its files are waited for (or it is drawn then, when no worker was idle to take it)."""

    def __init__(self, job: FigureJob | FigureBatch) -> None:
        self.job = job
        self.files: list[Path] | None = None
        self.error: BaseException | None = None
        self.sent = False


def drawing_processes(processes: int | None = None) -> int:
    """Processes to draw with: ``processes``, else ``$FEEDDRIVE_PLOT_PROCESSES``, else the number of CPUs;
    1 without ``fork`` or in a daemonic process (a campaign's Pool or Dask worker may have no children)."""
    default = int(os.environ.get("FEEDDRIVE_PLOT_PROCESSES", "0") or 0)
    k = max(1, processes or default or os.cpu_count() or 1)
    if "fork" not in multiprocessing.get_all_start_methods() or multiprocessing.current_process().daemon:
        return 1
    return k


def motions(signals: Mapping[str, np.ndarray]) -> dict[int, np.ndarray]:
    """``motion index -> sample indices`` of each high-speed motion (NC state 1), from nc.state/nc.motion."""
    if "nc.state" not in signals or "nc.motion" not in signals:
        return {}
    state, motion = signals["nc.state"], signals["nc.motion"]
    rapid = state == 1
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
    for k, idx in motions(signals).items():
        if idx.size < 2 or (only is not None and k != only):
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


class PlotWorkers:
    """Drawing processes forked now, used by :meth:`draw` at the end of the run; :meth:`close` ends them.

    The first worker is forked at once; it imports matplotlib, draws a throw-away figure, then forks the
    others from itself, so the simulation shares the machine with one import, not one per worker.

    Parameters
    ----------
    processes : int or None
        Processes drawing at once (see :func:`drawing_processes`); with 1 there is no worker and
        :meth:`draw` draws every job here.
    preload : sequence of str
        Modules the workers import before their first figure (those of the jobs' functions).
    jobs : sequence of callables
        Jobs known now: the workers inherit them (any callable, nothing pickled) and :meth:`draw` sends
        their index.
    here : bool
        This process draws too (one process of ``processes``); it then needs matplotlib itself.
    warm : bool
        The first worker imports matplotlib and draws a throw-away figure before forking the others
        (False: this process has done so already).
    """

    def __init__(self, processes: int | None = None, preload: Sequence[str] = (), jobs: Sequence[Callable] = (),
                 here: bool = False, warm: bool = True) -> None:
        self._conns: list[Any] = []  # this process's end of each worker's pipe
        # per worker, what it was sent and has not answered, in order: a job's index in draw()'s list, or a Submitted
        self._pending: dict[Any, deque] = {}
        self._pid: int | None = None  # the first worker (the others are its children)
        self._index = {id(job): j for j, job in enumerate(jobs)}
        self._here = here
        k = drawing_processes(processes) - here
        if k < 1 or (k < 2 and not here):
            return
        pipes = [multiprocessing.Pipe(duplex=True) for _ in range(k)]
        for stream in (sys.stdout, sys.stderr):  # nothing buffered here is written again by a worker
            stream.flush()
        # objects existing now stay out of the workers' garbage collections: their first collection would
        # otherwise touch every inherited object and copy its page (supervise.py does the same). In a
        # supervised run everything is frozen already and stays so (unfreezing would undo supervise's freeze)
        frozen_before = gc.get_freeze_count()
        gc.freeze()
        try:
            pid = os.fork()
            if pid == 0:  # pragma: no cover - the first worker; coverage cannot follow it
                _first_worker(pipes, tuple(preload), tuple(jobs), warm)
        finally:
            if not frozen_before:
                gc.unfreeze()
        self._pid = pid
        for mine, theirs in pipes:
            theirs.close()
            self._conns.append(mine)
            self._pending[mine] = deque([_WARMING])  # until the worker says it is ready

    def __enter__(self) -> PlotWorkers:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def submit(self, job: FigureJob | FigureBatch) -> Submitted:
        """Send ``job`` to a worker now, while the run goes on, if no worker is drawing already (the simulation
        keeps a CPU: one worker draws beside it); otherwise :meth:`draw` sends it. The returned
        :class:`Submitted` takes the job's place in :meth:`draw`'s list, which returns its files (or raises its
        error). A motion's figures are final once it has ended: they are drawn while the run simulates the rest
        and the monitor treats the motion, not after the simulation."""
        ticket = Submitted(job)
        self._collect((), {}, timeout=0)  # results arrived meanwhile: their workers are idle again
        if self._working():
            return ticket
        for conn in [conn for conn in self._conns if not self._pending[conn]]:  # never blocked by a warm-up
            try:
                conn.send(job)
            except OSError:  # the worker is gone: the next one, or draw() draws it
                self._lost(conn, (), {})
                continue
            except Exception:  # noqa: BLE001 - data that cannot be pickled: draw() draws it here
                return ticket
            self._pending[conn].append(ticket)
            ticket.sent = True
            break
        return ticket

    def draw(self, jobs: Sequence[Callable[[], list[Path]] | Submitted], meanwhile: Callable[[], Any] | None = None
             ) -> list[Path]:
        """Draw ``jobs``; returns their files in the order of ``jobs``.

        :class:`FigureJob` s and the jobs given at the fork go to the workers, costliest first, one at a time to
        each idle one (and to this process, with ``here``, between the workers' results); ``meanwhile()`` (work
        of the run that does not need the figures) and any other job run here while they draw (every job when
        there is no worker). A :class:`Submitted` job is waited for (sent here if it was not yet)."""
        results: dict[int, list[Path]] = {}
        queue = [j for j, job in enumerate(jobs) if self._sendable(job) and not getattr(job, "sent", False)
                 ] if self._conns else []
        queue.sort(key=lambda j: -getattr(_job(jobs[j]), "cost", 1.0))  # the costliest first: the last ones are short
        local = [j for j, job in enumerate(jobs)
                 if j not in queue and not (isinstance(job, Submitted) and job.sent)]

        def dispatch() -> None:
            while queue:
                idle = [conn for conn in self._conns if not self._pending[conn]]
                if not idle:
                    return
                conn, j = idle[0], queue.pop(0)
                job = _job(jobs[j])
                try:
                    conn.send(self._index.get(id(job), job))  # an inherited job by its index
                except OSError:  # the worker is gone: its job is drawn here, it gets no more
                    self._lost(conn, jobs, results)
                    results[j] = list(job())
                except Exception:  # noqa: BLE001 - data that cannot be pickled: drawn here
                    results[j] = list(job())
                else:
                    self._pending[conn].append(j)

        dispatch()
        if meanwhile is not None:
            meanwhile()
        for j in local:  # this process's share, while the workers draw
            results[j] = list(_job(jobs[j])())
        while self._working() or (queue and self._conns):  # (a warm-up is waited for only by a job to send)
            if self._here and queue:  # this process's share: one job, then the results that came meanwhile
                j = queue.pop(0)
                results[j] = list(_job(jobs[j])())
                self._collect(jobs, results, timeout=0)
            else:
                self._collect(jobs, results, timeout=None)
            dispatch()
        for j in queue:  # every worker died
            results[j] = list(_job(jobs[j])())
        for j, job in enumerate(jobs):
            if isinstance(job, Submitted) and j not in results:
                if job.error is not None:
                    raise job.error
                results[j] = list(job.files or [])
        return [path for j in range(len(jobs)) for path in results[j]]

    def _working(self) -> bool:
        """A worker draws (or has a job waiting)."""
        return any(key is not _WARMING for keys in self._pending.values() for key in keys)

    def _sendable(self, job: Any) -> bool:
        job = _job(job)
        return isinstance(job, (FigureJob, FigureBatch)) or id(job) in self._index

    def _collect(self, jobs: Sequence, results: dict[int, list[Path]], timeout: float | None) -> None:
        """Receive the results that are ready (``timeout`` 0) or the next one (None): a job of ``jobs`` into
        ``results``, a :class:`Submitted` into itself; a failed job of ``jobs`` is raised."""
        busy = [conn for conn in self._conns if self._pending[conn]]
        for conn in wait(busy, timeout) if busy else ():
            try:
                status, value = conn.recv()
            except (EOFError, OSError):  # the worker died: its figures are drawn here, it gets no more
                self._lost(conn, jobs, results)
                continue
            key = self._pending[conn].popleft()
            if key is _WARMING:  # ("ready", None): the worker waits for jobs
                continue
            if isinstance(key, Submitted):
                key.files, key.error = (value, None) if status == "ok" else (None, value)
            elif status != "ok":
                raise value
            else:
                results[key] = value

    def _lost(self, conn: Any, jobs: Sequence, results: dict[int, list[Path]]) -> None:
        """A worker is gone: what it had not answered is drawn here."""
        self._conns.remove(conn)
        conn.close()
        for key in self._pending.pop(conn):
            if key is _WARMING:
                continue
            if isinstance(key, Submitted):
                key.files = list(key.job())
            else:
                results[key] = list(_job(jobs[key])())

    def close(self, wait: bool = True) -> None:
        """End the workers: each finishes its figure and exits; this waits for them (10 s at most, then the
        first worker, whose exit ends the others, is killed).

        ``wait=False`` (the workers are idle: :meth:`draw` has returned): they are told to exit and a background
        thread reaps them. A worker's pipe closes only once the kernel has torn its memory down: waiting for
        that was 50 to 190 ms at the end of every run."""
        if not wait and self._pid is not None:
            for conn in self._conns:
                try:
                    conn.send(None)
                except OSError:
                    pass
                conn.close()
            self._conns, self._pending = [], {}
            # the thread only waits in the kernel: a fork meanwhile (the next run's workers) inherits no lock of it
            threading.Thread(target=_reap, args=(self._pid,), name="feeddrive-plot-reaper", daemon=True).start()
            self._pid = None
            return
        for conn in self._conns:
            try:
                conn.send(None)
            except OSError:
                pass
        deadline = time.monotonic() + 10.0
        for conn in self._conns:  # EOF: the worker has exited (its end is closed with it)
            try:
                while conn.poll(max(0.0, deadline - time.monotonic())):
                    conn.recv()
            except (EOFError, OSError):
                pass
            conn.close()
        self._conns, self._pending = [], {}
        if self._pid is not None:
            if time.monotonic() > deadline:
                _kill(self._pid)
            os.waitpid(self._pid, 0)
            self._pid = None


#: what a worker is busy with before its first message, ``("ready", None)``: its warm-up (no job is sent to it before,
#: so that a job sent while the run goes on never waits in the pipe, nor the run in ``send``, for that warm-up)
_WARMING = "warming"


def _job(job: Any) -> Any:
    """The job itself of a :class:`Submitted`."""
    return job.job if isinstance(job, Submitted) else job


def _reap(pid: int) -> None:
    try:
        os.waitpid(pid, 0)
    except ChildProcessError:  # reaped already
        pass


def _kill(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def _first_worker(pipes: list, preload: tuple[str, ...], table: tuple, warm: bool
                  ) -> None:  # pragma: no cover - runs in a worker
    """The first worker: warm up, fork the others (with matplotlib loaded), serve, wait for them, exit."""
    code = 0
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the run's to handle: the run ends the workers
        for mine, _ in pipes:  # the run's ends: EOF reaches a worker when the run is gone
            mine.close()
        if warm:
            _warm_up(preload)
        children = []
        for j in range(1, len(pipes)):
            pid = os.fork()
            if pid == 0:
                _serve(pipes[j][1], pipes, table)
                os._exit(0)
            children.append(pid)
        _serve(pipes[0][1], pipes, table)
        for pid in children:
            os.waitpid(pid, 0)
    except BaseException:  # noqa: BLE001 - the run sees EOF and draws the figures itself
        code = 1
    finally:
        os._exit(code)  # no atexit handlers, no flush of buffers inherited from the run


def _serve(conn: Any, pipes: list, table: tuple) -> None:  # pragma: no cover - runs in a worker
    """Draw each job received on ``conn`` (a job, or the index of one of ``table``, inherited at the fork) until
    None or EOF, sending back ``("ok", files)`` or ``("error", exc)``."""
    # every other worker's end closed here: the run sees EOF when that worker is gone
    for _, theirs in pipes:
        if theirs is not conn:
            theirs.close()
    # a figure's garbage (5 000 to 18 000 objects) is collected once it is drawn, when no job waits, not by the
    # collector's passes during the drawing: 9 % of the figures' time (5 figures of a tool change: 2.11 -> 1.92 s
    # of CPU, best of 6), for 5 to 23 ms per figure of collection
    gc.disable()
    conn.send(("ready", None))
    while True:
        if not conn.poll():
            gc.collect()
        try:
            job = conn.recv()
        except (EOFError, OSError):
            return
        if job is None:
            return
        if isinstance(job, int):
            job = table[job]
        try:
            conn.send(("ok", list(job())))
        except Exception as exc:  # noqa: BLE001 - handed to the run, which raises it
            try:
                conn.send(("error", exc))
            except Exception:  # noqa: BLE001 - an exception that cannot be pickled
                conn.send(("error", RuntimeError(f"{type(exc).__name__}: {exc}")))


def _warm_up(preload: tuple[str, ...]) -> None:  # pragma: no cover - runs in a worker
    """What every figure needs once per process, done before the first one is asked for: the imports,
    the font cache and the Agg renderer's first text (a figure drawn into memory and dropped)."""
    import io

    gc.disable()  # matplotlib's import makes long-lived objects only: collected once, below, then frozen

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for name in preload:  # the jobs' modules (cosim.plots, cosim.monitor_plots: run.FIGURE_MODULES)
        importlib.import_module(name)

    fig, ax = plt.subplots(figsize=(2, 1))
    ax.plot([0.0, 1.0], [0.0, 1.0], label="x")
    ax.set_xlabel("time [s]")
    ax.legend(fontsize=7)
    fig.savefig(io.BytesIO(), dpi=20)
    plt.close(fig)
    # matplotlib's modules and caches stay out of the figures' garbage collections too (the run's objects are
    # frozen already): 5-7 % of the figures' time (in-process, 5 figures 3.15 -> 2.93 s, best of 3)
    gc.collect()
    gc.freeze()
