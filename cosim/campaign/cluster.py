"""A local Dask cluster whose worker processes start warm: forked from this process once the run function's
``prepare`` hook has run here.

Dask spawns a LocalCluster's workers by default: each starts a new interpreter and imports the whole stack
(the estimator, scipy.stats, statsmodels, pint's unit registry: ~1.5 s on an idle core, several runs' worth
at load) with its first run, which kept a fresh cluster of 2 workers well below 2 times one process
(issue 26). Forked (``distributed.worker.multiprocessing-method: fork``), the workers inherit this process's
imports, as the local pool's workers do (cosim/campaign/execute.py), and the cluster starts in a fraction of
the time. The cluster leaves out Dask's diagnostics that cost CPU (``QUIET``). Its workers do not fork the
runs themselves: a zygote server forked from here before the cluster's threads start forks each worker a
single-threaded zygote, which forks the worker's runs (cosim/campaign/zygote.py). A cluster started elsewhere
(``--scheduler``) cannot be forked from here; its workers run ``prepare`` once each, as their first task, and
fork the runs themselves.
"""
from __future__ import annotations

import socket
import weakref
from collections.abc import Callable
from multiprocessing import get_all_start_methods
from typing import Any

from feeddrive.cosim.campaign.zygote import ZygoteServer

#: Dask's diagnostics and housekeeping that cost CPU for nothing a campaign reads: the workers' statistical
#: profiler (a thread sampling every thread's stack every 10 ms: ~9 % of the workers' CPU on bench_campaign),
#: the event loops' tick every 20 ms and the system monitor every 0.5 s in each process, the scheduler's work
#: stealing every 100 ms (runs wait on the scheduler until a worker is free: nothing to steal), the memory
#: monitor of each worker and of its nanny every 100 ms (1 s still stops a runaway worker in time: a run's
#: memory grows with its process, not within a tenth of a second) and the active memory manager every 2 s
#: (a campaign's results are small and never replicated). An idle cluster of 2 workers then costs this process
#: (where the scheduler and the nannies run) 11 ms of CPU a second instead of 26, and each worker 5 instead
#: of 10 (getrusage over 10 s of an idle ``local_cluster(2)`` with a client, loaded machine): CPU the runs,
#: which share the cores with them, no longer lose. A worker-saturation of 1: the scheduler queues a campaign's runs and sends each worker one per
#: thread, the next as soon as it is done (cosim/campaign/execute.py ``_dask``), where the default 1.1 sends a
#: one-thread worker two
QUIET = {"distributed.worker.profile.enabled": False, "distributed.admin.tick.interval": "1s",
         "distributed.admin.system-monitor.interval": "5s", "distributed.scheduler.work-stealing": False,
         "distributed.scheduler.worker-saturation": 1.0, "distributed.worker.memory.monitor-interval": "1s",
         "distributed.scheduler.active-memory-manager.start": False}


