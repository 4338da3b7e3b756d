"""A campaign of 6 runs on the faulty test FMU, one crashing (SIGSEGV) and one hanging: the 4 others finish
and are aggregated, the 2 are recorded failed with their reason, on the local pool and on Dask."""
from __future__ import annotations

import json
import os

import pytest
from faulty import MAP, MODES, build

from feeddrive.cosim.campaign import Campaign, run_campaign
from feeddrive.cosim.cli import main

TIMEOUT = 0.5


def sleepy(spec):
    """A run function (for the campaign's timeout): sleeps ``spec.options["sleep"]`` s unless index 0."""
    import time

    time.sleep(spec.options["sleep"] if spec.index else 0)
    return {"truth": {}, "injected": {"plant": {}, "sensors": {}}, "motions": []}


@pytest.fixture(scope="module")
def faulty_campaign(built_once) -> Campaign:
    fmu = built_once("Faulty", lambda folder: build(folder / "Faulty.fmu"))
    base = {"name": "faulty", "axis": "X", "step": 1e-3, "stop_time": 0.6,
            "plant": {"fmu": str(fmu), "parameters": {"mode": 0, "fail_time": 0.5}, "map": MAP, "call_timeout": 1.0},
            "nc": {"program": [{"rapid": {"to": 0.01, "v_max": 0.05, "accel": 0.5}}]}, "monitor": {}}
    # mode x fail_time: (segfault, 0.5 s) crashes and (loop, 0.5 s) hangs; fail_time 5 s is after the run's end
    return Campaign(name="faulty", base=base, root=str(fmu.parent),
                    sweep={"plant.parameters.mode": [MODES["none"], MODES["segfault"], MODES["loop"]],
                           "plant.parameters.fail_time": [0.5, 5.0]})


def check(result) -> None:
    by_mode = {(r["overrides"]["plant.parameters.mode"], r["overrides"]["plant.parameters.fail_time"]): r
               for r in result.records}
    assert len(result.records) == 6 and result.executed == 6
    failed = {k: r for k, r in by_mode.items() if r["status"] == "failed"}
    assert set(failed) == {(MODES["segfault"], 0.5), (MODES["loop"], 0.5)}
    assert failed[MODES["segfault"], 0.5]["reason"] == \
        "crashed: plant: the process crashed by signal SIGSEGV in fmi2DoStep at t=0.5 s"
    hung = failed[MODES["loop"], 0.5]
    assert hung["reason"] == "hung: plant: hung in fmi2DoStep at t=0.5 s: exceeded plant.call_timeout = 1 s; " \
        "the run was stopped (SIGKILL)"
    ok = [r for r in result.records if r["status"] == "ok"]
    assert len(ok) == 4
    for r in ok:  # each healthy run simulated its whole motion: one motion from 0 to the rapid's end (0.3 s)
        (motion,) = r["result"]["motions"]
        assert motion["start"] == 0 and motion["end"] == pytest.approx(0.3, abs=2e-3)
    rows = {row["fault_class"]: row for row in result.aggregates.detection}
    assert rows["(failed)"]["runs"] == 2 and sum(r["runs"] for k, r in rows.items() if k != "(failed)") == 4


def test_local_pool_records_the_crash_and_the_hang(tmp_path, faulty_campaign):
    check(run_campaign(faulty_campaign, tmp_path / "pool", workers=2, plots=False))
    stored = [json.loads(p.read_text()) for p in sorted((tmp_path / "pool" / "runs").glob("*.json"))]
    assert sorted(r["status"] for r in stored) == ["failed", "failed", "ok", "ok", "ok", "ok"]


def test_dask_local_cluster_records_the_crash_and_the_hang(tmp_path, faulty_campaign):
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        check(run_campaign(faulty_campaign, tmp_path / "dask", scheduler=cluster.scheduler_address, plots=False))


