"""Campaign runs on Dask forked from a single-threaded "zygote" process, not from the multi-threaded worker.

Each campaign run is forked from the process that supervises it (cosim/supervise.py: containment of FMU
crashes and hangs). A Dask worker process is multi-threaded (its event loop, its task thread), so forking a
run from it

- costs more (~20 ms a run, issue 26): a larger process, whose other threads keep writing to memory the
  child shares until it is copied;
- is unsafe: the child has only the forking thread, and a lock another thread held at the fork stays held
  for ever in the child (a run once hung 25 minutes on one).

``local_cluster`` therefore forks a zygote *server* from its own process, after the run's ``prepare``
hook and before the cluster starts any thread: a process that never starts one. Each worker thread connects
to it through a Unix socket on its first run; the server forks it a zygote of its own (the server is
single-threaded, so that fork is safe too) and the zygote runs the worker's runs one after the other: the
run's ``execute`` (its ``prepare``, its scenario resolved and its FMU's description read once per zygote),
each run forked from the zygote, single-threaded at every fork. The Dask task (``run_batch``: a few runs, cosim/
campaign/execute.py) only sends them one by one and waits for their records.

A zygote that dies under a run (killed from outside its containment) makes that run ``failed`` and the next
run gets a new zygote; a worker whose zygote server is gone runs its runs itself, as without zygotes. A
zygote ends when its worker closes the connection (or dies), the server when its cluster closes or its
parent process is gone.
"""
from __future__ import annotations

import gc
import os
import pickle
import resource
import select
import shutil
import signal
import socket
import struct
import sys
import tempfile
import threading
from typing import Any

#: (pid of the process that started the zygote server, its socket's path); inherited by the workers that
#: process forks. The process itself does not use it (its runs are not on a Dask worker), unless the pid is
#: None (a preloaded worker's own server)
ADDRESS: tuple[int | None, str] | None = None
#: in a zygote: the pid of the worker it serves
WORKER_PID: int | None = None

_HEADER = struct.Struct("!Q")
#: this worker process's connections to its zygotes, one per thread: {thread id: _Link}
_LINKS: dict[int, _Link] = {}
_LOCK = threading.Lock()


# -- messages: a length and a pickle -----------------------------------------------------------------------
def _send(sock: socket.socket, payload: bytes) -> None:
    sock.sendall(_HEADER.pack(len(payload)) + payload)


def _recv(sock: socket.socket) -> Any:
    (n,) = _HEADER.unpack(_read(sock, _HEADER.size))
    return pickle.loads(_read(sock, n))


def _read(sock: socket.socket, n: int) -> bytearray:
    buf = bytearray(n)
    view = memoryview(buf)
    while view:
        k = sock.recv_into(view)
        if k == 0:
            raise EOFError("the zygote closed the connection")
        view = view[k:]
    return buf


# -- the server and its zygotes (their own processes) ----------------------------------------------------
class ZygoteServer:
    """The zygote server of a ``local_cluster``: forked from this process now, from the calling thread.

    Call it before the cluster starts (its event loop's thread). A forked process has only the forking thread,
    and a lock another thread held at the fork stays held for ever in it (and in every run forked from it):
    the threads this process's campaigns start are therefore stopped first (tqdm's monitor, which a progress
    bar started and which takes tqdm's lock every 10 s; a new bar starts it again) or waited for
    (``supervise``'s reapers, a few ms each). Other threads found then are named in ``threads_at_fork``:
    idle ones are harmless (Dask's offload thread, left by a closed cluster, waits on its queue holding no
    lock). ``close`` stops the server (its zygotes end with their workers' connections).

    Parameters
    ----------
    serve_here : bool
        Whether this process's own runs use it too (a preloaded Dask worker, cosim/campaign/preload.py); by
        default only the processes forked from this one do (``local_cluster``'s workers).
    """

    def __init__(self, serve_here: bool = False) -> None:
        global ADDRESS
        self.threads_at_fork = _quiesce()
        self.dir = tempfile.mkdtemp(prefix="feeddrive-zygote-")
        self.address = os.path.join(self.dir, "socket")
        listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        listener.bind(self.address)
        listener.listen(64)
        parent = os.getpid()
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
        pid = os.fork()
        if pid == 0:  # pragma: no cover - the server; coverage cannot follow it
            code = 0
            try:
                _serve(listener, parent)
            except BaseException:  # noqa: BLE001 - Ctrl-C or its parent gone: nothing to report to
                code = 1
            finally:
                os._exit(code)
        listener.close()
        self.pid = pid
        ADDRESS = (None if serve_here else parent, self.address)

    def close(self) -> None:
        """Stop the server and remove its socket."""
        global ADDRESS
        if self.pid is None:
            return
        if ADDRESS is not None and ADDRESS[1] == self.address:
            ADDRESS = None
        try:
            os.kill(self.pid, signal.SIGTERM)
            os.waitpid(self.pid, 0)
        except (ProcessLookupError, ChildProcessError):
            pass
        self.pid = None
        shutil.rmtree(self.dir, ignore_errors=True)


