"""What a campaign's worker keeps from one run to the next (issue 26): the FMU's inspection (version, archive
check, sha256, model description) read once per process until the file changes, and runs whose results do
not depend on it: the same run with its worker's caches cold or warm gives the same signals, bit for bit."""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
import time

from feeddrive.cosim import fmu_inspect
from feeddrive.cosim.campaign import Campaign, cosim_run, expand
from feeddrive.cosim.campaign.runner import _call, execute
from feeddrive.cosim.run import run_scenario  # here, not in each run's child
from feeddrive.cosim.supervise import supervise


def test_fmu_answers_are_kept_until_the_file_changes(tmp_path, feeddrive_fmu):
    """The second question is answered from the cache (the same description object); a file rewritten in place
    with the same size and mtime (only its ctime tells) is read again: its new sha256, not the cached one."""
    fmu = tmp_path / "plant.fmu"
    shutil.copy(feeddrive_fmu, fmu)
    md = fmu_inspect.model_description(fmu)
    assert fmu_inspect.model_description(fmu) is md and fmu_inspect.fmi_version(fmu) == "2.0"
    assert fmu_inspect.sha256(fmu) == hashlib.sha256(fmu.read_bytes()).hexdigest()
    st = fmu.stat()
    time.sleep(0.05)  # past the file system's timestamp granularity: the rewrite gets another ctime
    data = bytearray(fmu.read_bytes())
    data[len(data) // 2] ^= 0xFF  # one byte of the archive's content
    with open(fmu, "r+b") as f:  # in place: same inode, same size
        f.write(data)
    os.utime(fmu, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert (fmu.stat().st_size, fmu.stat().st_mtime_ns, fmu.stat().st_ino) == (st.st_size, st.st_mtime_ns, st.st_ino)
    assert fmu_inspect.sha256(fmu) == hashlib.sha256(bytes(data)).hexdigest() != hashlib.sha256(
        feeddrive_fmu.read_bytes()).hexdigest()
    fmu.unlink()
    assert fmu_inspect._identity(fmu) is None and fmu_inspect._identity(tmp_path) is None  # missing; a folder


def signal_digests(spec):
    """A campaign run as ``run_cosim`` runs it (its scenario from ``cosim_run._scenario``: the worker's resolution
    when there is one) without its figures: the SHA-256 of every recorded signal's samples."""
    with tempfile.TemporaryDirectory() as tmp:
        res = run_scenario(cosim_run._scenario(spec), tmp, plots=False, page=False)
    return {"time": hashlib.sha256(res.time.tobytes()).hexdigest(),
            **{k: hashlib.sha256(v.tobytes()).hexdigest() for k, v in res.signals.items()}}


signal_digests.validate = cosim_run.run_cosim.validate


def test_a_run_gives_the_same_signals_with_cold_and_warm_worker_caches():
    """One run three times: in a child of a process with nothing cached (it resolves its scenario and reads
    its FMU itself), then twice as a worker runs it (``execute``: resolved in the worker, the child inherits the
    scenario and the FMU's description). Every signal is equal, bit for bit."""
    base = {"name": "s", "step": 1e-4, "stop_time": 0.12, "plant": {"fmu": "builtin"},
            "nc": {"program": [{"dwell": {"time": 0.02}},
                               {"tool_change": {"position": 0.02, "v_max": 0.2, "accel": 0.8, "time": 0.01}}]}}
    (spec,) = expand(Campaign(name="c", base=base, seed=3, sweep={"plant.parameters.Cd": [1.4]}))
    fmu_inspect._CACHE.clear()
    cosim_run._RESOLVED.clear()
    cold = supervise(_call, signal_digests, spec)
    assert cold.status == "ok" and not fmu_inspect._CACHE and not cosim_run._RESOLVED
    warm = [execute(signal_digests, spec) for _ in range(2)]
    assert [r["status"] for r in warm] == ["ok", "ok"] and fmu_inspect._CACHE and cosim_run._RESOLVED
    digests = json.loads(cold.value)
    assert len(digests) > 20 and {"plant.speed", "sensors.Im1", "nc.state"} <= set(digests)
    assert digests == warm[0]["result"] == warm[1]["result"]


def test_the_longest_runs_start_first_on_several_workers(tmp_path):
    """``run_cosim.cost``: the plant steps of each run (its stop time, else the NC program's + the settling
    time, over the step, times the oversampling); ``longest_first`` orders the runs by it, ties in campaign
    order, and leaves them as they are when a run has no cost (not resolved here)."""
    from feeddrive.cosim.campaign.execute import longest_first
    from feeddrive.cosim.nc import SETTLING, plan_program
    from feeddrive.cosim.scenario import scenario_from_dict

    base = {"name": "s", "step": 1e-3, "plant": {"fmu": "builtin", "oversample": 2},
            "nc": {"program": [{"dwell": {"time": 0.05}}]}}
    c = Campaign(name="c", base=base, sweep={"stop_time": [0.2, 0.5, None, 0.5]})
    specs = expand(c)
    assert [cosim_run.run_cosim.cost(s) for s in specs] == [None] * 4  # not resolved in this process yet
    assert longest_first(cosim_run.run_cosim, specs) == specs
    for s in specs:
        cosim_run.run_cosim.validate(s)
    default = plan_program(scenario_from_dict(base).nc)[-1][0] + SETTLING
    costs = [cosim_run.run_cosim.cost(s) for s in specs]
    assert costs == [0.2 / 1e-3 * 2, 0.5 / 1e-3 * 2, default / 1e-3 * 2, 0.5 / 1e-3 * 2] and 0.2 < default < 0.5
    assert [s.index for s in longest_first(cosim_run.run_cosim, specs)] == [1, 3, 2, 0]
    assert longest_first("test_campaign:toy_run", specs) == specs  # no cost hook


def spin(spec):
    """A run that uses 0.1 s of CPU (its own, measured by itself) and reports it, and its parent's threads as it starts."""
    import re
    import resource
    from pathlib import Path

    threads = int(re.search(r"^Threads:\s+(\d+)", Path(f"/proc/{os.getppid()}/status").read_text(), re.M).group(1))
    while time.process_time() < 0.1:
        pass
    own = resource.getrusage(resource.RUSAGE_SELF)
    return {"truth": {}, "injected": {"plant": {}, "sensors": {}}, "motions": [], "cpu": own.ru_utime + own.ru_stime,
            "parent_threads": threads}


def test_pool_runs_are_forked_from_single_threaded_workers_and_their_cpu_is_all_counted(tmp_path):
    """On the local pool each run is forked from a worker with no other thread (its runs' children are reaped by
    the worker, not by a thread per run), and every run's CPU reaches this process's ``RUSAGE_CHILDREN`` once
    the campaign returns: the last runs were reaped before their workers exited (bench_campaign reads the
    pool's CPU there)."""
    import resource

    from feeddrive.cosim.campaign import run_campaign

    c = Campaign(name="spin", base={"name": "s"}, run="test_campaign_workers:spin", repetitions=6)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    res = run_campaign(c, tmp_path / "out", workers=2, plots=False)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    assert [r["status"] for r in res.records] == ["ok"] * 6
    assert [r["result"]["parent_threads"] for r in res.records] == [1] * 6
    runs = sum(r["result"]["cpu"] for r in res.records)
    assert runs >= 0.6 and (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime) >= runs
