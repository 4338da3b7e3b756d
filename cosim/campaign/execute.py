"""Campaign execution: in this process, on a local process pool or on a Dask cluster; resumable store.

One run (``execute``, ``resolve_function``) is cosim/campaign/runner.py's."""
from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import tempfile
from collections.abc import Callable
from concurrent.futures import CancelledError, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from multiprocessing import get_all_start_methods, get_context
from pathlib import Path
from typing import Any

from feeddrive.cosim.campaign.aggregate import Aggregates, aggregate, plot_campaign
from feeddrive.cosim.campaign.runner import _lost, execute, one_blas_thread, resolve_function
from feeddrive.cosim.campaign.schema import Campaign, CampaignError, RunSpec, expand
from feeddrive.cosim.errors import SimulationError


class SchedulerLost(SimulationError):
    """The Dask scheduler went away during a campaign: the runs recorded until then are kept, the same command
    resumes the others (``cosim campaign`` exits 1 with this line)."""


# -- execution -------------------------------------------------------------------------------------------
def _write_atomic(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _fingerprint(campaign: Campaign) -> str:
    payload = json.dumps([campaign.model_dump(mode="json", exclude={"root"}), campaign.base_scenario()], sort_keys=True)
    return hashlib.sha256(payload.encode()).hexdigest()


def _open_store(campaign: Campaign, out: Path, overwrite: bool) -> dict[str, dict]:
    """Create or reopen the out dir; return the finished records by id."""
    meta = out / "campaign.json"
    runs = out / "runs"
    fingerprint = _fingerprint(campaign)
    if meta.exists():
        old = json.loads(meta.read_text())
        if old.get("fingerprint") != fingerprint:
            if not overwrite:
                raise CampaignError(f"{out}: holds the results of another campaign ({old.get('name')!r} or an "
                                    "earlier version of this one); choose another --out or pass --overwrite")
            for f in runs.glob("*.json"):
                f.unlink()
    elif out.exists() and any(out.iterdir()) and not overwrite:
        raise CampaignError(f"{out}: exists, is not empty and holds no campaign; choose another --out or pass --overwrite")
    runs.mkdir(parents=True, exist_ok=True)
    _write_atomic(meta, json.dumps({"name": campaign.name, "fingerprint": fingerprint,
                                    "campaign": campaign.model_dump(mode="json")}, indent=1))
    done = {}
    for f in runs.glob("*.json"):
        record = json.loads(f.read_text())
        done[record["id"]] = record
    return done


def _local(run, specs, workers, on_done, timeout=None) -> None:
    if workers == 1:
        with one_blas_thread():  # the runs forked from here with one; the caller's own threads given back after
            for spec in specs:
                on_done(execute(run, spec, timeout))
        return
    # the workers are forked from this process once the run's imports are done here (its prepare hook):
    # they start warm, where spawned workers imported the whole stack again (scipy.stats, statsmodels, the
    # estimator: ~3 s each, several runs' worth, which kept 2 workers at 1.3 times one, issue 26). This
    # process is as single-threaded as the one each run is forked from (cosim/supervise.py): the
    # progress bar's monitor thread only sleeps.
    fn = resolve_function(run) if isinstance(run, str) else run
    prepare = getattr(fn, "prepare", None)
    if callable(prepare):
        try:
            prepare()
        except Exception:  # noqa: BLE001 - each worker calls it again and records the failure with the run
            pass
    context = "fork" if "fork" in get_all_start_methods() else "spawn"
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=get_context(context), initializer=_pool_worker)
    try:
        futures = {pool.submit(execute, run, spec, timeout): spec for spec in specs}
        for future in as_completed(futures):
            try:
                on_done(future.result())
            except BrokenProcessPool as exc:  # a worker died outside a run's containment (killed, OOM)
                on_done(_lost(futures[future], f"crashed: its worker process died ({exc}); not retried"))
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _pool_worker() -> None:
    """A pool worker's start: it never starts a thread, and reaps its runs' children itself.

    Each run's child is reaped by its worker before the worker's next run (``runner.execute``), and the last
    ones as the worker exits (a ``multiprocessing`` finalizer), not by a thread per run (``supervise``'s
    default): every run is then forked from a single-threaded process, as from a Dask worker's zygote, and
    the runs' CPU is all in the worker's ``RUSAGE_CHILDREN`` when the pool is shut down (a reaper thread
    still waiting as its worker exited left its run uncounted: bench_campaign's pool CPU came out short).
    """
    from multiprocessing.util import Finalize

    from feeddrive.cosim import supervise

    supervise.REAP_IN_THREAD = False
    Finalize(None, supervise.reap, kwargs={"block": True}, exitpriority=0)
    one_blas_thread()  # for good: this process is the campaign's


