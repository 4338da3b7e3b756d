"""Containment of FMU crashes and hangs: a run in a forked child process, supervised by its parent.

A vendor FMU is native code: a segmentation fault, an ``abort()`` or an endless loop inside an FMI
call would take the whole process down or hold it forever. :func:`supervise` forks; the child runs
the target with a shared record (cosim/fmi_progress.py) in which the FMU adapter writes the FMI
function in progress and the simulated time, and sends its result (or its exception) back through a
pipe. The parent waits on the pipe and watches the record:

* the child dies by a signal (or exits without a result): ``crashed``, naming the signal, the
  component, the FMI function and the simulated time found in the record;
* one FMI call runs longer than its component's ``call_timeout`` (``plant.call_timeout``, default
  60 s), or the whole target longer than ``timeout``: the parent kills the child (SIGKILL): ``hung``.

The fork and the exit of the child cost ~20 ms per run (a 240 MB process) and nothing per
step (the record is written by the adapter either way): ``python benchmarks/bench_cosim.py
--containment`` measures it. Python tracebacks of the child, and the Python stack at a fatal signal
(faulthandler), go to the run's log file, never to the user's terminal.

:func:`run_supervised` is ``cosim run``'s use of it: it writes report.json with ``status: crashed``
or ``hung`` (signals.csv is streamed block by block by the child and stays as it was written; the
history database is SQLite in WAL mode, consistent after a kill) and raises :class:`RunCrashed`.
"""
from __future__ import annotations

import datetime as _dt
import faulthandler
import gc
import json
import logging
import os
import pickle
import select
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from feeddrive.cosim import fmi_progress
from feeddrive.cosim.errors import InputError, SimulationError

#: how often the parent looks at the child's record [s]
POLL_S = 0.05
#: reap a child that sent its result in a background thread (True), or leave it to ``reap`` (False: a
#: process that forks runs must stay single-threaded, cosim/campaign/zygote.py)
REAP_IN_THREAD = True
#: the name of those threads (a process about to fork a long-lived server waits for them: cosim/campaign/zygote.py)
REAPER = "feeddrive-reap"
#: children that sent their result and were not reaped yet (``REAP_IN_THREAD`` False)
_UNREAPED: list[int] = []
LOG_FILE = "run.log"
#: how long an interrupted child (Ctrl-C) may take to write report.json and report.html before it is killed [s]
INTERRUPT_GRACE_S = 5.0


class RunInterrupted(KeyboardInterrupt):
    """``cosim run`` interrupted (Ctrl-C): its message says until when and what was kept."""


class RunCrashed(SimulationError):
    """The run's process died by a signal or was stopped by the watchdog (``outcome`` says which)."""

    def __init__(self, message: str, outcome: Outcome) -> None:
        super().__init__(message)
        self.outcome = outcome


@dataclass(frozen=True)
class Outcome:
    """How a supervised target ended.

    Attributes
    ----------
    status : str
        ``ok`` (``value`` holds the result), ``error`` (``error`` holds the exception it raised),
        ``crashed`` (died by ``signal``, or exited with ``exit_code`` without a result) or ``hung``.
    component, function : str
        The component and FMI function in progress at the end (``""``: none).
    time : float or None
        Simulated time of that call [s].
    limit : str
        For ``hung``: which limit was exceeded, e.g. ``plant.call_timeout = 60 s``.
    """

    status: str
    value: Any = None
    error: BaseException | None = None
    signal: str = ""
    exit_code: int | None = None
    component: str = ""
    function: str = ""
    time: float | None = None
    limit: str = ""

    def describe(self) -> str:
        """One line: what happened, in which component and FMI function, at which simulated time."""
        where = f"in {self.function}" if self.function else "outside any FMI call"
        at = f" at t={self.time:.6g} s" if self.time is not None else ""
        who = f"{self.component}: " if self.component else ""
        if self.status == "hung":
            return f"{who}hung {where}{at}: exceeded {self.limit}; the run was stopped (SIGKILL)"
        how = f"by signal {self.signal}" if self.signal else f"with exit status {self.exit_code} and no result"
        return f"{who}the process crashed {how} {where}{at}"