def test_run_timeout_from_the_campaign_file_and_the_option(tmp_path):
    """``timeout`` in the campaign file, overridden by the option: a run over it is killed and recorded hung."""
    c = Campaign(name="slow", base={"name": "s"}, run="test_campaign_containment:sleepy", repetitions=2,
                 run_options={"sleep": 30}, timeout=TIMEOUT)
    res = run_campaign(c, tmp_path / "a", plots=False)
    assert [r["status"] for r in res.records] == ["ok", "failed"]
    assert res.records[1]["reason"] == f"hung: hung outside any FMI call: exceeded the run's timeout of {TIMEOUT:g} s; " \
        "the run was stopped (SIGKILL)"
    assert TIMEOUT <= res.records[1]["elapsed_s"] < TIMEOUT + 2
    res = run_campaign(c, tmp_path / "b", plots=False, timeout=0.2)
    assert "timeout of 0.2 s" in res.records[1]["reason"] and res.records[1]["elapsed_s"] < 2


def test_cli_prints_the_failures_and_exits_0(tmp_path, faulty_campaign, capsys):
    path = tmp_path / "c.yaml"
    data = faulty_campaign.model_dump(mode="json", exclude={"root"})
    data["sweep"] = {"plant.parameters.mode": [MODES["none"], MODES["abort"]]}
    path.write_text(json.dumps(data))
    assert main(["campaign", str(path), "--out", str(tmp_path / "out"), "--no-plots", "--timeout", "30"]) == 0
    out = capsys.readouterr().out
    assert "2 runs (2 run now, 1 failed)" in out
    assert "crashed: plant: the process crashed by signal SIGABRT in fmi2DoStep at t=0.5 s" in out


def kill_my_worker(spec):
    """A run function that kills the process running it from outside its containment: the Dask worker
    (which sent the run to the zygote that forked it, cosim/campaign/zygote.py), as the kernel's OOM killer
    would."""
    import os
    import signal

    from feeddrive.cosim.campaign import zygote

    if spec.index == 1:
        os.kill(zygote.WORKER_PID or os.getppid(), signal.SIGKILL)
    return {"truth": {}, "injected": {"plant": {}, "sensors": {}}, "motions": [], "forked_from": FORKED_FROM}


#: set by the test before its cluster starts: a worker forked from the test's process has it, a spawned one None
FORKED_FROM = None


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("FEEDDRIVE_DASK_PROCESSES"), reason="starts and restarts Dask worker "
                    "processes (~3 s); FEEDDRIVE_DASK_PROCESSES=1 runs it")
def test_dask_worker_killed_under_a_run_is_recorded_not_retried_forever(tmp_path):
    """Run 1 kills its worker each time it runs: after the allowed failure (1) it is recorded as crashed, and
    the 7 others are ok. Tasks go to the cluster one per worker thread (cosim/campaign/execute.py), so no
    other task was ever on the worker that run 1 killed (the scheduler blames every task on a dead worker:
    with two on it, the other failed too). Run 1 is in the campaign's first task, with runs 0, 2 and 3
    (``batches``: 4, 2, 1, 1 runs): that task killed its worker twice, and was run again run by run, where
    only run 1 killed it. The worker is forked (``local_cluster``): its restarts take a fraction of a second,
    not the spawned worker's imports."""
    import dask

    from feeddrive.cosim.campaign import local_cluster

    global FORKED_FROM
    c = Campaign(name="killer", base={"name": "s"}, run="test_campaign_containment:kill_my_worker", repetitions=8)
    FORKED_FROM = os.getpid()
    try:
        with dask.config.set({"distributed.scheduler.allowed-failures": 1}), \
                local_cluster(1, run=kill_my_worker) as cluster:
            res = run_campaign(c, tmp_path / "out", scheduler=cluster.scheduler_address, plots=False)
    finally:
        FORKED_FROM = None
    assert [r["status"] for r in res.records] == ["ok", "failed"] + ["ok"] * 6
    assert res.records[1]["reason"].startswith("crashed: Dask workers died running it")
    # the runs after it ran on the worker restarted 4 times: forked from here as the first one was, not spawned
    assert {r["result"]["forked_from"] for r in res.records if r["status"] == "ok"} == {os.getpid()}