def _check_scheduler(scheduler: str) -> None:
    """Refuse a malformed or unresolvable scheduler address before anything is written."""
    from distributed.comm.addressing import resolve_address

    try:
        resolve_address(scheduler)
    except (ValueError, OSError) as exc:
        raise CampaignError(f"--scheduler {scheduler}: {' '.join(str(exc).split())}; expected the address of a "
                            "Dask scheduler, such as tcp://host:8786") from None


#: seconds the campaign's client tries to reach its scheduler, at the start and again once it lost it (then the
#: campaign ends: ``SchedulerLost``)
CONNECT_TIMEOUT_S = 20


def _connect(scheduler: str, run: str | Callable) -> tuple[Any, list]:
    """A client of the Dask scheduler, and one task per worker that runs the run function's ``prepare`` hook:
    submitted now, the workers import while this process resolves the runs' scenarios."""
    from distributed import Client

    try:
        client = Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S}s", direct_to_workers=_loopback(scheduler) or None)
    except (OSError, TimeoutError) as exc:
        raise CampaignError(f"--scheduler {scheduler}: cannot connect to the Dask scheduler ({exc})") from None
    try:
        fn = resolve_function(run) if isinstance(run, str) else run
    except CampaignError:  # the runs' check names it
        return client, []
    if not callable(getattr(fn, "prepare", None)):
        return client, []
    try:
        return client, [client.submit(_prepare_worker, _pickled(run), key=f"campaign-prepare-{address}",
                                      workers=[address], pure=False) for address in client.scheduler_info()["workers"]]
    except Exception:  # noqa: BLE001 - only a head start: each run calls the hook anyway
        return client, []


def _pickled(run: str | Callable) -> bytes | str:
    """The run function as a Dask task gets it: its name as it is, a function pickled here (``zygote.load_run``
    unpickles it in the task, where a failure is the runs', not the worker's connection's)."""
    import cloudpickle  # a dependency of distributed: a run function of __main__ travels by value

    return run if isinstance(run, str) else cloudpickle.dumps(run, protocol=5)


def _loopback(scheduler: str) -> bool:
    """Whether the scheduler listens on this machine's loopback only (``local_cluster``'s): its workers are then
    on this machine too, and the client fetches each run's record from its worker itself, not through the
    scheduler (~1.4 ms less of this process's CPU a run, where the scheduler runs too). Elsewhere the workers
    may not be reachable from here: through the scheduler, as Dask does by default."""
    import ipaddress

    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        protocol, location = parse_address(scheduler)
        if protocol in ("inproc", "ipc"):
            return True
        host = parse_host_port(location)[0]
        return host == "localhost" or ipaddress.ip_address(host).is_loopback
    except (ValueError, TypeError):
        return False


def _prepare_worker(run: bytes | str) -> None:
    """A worker's head start: the run function's ``prepare`` (a failure is left to the runs, which record it), and
    its thread's zygote forked (``zygote.connect``), while this process checks the runs' scenarios: the first run
    no longer waits for it (~15 ms, a fork of the whole stack)."""
    from feeddrive.cosim.campaign.zygote import connect, load_run

    try:
        fn = load_run(run)
        getattr(resolve_function(fn) if isinstance(fn, str) else fn, "prepare")()
    except Exception:  # noqa: BLE001, S110 - execute calls it again and records the failure with each run
        pass
    connect()


#: the most runs in one Dask task (``batches``): a task costs ~14 ms of CPU in this process and the scheduler,
#: spread over its runs; more would delay the progress and lose more finished runs to an interruption
MAX_BATCH = 8
#: each task takes 1 / (BATCH_SHARE x threads) of the runs not yet cut into tasks
BATCH_SHARE = 2