def supervise(target: Callable[..., Any], *args: Any, timeout: float | None = None,
              log_path: str | Path | None = None) -> Outcome:
    """Run ``target(*args)`` in a forked child; return how it ended (never raises for the child's sake).

    Parameters
    ----------
    target : callable
        Its return value and any exception it raises must be picklable (an exception that is not is
        sent as an InputError (ValueError) or SimulationError with the same message).
    timeout : float or None
        Wall-time limit of the whole target [s].
    log_path : path or None
        File (appended) receiving the child's tracebacks, WARNING+ log records and the Python stack
        at a fatal signal.
    """
    mapping, rec = fmi_progress.new_shared()
    for r in rec:
        r.function, r.time, r.call_timeout = fmi_progress.IDLE, float("nan"), 0.0
    read_fd, write_fd = os.pipe()
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    # tqdm's write lock (a multiprocessing semaphore, made with the first bar) made here, not in the child:
    # a child that makes it registers it with the resource tracker and leaves by os._exit without
    # unregistering, and a campaign's worker then ended with "resource_tracker: ... leaked semaphore objects"
    from tqdm import tqdm

    tqdm.get_lock()
    # objects existing now are left out of the garbage collector's passes in the child: without this its
    # first collection touches every object, and copying those pages costs more than the fork itself
    gc.freeze()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child; coverage cannot follow it
        os.close(read_fd)
        _child(target, args, rec, write_fd, log_path)
    gc.unfreeze()
    os.close(write_fd)
    try:
        return _watch(pid, read_fd, rec, timeout)
    except KeyboardInterrupt:  # Ctrl-C: the child writes what it has (report.json, signals.csv), then goes
        _stop(pid, read_fd)
        raise
    except BaseException:  # an error here: never leave the child behind
        _kill(pid)
        raise
    finally:
        os.close(read_fd)
        del rec
        try:
            mapping.close()
        except BufferError:  # the record is still referenced (e.g. by a traceback): freed with it
            pass


