"""Campaign runs on a ``local_cluster`` are forked from a single-threaded zygote process per worker, not from the
multi-threaded Dask worker (cosim/campaign/zygote.py): a lock another thread of the worker held at the fork
could stay held for ever in the run's process, and the fork of the larger process cost ~20 ms a run."""
from __future__ import annotations

import os
import re
import sys
from pathlib import Path

from feeddrive.cosim.campaign import Campaign, local_cluster, run_campaign


def _status(pid: int) -> dict[str, int]:
    """Threads and parent of the process ``pid`` (Linux /proc)."""
    text = Path(f"/proc/{pid}/status").read_text()
    return {key: int(re.search(rf"^{key}:\s+(\d+)", text, re.M).group(1)) for key in ("Threads", "PPid")}


def where_am_i(spec):
    """A run function reporting the process its run was forked from: its pid, threads and parent."""
    parent = os.getppid()
    return {"truth": {}, "injected": {"plant": {}, "sensors": {}}, "motions": [], "parent": parent,
            "parent_status": _status(parent)}


def kill_my_zygote(spec):
    """Run 1 kills the process it was forked from (its zygote), from outside its containment."""
    import signal

    if spec.index == 1:
        os.kill(os.getppid(), signal.SIGKILL)
    return where_am_i(spec)


def interrupt_at(spec):
    """Ctrl-C to the campaign's process (``toy.pid``) at run ``toy.at``, once the runs before it are on disk
    (``toy.runs``, waited for up to 10 s: in the same Dask task, they are there only if written as each ended)."""
    import signal
    import time

    toy = spec.scenario["toy"]
    if spec.index == toy["at"]:
        deadline = time.monotonic() + 10.0
        while len(list(Path(toy["runs"]).glob("*.json"))) < toy["at"] and time.monotonic() < deadline:
            time.sleep(0.01)
        os.kill(toy["pid"], signal.SIGINT)
    return where_am_i(spec)


def _add_path(path: str) -> None:
    sys.path.insert(0, path)


def check_runs_forked_from_zygotes(cluster, client, tmp_path) -> None:
    """8 runs on the ``local_cluster`` of ``client`` (2 workers): each run's parent is a one-thread process forked by
    the cluster's zygote server, neither a Dask worker (which has several threads) nor this process; one zygote
    per worker, kept from one run to the next. Called by test_campaign.py's ``local_cluster`` test, whose
    cluster it uses (a cluster's start is most of such a test's time), which then checks ``check_server_closed``."""
    server = cluster.zygote_server
    workers = client.run(os.getpid)
    worker_threads = {pid: _status(pid)["Threads"] for pid in workers.values()}
    c = Campaign(name="z", base={"name": "s"}, run="test_campaign_zygote:where_am_i", repetitions=8)
    res = run_campaign(c, tmp_path / "zygotes", scheduler=cluster.scheduler_address, plots=False)
    assert [r["status"] for r in res.records] == ["ok"] * 8
    parents = {r["result"]["parent"] for r in res.records}
    assert len(parents) == len(workers) == 2 and not parents & (set(workers.values()) | {os.getpid()})
    assert [r["result"]["parent_status"] for r in res.records] == [{"Threads": 1, "PPid": server.pid}] * 8
    assert min(worker_threads.values()) > 1  # what the runs were forked from before
    # a run function the zygotes cannot load (its module is only on the workers' path, as client.upload_file
    # leaves it): its runs are forked from the workers, as without zygotes
    late = tmp_path / "late"
    late.mkdir()
    (late / "late_zygote_run.py").write_text("import os\n\ndef run(spec):\n    return {'truth': {}, 'injected': "
                                             "{'plant': {}, 'sensors': {}}, 'motions': [], 'parent': os.getppid()}\n")
    client.run(_add_path, str(late))
    sys.path.insert(0, str(late))
    try:
        from late_zygote_run import run
    finally:
        sys.path.remove(str(late))
    res = run_campaign(c, tmp_path / "late-runs", scheduler=cluster.scheduler_address, run=run, plots=False)
    assert [r["status"] for r in res.records] == ["ok"] * 8
    assert {r["result"]["parent"] for r in res.records} <= set(workers.values())
    # a run function the workers cannot import at all (its module only on this process's path): each run fails
    # with the reason, where the worker could not read the scheduler's message and the campaign hung for ever
    mine = tmp_path / "client-only"
    mine.mkdir()
    (mine / "client_only_run.py").write_text("def run(spec):\n    return {}\n")
    sys.path.insert(0, str(mine))
    try:
        from client_only_run import run
    finally:
        sys.path.remove(str(mine))
    res = run_campaign(c.model_copy(update={"repetitions": 3}), tmp_path / "unloadable", run=run, plots=False,
                       scheduler=cluster.scheduler_address)
    assert [r["reason"] for r in res.records] == ["run: the Dask worker cannot load the run function "
                                                  "(ModuleNotFoundError: No module named 'client_only_run'); name it "
                                                  "'package.module:function' of a module the workers can import "
                                                  "(installed there, or sent with client.upload_file)"] * 3
    assert [r["status"] for r in res.records] == ["failed"] * 3 and res.executed == 3


