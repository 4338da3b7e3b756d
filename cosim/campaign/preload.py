"""Dask worker preload: the default run function's imports when the worker starts, not with its first run.

``dask worker tcp://HOST:8786 --preload feeddrive.cosim.campaign.preload`` (or ``LocalCluster(preload=[...])``)
runs ``run_cosim.prepare`` in each worker process as it starts: a spawned worker otherwise imports the stack
(the estimator, scipy.signal and scipy.stats, statsmodels with pandas, pint's registry: ~4 s of CPU) with
the campaign's first task (``execute._connect``), and on a fresh cluster of 2 workers that was about as
long as the 8 runs of bench_campaign. A cluster that stays up pays it once; ``local_cluster`` forks its
workers from a process that has the imports already and needs no preload.
"""
from __future__ import annotations

from typing import Any


def dask_setup(worker: Any = None) -> None:
    """Dask's preload hook: ``run_cosim.prepare()`` in this worker process."""
    from feeddrive.cosim.campaign.cosim_run import run_cosim

    run_cosim.prepare()