def local_cluster(workers: int, run: str | Callable | None = None, **options: Any) -> Any:
    """A ``distributed.LocalCluster`` of ``workers`` worker processes (one thread each) forked warm, without
    the diagnostics of ``QUIET``, whose runs are forked from a zygote per worker (``zygote_server``).

    Parameters
    ----------
    workers : int
        Worker processes, >= 1.
    run : str or callable, optional
        The campaign's run function (``package.module:function`` or the function; default
        ``run_cosim``): its ``prepare`` hook runs here first, so that the forked workers have its imports.
    **options
        More ``LocalCluster`` keywords (e.g. ``dashboard_address``; default none).

    Returns
    -------
    distributed.LocalCluster
        With ``zygote_server`` (None where processes cannot fork). Close it (``with local_cluster(2) as cluster: run_campaign(..., scheduler=cluster.scheduler_address)``).
    """
    import dask
    import distributed  # noqa: F401 - its config defaults now: loaded inside dask.config.set they would go with it

    from feeddrive.cosim.campaign.execute import resolve_function
    from feeddrive.cosim.campaign.schema import CampaignError

    if workers < 1:
        raise CampaignError(f"workers: expected >= 1, got {workers}")
    if run is None:
        from feeddrive.cosim.campaign.cosim_run import run_cosim as run
    fn = resolve_function(run) if isinstance(run, str) else run
    prepare = getattr(fn, "prepare", None)
    if callable(prepare):
        prepare()
    method = "fork" if "fork" in get_all_start_methods() else "spawn"
    # forked now, before the cluster starts its event loop's thread: the zygotes the runs are forked from
    # (cosim/campaign/zygote.py) descend from this thread alone
    server = ZygoteServer() if method == "fork" and hasattr(socket, "AF_UNIX") else None
    try:
        with dask.config.set(QUIET | {"distributed.worker.multiprocessing-method": method}):
            cluster = _cluster_class()(**({"n_workers": workers, "threads_per_worker": 1, "processes": True,
                                           "dashboard_address": None, "worker_class": _nanny(method)} | options))
    except BaseException:
        if server is not None:
            server.close()
        raise
    cluster.zygote_server = server
    if server is not None:  # also when the cluster is dropped without being closed
        weakref.finalize(cluster, server.close)
    _slow_heartbeats(cluster.scheduler)
    return cluster


#: seconds between two heartbeats of a ``local_cluster``'s worker (Dask: 0.5 s up to 10 workers)
HEARTBEAT_S = 5.0


def _slow_heartbeats(scheduler: Any) -> None:
    """The scheduler (in this process) tells its workers to send a heartbeat every ``HEARTBEAT_S``, not 0.5 s.

    A heartbeat carries the worker's metrics (memory, CPU, transfers), which a campaign reads nowhere: each
    cost the worker ~1.2 ms of CPU and this process (the scheduler) ~0.6 ms, twice a second (an idle cluster
    of 2 workers: 10 ms of this process's CPU a second -> 8, 4 ms of each worker's -> 1.5). A dead worker is
    still seen at once (its connection closes, its nanny restarts it). The scheduler's own answer is kept
    but for the interval, which the worker applies to its next heartbeats (``Worker.heartbeat``).
    """
    handler = scheduler.handlers.get("heartbeat_worker")
    if handler is None:  # another Dask: its own heartbeats
        return

    def heartbeat_worker(*args: Any, **kwargs: Any) -> Any:
        reply = handler(*args, **kwargs)
        if isinstance(reply, dict) and isinstance(reply.get("heartbeat-interval"), (int, float)):
            reply["heartbeat-interval"] = max(reply["heartbeat-interval"], HEARTBEAT_S)
        return reply

    scheduler.handlers["heartbeat_worker"] = heartbeat_worker


_CLUSTER: list[type] = []


def _cluster_class() -> type:
    """A ``LocalCluster`` that stops its zygote server (``zygote_server``) when it closes."""
    if not _CLUSTER:
        from distributed import LocalCluster

        class CampaignCluster(LocalCluster):
            zygote_server: ZygoteServer | None = None

            async def _close(self) -> Any:
                try:
                    return await super()._close()
                finally:
                    if self.zygote_server is not None:
                        self.zygote_server.close()

        _CLUSTER.append(CampaignCluster)
    return _CLUSTER[0]


_NANNIES: dict[str, type] = {}


def _nanny(method: str) -> type:
    """A ``distributed.Nanny`` that starts its worker process with ``method`` (and ``QUIET``) every time.

    The nanny reads ``distributed.worker.multiprocessing-method`` when it starts a worker, and again when it
    restarts one that died (a run killed it, or the OOM killer): by then the setting in force was the
    default, so the new worker was spawned and imported the whole stack (~15 s under load) before its
    first run.
    """
    if method not in _NANNIES:
        import dask
        from distributed import Nanny

        class CampaignNanny(Nanny):
            async def instantiate(self) -> Any:
                with dask.config.set(QUIET | {"distributed.worker.multiprocessing-method": method}):
                    return await super().instantiate()

        _NANNIES[method] = CampaignNanny
    return _NANNIES[method]