def batches(specs: list[RunSpec], threads: int) -> list[list[RunSpec]]:
    """``specs`` cut in order into Dask tasks of decreasing size (guided self-scheduling).

    Each task holds ``ceil(R / (BATCH_SHARE * threads))`` of the R runs still to cut (1 to ``MAX_BATCH``): the
    first tasks amortise the task's cost over several runs, the last ones are single runs, so the workers,
    which take the next task as they finish one, end within about one run of each other. 32 runs on 2
    threads: tasks of 8, 6, 5, 4, 3, 2, 1, 1, 1, 1 runs.
    """
    out, k = [], 0
    while k < len(specs):
        size = min(MAX_BATCH, max(1, math.ceil((len(specs) - k) / (BATCH_SHARE * threads))))
        out.append(specs[k:k + size])
        k += size
    return out


def _dask(run, specs, client, on_done, timeout=None, recorded: Callable[[], int] | None = None,
          total: int | None = None) -> None:
    """Run ``specs`` on the cluster of ``client`` in tasks of a few runs (``batches``), at most one task per worker
    thread at a time.

    A scheduler that queues tasks itself (``_queues``: ``distributed.scheduler.worker-saturation`` <= 1, as
    ``local_cluster``'s) gets them all at once, as one group: it keeps them and hands a worker its next task as
    soon as the worker reports one done. Else the next task is submitted when one ends, not all at once: with
    them all submitted, a scheduler at the default saturation (1.1) gave each one-thread worker a second task
    behind the one it ran, so at the campaign's end one worker could still have two while the other idled
    (no work stealing: cluster.QUIET), and a run that killed its worker took the task queued behind it down
    too (the scheduler blames every task on a dead worker). That leaves each worker idle between its tasks
    for a round trip through this process, longer when this process is busy (issue 26).

    Each run's record is written as the run ends, not when its task does: the task publishes it as an event of
    this campaign's topic (``zygote.run_batch``, ``Worker.log_event``), which the scheduler forwards here
    (cosim/campaign/arrivals.py). Ctrl-C (which also stops a ``local_cluster``'s workers) then loses only the runs in
    progress, where it lost up to a whole task's finished runs (``MAX_BATCH``). The task's result, its records
    as each run's ``execute`` made them, stays the reference: it replaces the published copy in ``on_done``'s
    records without writing it again, and records a run whose event was lost. A task whose workers kept dying
    (``KilledWorker``) is cut into its runs not yet recorded, run again one by one: only the run that kills its
    worker is recorded as crashed. A cluster left without a worker is said on stderr (``arrivals.NoWorkers``,
    with ``recorded()`` of the campaign's ``total`` runs recorded): the tasks wait for a worker to join.
    """
    from distributed.scheduler import KilledWorker

    from feeddrive.cosim.campaign.arrivals import Arrivals, NoWorkers
    from feeddrive.cosim.campaign.zygote import run_batch  # the runs forked from their worker's zygote, if any

    payload, by_key, running = _pickled(run), {}, set()
    queue = list(reversed(batches(specs, _threads(client))))
    arrivals = Arrivals(client)

    def submit() -> Any:
        batch = queue.pop()
        future = client.submit(run_batch, payload, batch, timeout, arrivals.topic,
                               key=f"campaign-{batch[0].id}-{len(batch)}", pure=False)
        by_key[future.key] = batch
        running.add(future)
        return future

    def record(rec: dict, final: bool) -> None:
        if rec["id"] not in arrivals.recorded:
            arrivals.recorded.add(rec["id"])
            on_done(rec)
        elif final:  # published and written already: the task's own copy in the records
            on_done(rec, written=True)

    try:
        if _queues(client, len(queue)):
            queue.reverse()
            futures = client.map(run_batch, [payload] * len(queue), queue, [timeout] * len(queue),
                                 [arrivals.topic] * len(queue),
                                 key=[f"campaign-{batch[0].id}-{len(batch)}" for batch in queue], pure=False)
            by_key |= {f.key: batch for f, batch in zip(futures, queue)}
            running |= set(futures)
            queue.clear()
            pending = arrivals.completed(futures)
        else:
            pending = arrivals.completed([submit() for _ in range(min(len(queue), _threads(client)))])
        idle = NoWorkers(client, client.scheduler.address, recorded or (lambda: len(arrivals.recorded)),
                         total or len(specs))
        for future in arrivals.wait(pending, lambda rec: record(rec, False), idle.check):
            running.discard(future)
            free = _threads(client) - len(running) if queue else 0  # workers may have come or gone
            for _ in range(min(len(queue), max(free, 0 if running else 1))):
                pending.add(submit())  # before this task's records are written: its worker waits for it
            try:
                records = future.result()
            except CancelledError as exc:  # the client lost its scheduler (or someone cancelled the campaign's tasks)
                raise SchedulerLost(str(getattr(exc, "reason", None) or "its tasks were cancelled").replace("-", " ")) from None
            except KilledWorker as exc:  # the scheduler gave up after its allowed-failures: no endless retry
                batch = [spec for spec in by_key[future.key] if spec.id not in arrivals.recorded]
                if len(batch) > 1:  # which of its runs killed the workers: each alone
                    queue[:0] = [[spec] for spec in reversed(batch)]
                    if not running:
                        pending.add(submit())
                    continue
                records = [_lost(spec, f"crashed: Dask workers died running it ({exc})") for spec in batch]
            for rec in records:
                record(rec, True)
            arrivals.prune()
    finally:
        try:  # interrupted: the runs that ended meanwhile, recorded before the others are given up
            for rec in arrivals.drain():
                record(rec, False)
        finally:
            arrivals.close()
            with contextlib.suppress(Exception):  # a client that lost its scheduler has nothing to cancel
                client.cancel(list(running))


