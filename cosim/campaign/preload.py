"""Dask worker preload: the default run function's imports when the worker starts, not with its first run, and
a zygote server, so that the worker's runs are forked from single-threaded zygotes (cosim/campaign/zygote.py).

``dask worker tcp://HOST:8786 --preload feeddrive.cosim.campaign.preload`` (or ``LocalCluster(preload=[...])``)
runs ``run_cosim.prepare`` in each worker process as it starts: a spawned worker otherwise imports the stack
(the estimator, scipy.signal and scipy.stats, statsmodels with pandas, pint's registry: ~4 s of CPU) with
the campaign's first task (``execute._connect``), and on a fresh cluster of 2 workers that was about as
long as the 8 runs of bench_campaign. A cluster that stays up pays it once; ``local_cluster`` forks its
workers from a process that has the imports already and needs no preload.

The worker then forks its zygote server (one fork as it starts; a zygote per worker thread with its first
run): its runs are no longer forked from the worker itself, whose event loop, task and offload threads run
as it forks (a lock one of them held stays held for ever in the run's process). At this point the worker
has two other threads, both idle and holding no lock the zygotes take: the nanny's watch of its parent
(it sleeps) and of its stop queue (blocked on the queue, whose lock no zygote touches).
"""
from __future__ import annotations

import socket
from multiprocessing import get_all_start_methods
from typing import Any

#: this worker's zygote server (None before ``dask_setup``, or where processes cannot fork)
SERVER: Any = None


def dask_setup(worker: Any = None) -> None:
    """Dask's preload hook: ``run_cosim.prepare()`` in this worker process, then its zygote server."""
    global SERVER
    from feeddrive.cosim.campaign.cosim_run import run_cosim
    from feeddrive.cosim.campaign.zygote import ZygoteServer

    run_cosim.prepare()
    if SERVER is None and "fork" in get_all_start_methods() and hasattr(socket, "AF_UNIX"):
        SERVER = ZygoteServer(serve_here=True)


def dask_teardown(worker: Any = None) -> None:
    """Dask's hook as the worker closes: its zygote server stops."""
    global SERVER
    if SERVER is not None:
        SERVER.close()
        SERVER = None
