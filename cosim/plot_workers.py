"""Processes that draw a run's figures, forked when the run starts (issue 23).

A run's five PNGs and the import of matplotlib they need took longer than the co-simulation itself, and
the user waited for them after it. :class:`PlotWorkers` forks its processes at the start of the run: each
imports matplotlib and draws a first, throw-away figure (fonts, the Agg renderer) while the simulation
runs in the parent, then says it is ready and waits for figures. The parent sends each figure as a
:class:`cosim.figure_jobs.FigureJob` (the drawing function's name and what it draws, pickled: each long trace
as its envelope, tens of kB) to the next idle process: a motion's run figures when the motion ends
(:meth:`PlotWorkers.submit`, to one worker beside the simulation), the others at the end of the run
(:meth:`PlotWorkers.draw`); the run itself never imports matplotlib.

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
from collections.abc import Callable, Sequence
from multiprocessing.connection import wait
from multiprocessing.reduction import ForkingPickler
from pathlib import Path
from typing import Any

from feeddrive.cosim.figure_jobs import FigureBatch, FigureJob


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
        self._senders: list[threading.Thread] = []  # submit()'s writers
        self._pid: int | None = None  # the first worker (the others are its children)
        #: the process that forked the first worker, the one that reaps it: a process forked from it after (``cosim
        #: run``'s supervised child, which draws with workers forked before the run's imports) only ends them
        self._owner = os.getpid()
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
            # until the worker says it is ready: no job is written to it before (the send would wait for its warm-up)
            self._pending[mine] = deque([_WARMING] if warm else [])

    def __enter__(self) -> PlotWorkers:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def submit(self, job: FigureJob | FigureBatch) -> Submitted:
        """Send ``job`` to a worker now, while the run goes on, if no worker is drawing already (the simulation
        keeps a CPU: one worker draws beside it); otherwise :meth:`draw` sends it. The returned
        :class:`Submitted` takes the job's place in :meth:`draw`'s list, which returns its files (or raises its
        error). A motion's figures are final once it has ended: they are drawn while the run simulates the rest
        and the monitor treats the motion, not after the simulation.

        The job (hundreds of kB: more than the socket holds) is written by a thread, so the run does not wait for
        the worker to read it, e.g. while it is still warming up."""
        ticket = Submitted(job)
        self._collect((), {}, timeout=0)  # results arrived meanwhile: their workers are idle again
        if self._working() or not self._conns:
            return ticket
        try:
            data = bytes(ForkingPickler.dumps(job))
        except Exception:  # noqa: BLE001 - data that cannot be pickled: draw() draws it here
            return ticket
        conn = min(self._conns, key=lambda c: len(self._pending[c]))  # an idle worker, else one warming up
        self._pending[conn].append(ticket)
        ticket.sent = True
        # the thread only writes (the kernel's wait, the GIL released); draw() and close() join it before they write
        sender = threading.Thread(target=_send_bytes, args=(conn, data), name="feeddrive-plot-sender", daemon=True)
        sender.start()
        self._senders.append(sender)
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
        while self._working() or (queue and self._conns):
            if self._here and queue:  # this process's share: one job, then the results that came meanwhile
                j = queue.pop(0)
                results[j] = list(_job(jobs[j])())
                self._collect(jobs, results, timeout=0)
            else:
                self._collect(jobs, results, timeout=None)
            dispatch()
        for j in queue:  # every worker died
            results[j] = list(_job(jobs[j])())
        self._join_senders()  # done: their jobs are answered
        for j, job in enumerate(jobs):
            if isinstance(job, Submitted) and j not in results:
                if job.error is not None:
                    raise job.error
                results[j] = list(job.files or [])
        return [path for j in range(len(jobs)) for path in results[j]]

    def _join_senders(self) -> None:
        for sender in self._senders:
            sender.join()
        self._senders = []

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
            if status == "ready":  # the worker waits for jobs
                if self._pending[conn] and self._pending[conn][0] is _WARMING:
                    self._pending[conn].popleft()
                continue
            key = self._pending[conn].popleft()
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

    def abandon(self) -> None:
        """End the workers now, without waiting for a figure or a warm-up: their figures are not wanted (``cosim run``
        failed before its run drew, e.g. on a bad scenario: its error is not held back by a warm-up's second). The first
        worker is killed (it writes no file), the others see their pipe close and exit."""
        self._join_senders()
        for conn in self._conns:
            conn.close()
        self._conns, self._pending = [], {}
        if self._pid is not None:
            _kill(self._pid)
            if os.getpid() == self._owner:
                os.waitpid(self._pid, 0)
            self._pid = None

    def close(self, wait: bool = True) -> None:
        """End the workers: each finishes its figure and exits; this waits for them (10 s at most, then the
        first worker, whose exit ends the others, is killed).

        ``wait=False`` (the workers are idle: :meth:`draw` has returned): they are told to exit and a background
        thread reaps them. A worker's pipe closes only once the kernel has torn its memory down: waiting for
        that was 50 to 190 ms at the end of every run."""
        self._join_senders()  # a job being written is not cut by the None that ends the worker
        if not wait and self._pid is not None:
            for conn in self._conns:
                try:
                    conn.send(None)
                except OSError:
                    pass
                conn.close()
            self._conns, self._pending = [], {}
            if os.getpid() == self._owner:
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
            if os.getpid() == self._owner:
                os.waitpid(self._pid, 0)
            self._pid = None


#: what a worker is busy with before its first message, ``("ready", None)``: its warm-up (draw() sends it nothing
#: meanwhile; submit() prefers a worker that is ready, and writes from a thread)
_WARMING = "warming"


def _send_bytes(conn: Any, data: bytes) -> None:
    try:
        conn.send_bytes(data)
    except OSError:  # the worker is gone: draw() sees it (EOF) and draws its jobs here
        pass


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
        # the first worker makes the run's usual figures in advance, while it has nothing to draw (the others were
        # forked before: the warm-up is not made longer, and one process's CPU is taken, not two)
        _serve(pipes[0][1], pipes, table, _preparations(preload) if warm else [])
        for pid in children:
            os.waitpid(pid, 0)
    except BaseException:  # noqa: BLE001 - the run sees EOF and draws the figures itself
        code = 1
    finally:
        os._exit(code)  # no atexit handlers, no flush of buffers inherited from the run


def _serve(conn: Any, pipes: list, table: tuple, preparations: list | None = None
           ) -> None:  # pragma: no cover - runs in a worker
    """Draw each job received on ``conn`` (a job, or the index of one of ``table``, inherited at the fork) until
    None or EOF, sending back ``("ok", files)`` or ``("error", exc)``; while no job waits, make the figures of
    ``preparations`` (:func:`_preparations`), one at a time."""
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
            while preparations and not conn.poll():  # a job waits for one figure's making at most
                prepare, layout = preparations.pop(0)
                prepare((layout,))
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


def _preparations(preload: tuple[str, ...]) -> list[tuple[Callable, Any]]:
    """``(prepare_figures, layout)`` of each figure layout (``LAYOUTS``) of the modules ``preload``: the run's
    figures that a drawing process makes before they are asked for (cosim.plots.prepare_figures)."""
    out = []
    for name in preload:
        module = sys.modules.get(name)
        prepare = getattr(module, "prepare_figures", None)
        if callable(prepare):
            out += [(prepare, layout) for layout in getattr(module, "LAYOUTS", ())]
    return out


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