def check_server_closed(server, pid: int) -> None:
    """The closed cluster's zygote server is stopped and reaped, its socket removed."""
    assert server.pid is None and not Path(server.address).exists() and not Path(f"/proc/{pid}").exists()


def test_a_zygote_killed_under_a_run_fails_that_run_only(tmp_path):
    """Run 1 kills its zygote: it is recorded failed with the reason; runs 0 and 2 are ok, run 2 in a new zygote
    of the same worker."""
    c = Campaign(name="k", base={"name": "s"}, run="test_campaign_zygote:kill_my_zygote", repetitions=3)
    with local_cluster(1, run=kill_my_zygote) as cluster:
        res = run_campaign(c, tmp_path / "out", scheduler=cluster.scheduler_address, plots=False)
    assert [r["status"] for r in res.records] == ["ok", "failed", "ok"]
    assert res.records[1]["reason"].startswith("crashed: its zygote process died")
    assert res.records[0]["result"]["parent"] != res.records[2]["result"]["parent"]


def test_ctrl_c_keeps_the_runs_that_ended_in_an_unfinished_dask_task(tmp_path):
    """The first Dask task holds runs 0-5 (``batches``: 6, 3, 2, 1 of 12 runs on 1 thread); run 3 sends Ctrl-C to
    this process once runs 0-2 are on disk. They are there as each ended (published by the task, written by the
    campaign, cosim/campaign/execute.py ``_dask``), not when the task would have; the campaign stops with
    KeyboardInterrupt, the runs not started are not recorded."""
    import signal

    import pytest

    out = tmp_path / "out"
    c = Campaign(name="i", run="test_campaign_zygote:interrupt_at", repetitions=12,
                 base={"name": "s", "toy": {"at": 3, "pid": os.getpid(), "runs": str(out / "runs")}})
    handler = signal.signal(signal.SIGINT, signal.default_int_handler)  # pytest-xdist's workers may ignore it
    try:
        with local_cluster(1, run=interrupt_at) as cluster, pytest.raises(KeyboardInterrupt):
            run_campaign(c, out, scheduler=cluster.scheduler_address, plots=False)
    finally:
        signal.signal(signal.SIGINT, handler)
    recorded = sorted(int(f.name.split("-")[0]) for f in (out / "runs").glob("*.json"))
    assert recorded[:3] == [0, 1, 2] and recorded in ([0, 1, 2], [0, 1, 2, 3])


def test_records_come_straight_from_the_workers_of_a_scheduler_on_loopback_only():
    """The client fetches the records from the workers themselves (not through the scheduler) only when the
    scheduler listens on loopback, where its workers are on this machine too (cosim/campaign/execute.py)."""
    from feeddrive.cosim.campaign.execute import _loopback

    local = ["tcp://127.0.0.1:8786", "tcp://localhost:8786", "tcp://[::1]:8786", "tls://127.0.0.2:1", "inproc://x/1/2"]
    remote = ["tcp://10.0.0.2:8786", "tcp://host.example:8786", "tcp://0.0.0.0:8786", "not an address"]
    assert [_loopback(a) for a in local] == [True] * 5 and [_loopback(a) for a in remote] == [False] * 4
