"""A campaign whose Dask scheduler goes away: one line (``SchedulerLost``, ``cosim campaign`` exit 1), the runs recorded
until then kept, and the same campaign resumed without them. It ended in a traceback of distributed's
``FutureCancelledError`` (exit 1), the user left to guess whether anything was kept."""
from __future__ import annotations

import threading
import time

import pytest
from test_campaign import campaign, toy_run

from feeddrive.cosim.campaign import run_campaign
from feeddrive.cosim.errors import SimulationError


def slow_toy_run(spec):
    """``toy_run`` after 0.1 s: the scheduler goes while runs are left."""
    time.sleep(0.1)
    return toy_run(spec)


@pytest.mark.slow
def test_a_lost_scheduler_keeps_the_runs_recorded_and_says_so(tmp_path, monkeypatch):
    import importlib

    from distributed import LocalCluster

    execute = importlib.import_module("feeddrive.cosim.campaign.execute")
    monkeypatch.setattr(execute, "CONNECT_TIMEOUT_S", 0.5)  # its attempts to reach it again: 0.5 s, not 20
    c = campaign(tmp_path)
    out, runs = tmp_path / "dask", tmp_path / "dask" / "runs"
    cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0")

    def lose_scheduler() -> None:  # once two runs are recorded
        deadline = time.monotonic() + 60
        while len(list(runs.glob("*.json"))) < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
        cluster.close()

    killer = threading.Thread(target=lose_scheduler)
    killer.start()
    try:
        with pytest.raises(execute.SchedulerLost) as caught:
            run_campaign(c, out, scheduler=cluster.scheduler_address, run=slow_toy_run, plots=False)
    finally:
        killer.join()
        cluster.close()
    recorded = len(list(runs.glob("*.json")))
    assert 2 <= recorded < 12
    assert isinstance(caught.value, SimulationError)  # cosim campaign: "failed: ...", exit 1
    assert str(caught.value) == (f"--scheduler {cluster.scheduler_address}: lost the Dask scheduler during the campaign "
                                 f"(scheduler connection lost); {recorded} of 12 runs recorded in {out}: the same "
                                 "command runs the others when the cluster is back")
    resumed = run_campaign(c, out, run=toy_run, plots=False)
    assert resumed.executed == 12 - recorded
    serial = run_campaign(c, tmp_path / "serial", run=toy_run, plots=False)
    assert [(r["id"], r["status"], r["result"]) for r in resumed.records] == \
           [(r["id"], r["status"], r["result"]) for r in serial.records]


@pytest.mark.slow
def test_a_cluster_left_without_a_worker_is_said_and_the_campaign_goes_on_when_one_joins(tmp_path, monkeypatch,
                                                                                         capsys):
    """The campaign sat silent, its progress bar stopped, while its tasks waited for a worker that never came."""
    from distributed import LocalCluster

    from feeddrive.cosim.campaign import arrivals

    monkeypatch.setattr(arrivals, "NO_WORKER_CHECK_S", 0.3)
    said_it, check = threading.Event(), arrivals.NoWorkers.check

    def watched(self) -> None:
        check(self)
        if self.said:
            said_it.set()

    monkeypatch.setattr(arrivals.NoWorkers, "check", watched)
    c = campaign(tmp_path)
    out, runs = tmp_path / "dask", tmp_path / "dask" / "runs"
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster:
        def worker_goes_and_comes() -> None:
            deadline = time.monotonic() + 60
            while len(list(runs.glob("*.json"))) < 2 and time.monotonic() < deadline:
                time.sleep(0.02)
            cluster.scale(0)
            said_it.wait(30)
            cluster.scale(1)

        mover = threading.Thread(target=worker_goes_and_comes)
        mover.start()
        try:
            result = run_campaign(c, out, scheduler=cluster.scheduler_address, run=slow_toy_run, plots=False)
        finally:
            mover.join()
    said = [line for line in capsys.readouterr().err.splitlines() if "has had no worker" in line]
    assert len(said) == 1, said
    recorded = int(said[0].split("join (")[1].split(" of 12")[0])
    assert 2 <= recorded < 12
    assert said[0] == (f"cosim campaign: the Dask scheduler {cluster.scheduler_address} has had no worker for 0.3 s: "
                       f"the runs wait for one to join ({recorded} of 12 recorded so far; Ctrl-C keeps them, and the "
                       "same command runs the others)")
    serial = run_campaign(c, tmp_path / "serial", run=toy_run, plots=False)
    assert [(r["id"], r["status"], r["result"]) for r in result.records] == \
           [(r["id"], r["status"], r["result"]) for r in serial.records]