def _queues(client: Any, runs: int) -> bool:
    """Whether the scheduler would keep ``runs`` submitted at once and send each worker one per thread.

    Its ``worker-saturation`` must be at most 1 (a one-thread worker gets ``ceil(saturation)`` runs at a
    time), and the runs must be more than twice the cluster's threads, else the scheduler sends every one
    to a worker straight away (``Scheduler.is_rootish``: only a large group of tasks is queued)."""
    try:
        saturation = client.run_on_scheduler(_saturation)
    except Exception:  # noqa: BLE001 - a scheduler that refuses to run code (or an old one): the safe way
        return False
    return 0 < saturation <= 1 and runs > 2 * _threads(client)


def _saturation(dask_scheduler: Any) -> float:
    """On the scheduler: its ``distributed.scheduler.worker-saturation``."""
    return float(dask_scheduler.WORKER_SATURATION)


def _threads(client: Any) -> int:
    """The cluster's worker threads now (at least 1: runs wait for a worker to come)."""
    try:
        return max(1, sum(client.nthreads().values()))
    except Exception:  # noqa: BLE001 - the scheduler briefly unreachable: one run at a time meanwhile
        return 1


@dataclass
class CampaignResult:
    """Records of every run in index order, the aggregates, and how many runs this call executed."""

    out_dir: Path
    records: list[dict]
    executed: int
    aggregates: Aggregates

    @property
    def failed(self) -> list[dict]:
        return [r for r in self.records if r["status"] == "failed"]