def _interrupt_once(signum: int, frame: Any) -> None:  # pragma: no cover - runs in the child
    """The child's SIGINT handler: KeyboardInterrupt once, then SIGINT ignored, so that the terminal's Ctrl-C and
    the parent's forwarded one (:func:`_stop`) do not cut the writing of what the run has short."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    raise KeyboardInterrupt


def _stop(pid: int, fd: int) -> None:
    """Interrupt the child (SIGINT: a terminal's Ctrl-C reaches it too, a ``kill -INT`` of this process does not),
    give it ``INTERRUPT_GRACE_S`` to write its report and close its pipe, then kill it; a second Ctrl-C kills it
    at once."""
    try:
        os.kill(pid, signal.SIGINT)
        deadline = time.monotonic() + INTERRUPT_GRACE_S
        while (left := deadline - time.monotonic()) > 0:
            ready, _, _ = select.select([fd], [], [], min(left, POLL_S))
            if ready and not os.read(fd, 1 << 20):
                break  # the pipe closed: the child has written what it had and is exiting
    except ProcessLookupError:
        pass
    finally:
        _kill(pid)
        try:
            os.waitpid(pid, 0)
        except ChildProcessError:
            pass


def _child(target: Callable[..., Any], args: tuple, rec: Any, fd: int,
           log_path: str | Path | None) -> None:  # pragma: no cover - runs in the child
    code = 0
    try:
        if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:  # a run started ignoring it (nohup, &) still does
            signal.signal(signal.SIGINT, _interrupt_once)
        fmi_progress.install(rec)
        log = open(log_path, "a", encoding="utf-8", buffering=1) if log_path else None  # noqa: SIM115
        faulthandler.disable()  # an inherited handler (PYTHONFAULTHANDLER, pytest) would print to the terminal
        if log is not None:
            faulthandler.enable(log)  # the Python stack at SIGSEGV / SIGABRT, then the signal proceeds
            handler = logging.StreamHandler(log)
            handler.setLevel(logging.WARNING)
            handler.setFormatter(logging.Formatter("%(asctime)s %(name)s %(levelname)s: %(message)s"))
            logging.getLogger().addHandler(handler)
        try:
            payload = pickle.dumps(("ok", target(*args)), protocol=pickle.HIGHEST_PROTOCOL)
        except BaseException as exc:  # noqa: BLE001 - everything goes back to the parent
            if log is not None:
                traceback.print_exc(file=log)
            payload = pickle.dumps(("error", _portable(exc)), protocol=pickle.HIGHEST_PROTOCOL)
        view = memoryview(payload)
        while view:
            view = view[os.write(fd, view):]
        os.close(fd)  # EOF for the parent now, not after the kernel has torn this process's memory down
    except BaseException:  # noqa: BLE001 - the parent sees "no result"
        code = 3
    finally:
        os._exit(code)  # no atexit handlers, no flush of buffers inherited from the parent


def _portable(exc: BaseException) -> BaseException:
    """``exc`` if it survives pickling, else an exception of the same kind (input or failure) and message."""
    try:
        return pickle.loads(pickle.dumps(exc))
    except Exception:  # noqa: BLE001 - exceptions with a custom __init__ do not unpickle
        text = " ".join((str(exc) or type(exc).__name__).split())
        return InputError(text) if isinstance(exc, ValueError) else SimulationError(text)


def _watch(pid: int, fd: int, records: Any, timeout: float | None) -> Outcome:
    start = seen_at = time.monotonic()
    seen: tuple = ()
    chunks: list[bytes] = []
    limit = ""
    while True:
        ready, _, _ = select.select([fd], [], [], POLL_S)
        if ready:
            data = os.read(fd, 1 << 20)
            if not data:
                break  # the child closed the pipe: it has exited
            chunks.append(data)
            continue
        now = time.monotonic()
        key = tuple((r.function, r.time) for r in records if r.component)  # slots in use (unused: time NaN != NaN)
        if key != seen:
            seen, seen_at = key, now
        rec = fmi_progress.current(records)
        if rec.function and rec.call_timeout and now - seen_at > rec.call_timeout:
            limit = f"{rec.component.decode('utf-8', 'replace')}.call_timeout = {rec.call_timeout:g} s"
        elif timeout is not None and now - start > timeout:
            limit = f"the run's timeout of {timeout:g} s"
        if limit:
            _kill(pid)
            break
    if not limit and chunks:
        try:
            kind, value = pickle.loads(b"".join(chunks))
        except Exception:  # noqa: BLE001 - a truncated result: the exit status says what happened
            pass
        else:  # a complete result: reap the exiting child in the background (its teardown takes ~20 ms)
            if REAP_IN_THREAD:
                threading.Thread(target=os.waitpid, args=(pid, 0), name=REAPER, daemon=True).start()
            else:
                _UNREAPED.append(pid)
            return Outcome("ok", value=value) if kind == "ok" else Outcome("error", error=value)
    _, status = os.waitpid(pid, 0)
    rec = fmi_progress.current(records)
    where = {"component": rec.component.decode("utf-8", "replace"), "function": fmi_progress.FUNCTIONS[rec.function]
             if 0 <= rec.function < len(fmi_progress.FUNCTIONS) else f"FMI function #{rec.function}",
             "time": rec.time if rec.time == rec.time else None}
    if limit:
        return Outcome("hung", limit=limit, signal="SIGKILL", **where)
    if chunks and not os.WIFSIGNALED(status):
        try:
            kind, value = pickle.loads(b"".join(chunks))
        except Exception as exc:  # noqa: BLE001 - a truncated result is a crash
            return Outcome("crashed", exit_code=os.waitstatus_to_exitcode(status), **where,
                           error=SimulationError(f"unreadable result ({exc})"))
        return Outcome("ok", value=value) if kind == "ok" else Outcome("error", error=value)
    if os.WIFSIGNALED(status):
        return Outcome("crashed", signal=signal.Signals(os.WTERMSIG(status)).name, **where)
    return Outcome("crashed", exit_code=os.waitstatus_to_exitcode(status), **where)


def reap(block: bool = False) -> None:
    """Reap the children left to it (``REAP_IN_THREAD`` False) that have exited; all of them if ``block``."""
    for pid in list(_UNREAPED):
        try:
            done = os.waitpid(pid, 0 if block else os.WNOHANG)[0]
        except ChildProcessError:
            done = pid
        if done:
            _UNREAPED.remove(pid)


def _kill(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def _reported() -> tuple[type[BaseException], ...]:
    from feeddrive.estimator.errors import EstimatorInputError, NotEnoughExcitation

    return (InputError, SimulationError, EstimatorInputError, NotEnoughExcitation, FileNotFoundError, FileExistsError,
            IsADirectoryError, NotADirectoryError, PermissionError)


#: exceptions the CLI turns into one line itself (cosim/cli/__init__.py); any other is wrapped
_REPORTED = _reported()


# -- cosim run -------------------------------------------------------------------------------------------
def _run_child(scenario: Any, out_dir: Path, progress: bool, default_history: Path | None, plots: bool,
               workers: Any = None) -> Any:
    from feeddrive.cosim.run import RunResult, run_scenario

    res = run_scenario(scenario, out_dir, progress=progress, overwrite=True, default_history=default_history,
                       plots=plots, workers=workers)
    # only the last sample crosses the pipe (the summary's needs): signals.csv holds them all
    last = {k: v[-1:].copy() for k, v in res.signals.items()}
    return RunResult(res.out_dir, res.time[-1:].copy(), last, res.units, res.report, res.paths)


def run_supervised(scenario: Any, out_dir: str | Path, *, progress: bool = False, overwrite: bool = False,
                   default_history: str | Path | None = None, timeout: float | None = None,
                   plots: bool = True, workers: Any = None) -> Any:
    """:func:`cosim.run.run_scenario` in a supervised child process (``cosim run``).

    Parameters are those of ``run_scenario``, plus ``timeout`` (wall time of the whole run [s]). ``workers``
    (cosim.plot_workers.PlotWorkers, forked by the caller) are the child's to draw with; the caller closes its
    copy once this returns.
    The run's log file ``run.log`` in ``out_dir`` receives the child's tracebacks.

    Returns
    -------
    cosim.run.RunResult
        With ``time`` and ``signals`` holding the last sample only (signals.csv has every sample).

    Raises
    ------
    RunCrashed
        The FMU (or anything in the run) crashed or hung; report.json has ``status: crashed|hung``.
    cosim.errors.InputError, cosim.errors.SimulationError
        Those the run raised, as without supervision.
    """
    from feeddrive.cosim.run import prepare_out_dir

    out_dir = prepare_out_dir(out_dir, overwrite)
    log = out_dir / LOG_FILE
    log.write_text("", encoding="utf-8")
    history = Path(default_history) if default_history is not None else None
    try:
        outcome = supervise(_run_child, scenario, out_dir, progress, history, plots, workers, timeout=timeout,
                            log_path=log)
    except KeyboardInterrupt:
        raise RunInterrupted(_interrupted(scenario, out_dir, progress)) from None
    if outcome.status == "ok":
        return outcome.value
    if outcome.status == "error":
        exc = outcome.error
        if isinstance(exc, KeyboardInterrupt):  # the child alone was interrupted (kill -INT of its pid)
            raise RunInterrupted(_interrupted(scenario, out_dir, progress))
        if isinstance(exc, _REPORTED) or not isinstance(exc, Exception):
            raise exc
        # a bug, not a user's mistake: one line for the user, the traceback is in run.log
        text = " ".join((str(exc) or type(exc).__name__).split())
        raise SimulationError(f"{type(exc).__name__}: {text} (the traceback is in {log})")
    message = outcome.describe()
    if progress and sys.stderr.isatty():
        sys.stderr.write("\r\x1b[K")  # the killed child's progress bar would share the error's line
    with open(log, "a", encoding="utf-8") as f:
        f.write(f"supervisor: {message}\n")
    _write_failure_report(scenario, out_dir, outcome, message)
    raise RunCrashed(message, outcome)


def _interrupted(scenario: Any, out_dir: Path, progress: bool) -> str:
    """report.json and report.html of an interrupted run: what the child wrote (the motions judged so far) kept,
    marked interrupted with the time recorded until; signals.csv holds every block recorded before. Returns what
    the console says of it."""
    if progress and sys.stderr.isatty():
        sys.stderr.write("\r\x1b[K")
    at = last_recorded_time(out_dir / "signals.csv")
    where = f" at t={at:.6g} s" if at is not None else ""
    report = _write_failure_report(scenario, out_dir, Outcome("interrupted"), f"interrupted (Ctrl-C / SIGINT){where}")
    judged = len(report.get("motions") or ())
    kept = "signals.csv up to then, " if at is not None else ""
    return f"{where.strip()}; {kept}report.json ({judged} motion{'s' * (judged != 1)} judged) in {out_dir}"


def _write_failure_report(scenario: Any, out_dir: Path, outcome: Outcome, message: str) -> dict[str, Any]:
    report: dict[str, Any] = {}
    path = out_dir / "report.json"
    try:
        report = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        from feeddrive.cosim.run import report_header

        report = report_header(scenario)
    report |= {"status": outcome.status, "error": message,
               "ended": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
               "failure": {"component": outcome.component, "function": outcome.function, "time_s": outcome.time,
                           "signal": outcome.signal, "exit_code": outcome.exit_code, "limit": outcome.limit},
               "recorded_until_s": last_recorded_time(out_dir / "signals.csv"), "log": LOG_FILE}
    path.write_text(json.dumps(report, indent=2), encoding="utf-8")
    # report.html too, as for a run that failed inside the child: a crash or hang left none (the README: every
    # run's directory holds it, a failed run's with its status and error)
    from feeddrive.cosim.run import _write_page

    _write_page(out_dir, report)
    return report


def last_recorded_time(signals_csv: Path) -> float | None:
    """Time [s] of the last complete row of a signals.csv (None: no row)."""
    try:
        with open(signals_csv, "rb") as f:
            f.seek(0, os.SEEK_END)
            size = f.tell()
            f.seek(max(0, size - 65536))
            tail = f.read().split(b"\n")
    except OSError:
        return None
    for line in reversed(tail[:-1] if tail and tail[-1] else tail):  # a last line without \n may be cut
        try:
            return float(line.split(b",", 1)[0])
        except ValueError:
            continue
    return None