def _quiesce() -> list[str]:
    """Stop tqdm's monitor thread and wait for ``supervise``'s reapers; the names of the other threads left."""
    from feeddrive.cosim.supervise import REAPER

    tqdm = getattr(sys.modules.get("tqdm.std"), "tqdm", None)
    monitor = getattr(tqdm, "monitor", None)
    if monitor is not None and monitor.is_alive():
        monitor.exit()  # joined; tqdm starts a new one with its next bar
    for thread in threading.enumerate():
        if thread.name == REAPER:
            thread.join(1.0)
    return [t.name for t in threading.enumerate() if t is not threading.current_thread() and t.is_alive()]


def _serve(listener: socket.socket, parent: int) -> None:  # pragma: no cover - runs in the server
    """The server's loop: a zygote forked for each connection; exits when ``parent`` is gone."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C stops the campaign, which closes the cluster and this
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    gc.freeze()  # the zygotes share these pages: the collector's passes would copy them
    try:
        _accept(listener, parent)
    finally:  # its parent gone without closing it (killed): the socket's directory goes with this process
        shutil.rmtree(os.path.dirname(listener.getsockname()), ignore_errors=True)


def _accept(listener: socket.socket, parent: int) -> None:  # pragma: no cover - runs in the server
    """Fork a zygote for each connection until ``parent`` is gone."""
    while os.getppid() == parent:
        ready, _, _ = select.select([listener], [], [], 1.0)
        _reap()
        if not ready:
            continue
        conn, _ = listener.accept()
        if os.fork() == 0:
            listener.close()
            code = 0
            try:
                signal.signal(signal.SIGINT, signal.default_int_handler)
                _zygote(conn)
            except BaseException:  # noqa: BLE001 - its worker sees the connection close
                code = 1
            finally:
                os._exit(code)
        conn.close()


def _reap() -> None:  # pragma: no cover - runs in the server
    try:
        while os.waitpid(-1, os.WNOHANG)[0]:
            pass
    except ChildProcessError:
        pass


def _zygote(conn: socket.socket) -> None:  # pragma: no cover - runs in a zygote
    """A zygote's loop: the runs its worker sends, one at a time; returns when the worker closes.

    Each reply is ``("ok", value)``, or ``("refused", reason)`` for a request this process cannot read (e.g. a
    run function of a module imported by the worker's parent after this process was forked): the worker then
    runs it itself.
    """
    global WORKER_PID
    from feeddrive.cosim import supervise
    from feeddrive.cosim.campaign.runner import execute, one_blas_thread

    supervise.REAP_IN_THREAD = False  # no thread, ever: every run's fork is from a single-threaded process
    one_blas_thread()  # for good (its runs' BLAS threads would spin against the other workers' runs)
    while True:
        try:
            request = _recv(conn)
        except EOFError:
            return
        except Exception as exc:  # noqa: BLE001 - the whole message was read: the next one is intact
            _send(conn, pickle.dumps(("refused", f"{type(exc).__name__}: {exc}")))
            continue
        kind = request[0]
        if kind == "hello":
            WORKER_PID = request[1]
            reply: Any = os.getpid()
        elif kind == "cpu":
            supervise.reap(block=True)  # the runs' CPU counts once they are reaped
            own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
            reply = (own.ru_utime + own.ru_stime, children.ru_utime + children.ru_stime)
        else:
            _, run, spec, timeout = request
            try:
                fn = _loaded(run)
            except Exception as exc:  # noqa: BLE001 - e.g. a module the worker's parent imported after the fork
                _send(conn, pickle.dumps(("refused", f"{type(exc).__name__}: {exc}")))
                continue
            reply = execute(fn, spec, timeout)  # which reaps the earlier runs' children that have exited
        _send(conn, pickle.dumps(("ok", reply), protocol=pickle.HIGHEST_PROTOCOL))


# -- in the Dask worker ----------------------------------------------------------------------------------
class _Link:
    """A worker thread's connection to its zygote; ``lock`` held while a request is answered."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock, self.lock = sock, threading.Lock()

    def ask(self, payload: bytes) -> Any:
        """Send one request and return its reply's ``(kind, value)``."""
        with self.lock:
            _send(self.sock, payload)
            return _recv(self.sock)


def load_run(run: bytes | str) -> Any:
    """The run function of a Dask task: ``package.module:function`` as it is (``execute`` imports it), or the
    function from its pickle (``cloudpickle``: by reference to its module, by value for one of ``__main__``)."""
    return run if isinstance(run, str) else pickle.loads(run)


#: in a zygote: the last run function unpickled, by its pickle (a campaign sends the same one every run)
_LOADED: list[tuple[bytes | str, Any]] = []


def _loaded(run: bytes | str) -> Any:  # pragma: no cover - runs in a zygote
    if not _LOADED or _LOADED[0][0] != run:
        _LOADED[:] = [(run, load_run(run))]
    return _LOADED[0][1]


def run_batch(run: bytes | str, specs: list, timeout: float | None = None,
              topic: str | None = None) -> list[dict[str, Any]]:
    """A campaign's Dask task: its runs one after the other, each ``execute``-d in this worker thread's zygote;
    their records, in order, each also published as it ends as an event of ``topic`` (JSON text: the campaign
    writes it then, not when the task ends, cosim/campaign/execute.py ``_dask``).

    The run function comes pickled (``load_run``) and is unpickled here, inside the task, not by the worker as
    it reads the scheduler's message: a function the worker cannot import (its module only on the campaign's
    machine) then fails these runs with one line, where the worker's connection to the scheduler broke on it
    and the campaign waited for ever. Without a zygote server (a cluster not started by ``local_cluster`` nor
    preloaded, or its server gone), or for a run the zygote cannot read, the run is executed here. A zygote
    that dies under a run fails that run only (the next run gets a new zygote).
    """
    from feeddrive.cosim.campaign.runner import _lost, execute, one_blas_thread

    try:
        fn = load_run(run)
    except Exception as exc:  # noqa: BLE001 - every run of the task fails with the reason, the campaign goes on
        reason = (f"run: the Dask worker cannot load the run function ({type(exc).__name__}: "
                  f"{' '.join(str(exc).split())}); name it 'package.module:function' of a module the workers can "
                  "import (installed there, or sent with client.upload_file)")
        return [_lost(spec, reason) for spec in specs]
    records = []
    for spec in specs:
        link = _link()
        if link is None:
            with one_blas_thread():  # run here, forked from this worker: with one BLAS thread, the worker's back after
                records.append(execute(fn, spec, timeout))
            _publish(topic, records[-1])
            continue
        try:
            kind, value = link.ask(pickle.dumps(("run", run, spec, timeout), protocol=pickle.HIGHEST_PROTOCOL))
        except (OSError, EOFError) as exc:
            _drop(link)
            records.append(_lost(spec, f"crashed: its zygote process died ({exc or type(exc).__name__}); not retried"))
            _publish(topic, records[-1])
            continue
        records.append(value if kind == "ok" else execute(fn, spec, timeout))
        _publish(topic, records[-1])
    return records


def _publish(topic: str | None, record: dict[str, Any]) -> None:
    """Send a finished run's record to the campaign now, through the scheduler (``Worker.log_event``)."""
    if topic is None:
        return
    import json

    from distributed import get_worker

    try:
        get_worker().log_event(topic, json.dumps(record))
    except (ValueError, TypeError):  # not in a worker (a task run inline), an unwritable record: the task's result
        pass


def zygote_cpu() -> tuple[float, float]:
    """CPU seconds of this worker's zygotes (user + system): their own and their finished runs' (a zygote busy
    with a run now is left out)."""
    own = children = 0.0
    for link in list(_LINKS.values()):
        if not link.lock.acquire(blocking=False):
            continue
        link.lock.release()
        try:
            kind, value = link.ask(pickle.dumps(("cpu",)))
        except (OSError, EOFError):
            continue
        own, children = own + value[0], children + value[1]
    return own, children


def connect() -> None:
    """This worker thread's zygote, forked now if the worker has a zygote server (``_link``). A Dask worker runs
    its tasks in one thread (``local_cluster``: one thread per worker), the campaign's with it."""
    _link()


def _link() -> _Link | None:
    """This thread's connection to its zygote (made now on its first run), None without a server."""
    address = ADDRESS
    if address is None or address[0] == os.getpid():
        return None
    key = threading.get_ident()
    link = _LINKS.get(key)
    if link is not None:
        return link
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        sock.connect(address[1])
        link = _Link(sock)
        link.ask(pickle.dumps(("hello", os.getpid())))
    except (OSError, EOFError):  # the server is gone: the runs are executed here
        sock.close()
        return None
    with _LOCK:
        _LINKS[key] = link
    return link


def _drop(link: _Link) -> None:
    with _LOCK:
        for key, other in list(_LINKS.items()):
            if other is link:
                del _LINKS[key]
    link.sock.close()