def run_campaign(campaign: Campaign, out_dir: str | os.PathLike, *, workers: int = 1, scheduler: str | None = None,
                 progress: bool = False, overwrite: bool = False, retry_failed: bool = False,
                 run: Callable[[RunSpec], dict] | None = None, plots: bool = True,
                 timeout: float | None = None) -> CampaignResult:
    """Run (or resume) a campaign and write its records, aggregates and plots to ``out_dir``.

    Parameters
    ----------
    campaign : Campaign
    out_dir : path
        Holds ``campaign.json``, ``runs/<id>.json`` (one per finished run), ``detection.csv``,
        ``estimation.csv``, ``plots/``. Reopened runs with the same campaign resume.
    workers : int
        1: run in this process; > 1: a local process pool of that size. Ignored with ``scheduler``.
    scheduler : str or None
        Address of a running ``dask.distributed`` scheduler (``tcp://host:port``).
    progress : bool
        tqdm progress bar.
    overwrite : bool
        Discard the results of a different campaign in ``out_dir`` instead of refusing.
    retry_failed : bool
        Run the failed runs again (they are otherwise finished).
    run : callable or None
        Run function; default the campaign's ``run`` entry.
    plots : bool
        Draw the plots.
    timeout : float or None
        Wall-time limit of each run [s] (default the campaign's ``timeout``); a run over it is killed
        and recorded as failed (``hung``).
    """

    if workers < 1:
        raise CampaignError(f"--workers: expected >= 1, got {workers}")
    if timeout is not None and not timeout > 0:
        raise CampaignError(f"--timeout: expected a number of seconds > 0, got {timeout}")
    timeout = timeout if timeout is not None else campaign.timeout
    if scheduler:
        _check_scheduler(scheduler)
    out = Path(out_dir)
    done = _open_store(campaign, out, overwrite)
    specs = expand(campaign, out)
    ids = {s.id for s in specs}
    finished = {i: r for i, r in done.items() if i in ids and not (retry_failed and r["status"] == "failed")}
    pending = [s for s in specs if s.id not in finished]
    fn = run if run is not None else campaign.run
    client, warm = _connect(scheduler, fn) if scheduler and pending else (None, [])
    try:
        # a bad entry or scenario is one input error now, not N failed runs later
        check = getattr(resolve_function(fn) if isinstance(fn, str) else fn, "validate", None)
        for spec in pending if check else ():
            check(spec)
        if client is not None or workers > 1:
            pending = longest_first(fn, pending)
        try:
            _execute(campaign, fn, pending, len(specs), finished, out, workers, client, progress, timeout)
        except SchedulerLost as exc:
            raise SchedulerLost(f"--scheduler {scheduler}: lost the Dask scheduler during the campaign ({exc}); "
                                f"{len(finished)} of {len(specs)} runs recorded in {out}: the same command runs the "
                                "others when the cluster is back") from None
        except KeyboardInterrupt:  # Ctrl-C: what was kept, and how to go on (cosim campaign: "interrupted with ...")
            raise KeyboardInterrupt(f"with {len(finished)} of {len(specs)} runs recorded in {out}; the same command "
                                    "runs the others") from None
    finally:
        if client is not None:
            with contextlib.suppress(Exception):  # a client that lost its scheduler: its closing is all that is left
                client.cancel(warm)
            client.close()
    records = sorted(finished.values(), key=lambda r: r["index"])
    aggregates = aggregate(records)
    aggregates.write(out)
    if plots:
        plot_campaign(records, aggregates, out / "plots", campaign.base_scenario())
    return CampaignResult(out, records, len(pending), aggregates)


def longest_first(run: str | Callable, specs: list[RunSpec]) -> list[RunSpec]:
    """``specs`` by the run function's ``cost(spec)`` hook, the costliest first (ties in campaign order).

    On several workers the campaign ends when its last run does: a long run started last would keep one
    worker busy while the others idle. Unchanged when the hook is missing or cannot cost every run (None).
    """
    cost = getattr(resolve_function(run) if isinstance(run, str) else run, "cost", None)
    if not callable(cost):
        return specs
    costs = [cost(spec) for spec in specs]
    if any(c is None for c in costs):
        return specs
    order = sorted(range(len(specs)), key=lambda k: -costs[k])  # stable: equal costs keep their order
    return [specs[k] for k in order]


def _execute(campaign: Campaign, fn: str | Callable, pending: list[RunSpec], total: int, finished: dict[str, dict],
             out: Path, workers: int, client: Any, progress: bool, timeout: float | None) -> None:
    """Run the pending specs (on Dask when ``client``), writing each record as it comes."""
    from tqdm import tqdm

    bar = tqdm(total=total, initial=len(finished), desc=campaign.name, unit="run", disable=not progress)

    def on_done(record: dict, written: bool = False) -> None:
        """A finished run's record: written (atomic), kept, counted; only kept when ``written`` already."""
        if not written:
            _write_atomic(out / "runs" / f"{record['id']}.json", json.dumps(record, indent=1))
            bar.update(1)
        finished[record["id"]] = record

    try:
        if not pending:
            pass
        elif client is not None:
            _dask(fn, pending, client, on_done, timeout, recorded=lambda: len(finished), total=total)
        else:
            _local(fn, pending, min(workers, len(pending)), on_done, timeout)
    finally:
        bar.close()
