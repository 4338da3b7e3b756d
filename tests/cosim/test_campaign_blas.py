"""One BLAS thread in every campaign run and in every ``cosim`` command: OpenBLAS's threads spin while they wait for
one another, and two campaign workers with two threads each were 1.13 times one worker (1.9 with one each; the
serial campaign itself 1.5 times slower), issue 26."""
from __future__ import annotations

import os
import subprocess
import sys

from test_campaign import campaign, toy_run
from threadpoolctl import threadpool_info, threadpool_limits

from feeddrive.cosim.campaign import run_campaign


def blas_threads_run(spec):
    """``toy_run`` with the BLAS libraries' threads of the run's process."""
    return toy_run(spec) | {"blas": sorted({lib["num_threads"] for lib in threadpool_info()
                                            if lib["user_api"] == "blas"})}


def test_a_campaign_runs_each_run_on_one_blas_thread_and_gives_the_caller_its_own_back(tmp_path):
    """In this process, on a local pool and on a ``local_cluster`` (its runs forked from zygotes)."""
    from feeddrive.cosim.campaign import local_cluster

    c = campaign(tmp_path).model_copy(update={"repetitions": 1})
    with threadpool_limits(2, user_api="blas"):  # a caller whose numpy runs two (a Python session without the variable)
        results = [run_campaign(c, tmp_path / "serial", run=blas_threads_run, plots=False),
                   run_campaign(c, tmp_path / "pool", workers=2, run=blas_threads_run, plots=False)]
        with local_cluster(2, run=blas_threads_run) as cluster:
            results.append(run_campaign(c, tmp_path / "dask", scheduler=cluster.scheduler_address, run=blas_threads_run,
                                        plots=False))
        after = {lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"}
    for result in results:
        assert {tuple(r["result"]["blas"]) for r in result.records} == {(1,)} and len(result.records) == 6
    assert after == {2}


def test_the_cosim_command_sets_one_blas_thread_unless_told_otherwise():
    probe = ("import os, sys; from feeddrive.cosim.cli import BLAS_THREADS; import numpy; "
             "from threadpoolctl import threadpool_info; "
             "print(os.environ['OPENBLAS_NUM_THREADS'], {l['num_threads'] for l in threadpool_info()})")
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, check=True).stdout
    assert out.split() == ["1", "{1}"]
    out = subprocess.run([sys.executable, "-c", probe], env=env | {"OPENBLAS_NUM_THREADS": "2"}, capture_output=True,
                         text=True, check=True).stdout
    assert out.split()[0] == "2" and "2" in out.split(maxsplit=1)[1]
