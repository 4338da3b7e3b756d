"""Campaign machinery: expansion, executors (in-process, local pool, Dask LocalCluster), resume, failures,
aggregates. The machinery tests use ``toy_run``, a pure-Python run function with known outcomes."""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from feeddrive.cosim.campaign import Campaign, CampaignError, aggregate, expand, load_campaign, run_campaign
from feeddrive.cosim.campaign.aggregate import (
    detection_curves,
    drift_outcome,
    drift_run,
    plot_campaign,
    sweep_label,
    sweep_unit,
)
from feeddrive.cosim.errors import ScenarioError

NOMINAL = {"R": 0.6, "L": 4.0e-3, "K": 1.05, "Jt": 0.1, "ft": 0.02, "Cd": 1.2}


def toy_run(spec):
    """A stand-in monitor with exact outcomes.

    Truth: nominal parameters with the scenario's plant.parameters. Estimates: LS = truth (1 +/- 2 %,
    sign alternating with the run index) with a +/-3 % CI; IV = truth (1 + 1 %) with a +/-0.5 % CI.
    Diagnosis when Cd is more than 20 % above nominal; sensor fault when |offset of sensor 1| > 0.1 A.
    """
    s = spec.scenario
    toy = s.get("toy", {})
    if toy.get("log"):
        with open(toy["log"], "a") as f:
            f.write(spec.id + "\n")
    if spec.index == toy.get("interrupt_at") and not Path(toy["log"] + ".interrupted").exists():
        Path(toy["log"] + ".interrupted").touch()
        raise KeyboardInterrupt
    truth = NOMINAL | s["plant"].get("parameters", {})
    if truth["Cd"] == toy.get("fail_if_Cd"):
        raise RuntimeError("broken FMU: fmi2DoStep returned fmi2Error")
    offset = s["sensors"]["current"][0]["offset"]
    e_ls = 0.02 if spec.index % 2 == 0 else -0.02

    def est(e, half):
        return {p: {"value": v * (1 + e), "ci95": [v * (1 + e - half), v * (1 + e + half)]} for p, v in truth.items()}

    plant = {p: truth[p] / NOMINAL[p] - 1 for p in truth if truth[p] != NOMINAL[p]}
    motion = {"validated": True, "parameters": est(0.01, 0.005), "method": "iv",
              "methods": {"ls": est(e_ls, 0.03), "iv": est(0.01, 0.005)},
              "sensor_faults": [{"sensor": "Im1", "kind": "offset"}] if abs(offset) > 0.1 else [],
              "diagnosis": [{"fault": "bearing or slide-way wear", "parameters": ["Cd"]}] if truth["Cd"] > 1.2 * 1.2 else []}
    return {"truth": truth, "injected": {"plant": plant, "sensors": {"Im1": {"offset": offset}} if offset else {}},
            "motions": [motion], "noise": float(np.random.default_rng(spec.seed).normal())}


def toy_drift(spec):
    """20 motions; Cd rises 2 %/motion from motion 5; the toy monitor diagnoses wear above +15 %."""
    motions = []
    for k in range(20):
        truth = NOMINAL | {"Cd": 1.2 * (1 + 0.02 * max(0, k - 4))}
        motions.append({"truth": truth, "validated": True, "sensor_faults": [],
                        "parameters": {p: {"value": v, "ci95": [v, v]} for p, v in truth.items()},
                        "diagnosis": [{"fault": "lack or ageing of lubricating oil", "parameters": ["Cd", "ft"]}]
                        if truth["Cd"] > 1.2 * 1.15 else []})
    return {"truth": NOMINAL, "injected": {}, "motions": motions}


def campaign(tmp_path, **toy):
    base = {"name": "toy", "plant": {"parameters": {"Cd": 1.2}},
            "sensors": {"seed": 0, "current": [{"offset": 0.0, "noise": 0.05}, {"offset": 0.0, "noise": 0.05}]},
            "toy": {"log": str(tmp_path / "executions.log")} | toy}
    return Campaign.model_validate({
        "name": "toy", "base": base, "seed": 7, "repetitions": 2, "root": str(tmp_path),
        "sweep": {"plant.parameters.Cd": [1.2, 1.3, 1.5], "sensors.current[0].offset": [0.0, 0.2]},
        "draw": {"sensors.current[1].noise": {"uniform": [0.02, 0.1]}},
        "run": "test_campaign:toy_run"})


def executions(tmp_path):
    return (tmp_path / "executions.log").read_text().split()


def test_expansion_is_deterministic_and_seeded(tmp_path):
    c = campaign(tmp_path)
    a, b = expand(c), expand(c)
    assert [(s.id, s.seed, s.overrides) for s in a] == [(s.id, s.seed, s.overrides) for s in b]
    assert len(a) == 3 * 2 * 2 and [s.index for s in a] == list(range(12))
    assert [s.overrides["plant.parameters.Cd"] for s in a] == [1.2] * 4 + [1.3] * 4 + [1.5] * 4
    assert [s.overrides["sensors.current[0].offset"] for s in a[:4]] == [0.0, 0.0, 0.2, 0.2]
    assert len({s.seed for s in a}) == 12 and all(s.scenario["sensors"]["seed"] == s.seed for s in a)
    noise = [s.scenario["sensors"]["current"][1]["noise"] for s in a]
    assert all(0.02 <= x <= 0.1 for x in noise) and len(set(noise)) == 12
    assert a[6].scenario["plant"]["parameters"]["Cd"] == 1.3 and a[6].scenario["sensors"]["current"][0]["offset"] == 0.2
    other = expand(c.model_copy(update={"seed": 8}))
    assert {s.seed for s in other}.isdisjoint({s.seed for s in a}) and [s.id for s in other] != [s.id for s in a]


def test_aggregates_of_known_outcomes_are_exact(tmp_path):
    res = run_campaign(campaign(tmp_path, fail_if_Cd=1.3), tmp_path / "out", plots=True)
    rows = {r["fault_class"]: r for r in res.aggregates.detection}
    # Cd 1.3 (+8 %) runs fail; Cd 1.5 (+25 %) is diagnosed; offset 0.2 A is always seen
    assert rows["(failed)"]["runs"] == 4 and len(res.failed) == 4
    assert all(r["reason"] == "RuntimeError: broken FMU: fmi2DoStep returned fmi2Error" for r in res.failed)
    assert rows["healthy"]["runs"] == 2 and rows["healthy"]["false_alarm_rate"] == 0.0
    assert (rows["plant:Cd"]["detection_rate"], rows["plant:Cd"]["isolation_rate"]) == (1.0, 1.0)
    assert rows["sensor:Im1"]["detection_rate"] == 1.0 and rows["sensor:Im1"]["isolation_rate"] == 1.0
    assert rows["plant:Cd & sensor:Im1"]["runs"] == 2 and rows["plant:Cd & sensor:Im1"]["mean_delay_motions"] == 0.0
    est = {(r["parameter"], r["method"]): r for r in res.aggregates.estimation}
    assert set(est) == {(p, m) for p in NOMINAL for m in ("ls", "iv", "monitor")}
    for p in NOMINAL:  # 4 finished runs without a sensor fault, LS errors +2 % and -2 % alternately, IV +1 %
        assert est[p, "ls"]["n"] == 4 and est[p, "ls"]["bias_pct"] == pytest.approx(0, abs=1e-9)
        assert est[p, "ls"]["rms_pct"] == pytest.approx(2.0, rel=1e-9) and est[p, "ls"]["coverage"] == 1.0
        assert est[p, "iv"]["bias_pct"] == pytest.approx(1.0, rel=1e-9) and est[p, "iv"]["coverage"] == 0.0
        # the monitor's validated parameters, scored apart: +1 % with a +/-0.5 % CI
        assert est[p, "monitor"]["n"] == 4 and est[p, "monitor"]["bias_pct"] == pytest.approx(1.0, rel=1e-9)
        assert est[p, "monitor"]["coverage"] == 0.0
    csv_rows = (tmp_path / "out" / "detection.csv").read_text().splitlines()
    assert csv_rows[0].startswith("fault_class,runs,detected") and len(csv_rows) == 1 + 5
    assert (tmp_path / "out" / "plots" / "detection_rate.png").stat().st_size > 0
    assert "plant:Cd" in res.aggregates.table()


def test_drift_delay_and_isolation():
    result = toy_drift(None)
    agg = aggregate([{"status": "ok", "result": result, "index": 0}])
    row = agg.detection[0]
    # onset at motion 5 (+2 %); +15 % first exceeded at motion 12 (+16 %): delay 7 motions
    assert row["fault_class"] == "plant:Cd" and row["mean_delay_motions"] == 7.0
    assert (row["detection_rate"], row["isolation_rate"], row["false_alarm_rate"]) == (1.0, 1.0, 0.0)


def test_interrupted_campaign_resumes_without_rerunning(tmp_path):
    c = campaign(tmp_path, interrupt_at=5)
    with pytest.raises(KeyboardInterrupt) as caught:
        run_campaign(c, tmp_path / "out", plots=False)
    # cosim campaign: "interrupted with 5 of 12 runs recorded in OUT; ..." (it said "interrupted" alone)
    assert str(caught.value) == f"with 5 of 12 runs recorded in {tmp_path / 'out'}; the same command runs the others"
    first = executions(tmp_path)
    assert len(first) == 6 and len(list((tmp_path / "out" / "runs").glob("*.json"))) == 5
    res = run_campaign(c, tmp_path / "out", plots=False)
    second = executions(tmp_path)[6:]
    ids = [s.id for s in expand(c)]
    assert second == ids[5:] and res.executed == 7 and len(res.records) == 12
    assert run_campaign(c, tmp_path / "out", plots=False).executed == 0 and len(executions(tmp_path)) == 13


def test_other_campaign_in_out_dir_is_refused(tmp_path):
    run_campaign(campaign(tmp_path), tmp_path / "out", plots=False)
    changed = campaign(tmp_path).model_copy(update={"seed": 1})
    with pytest.raises(CampaignError, match="another campaign.*--overwrite"):
        run_campaign(changed, tmp_path / "out", plots=False)
    assert run_campaign(changed, tmp_path / "out", plots=False, overwrite=True).executed == 12


@pytest.mark.slow
def test_local_pool_and_dask_give_identical_aggregates(tmp_path):
    from distributed import LocalCluster

    c = campaign(tmp_path, fail_if_Cd=1.3)
    serial = run_campaign(c, tmp_path / "serial", plots=False)
    pool = run_campaign(c, tmp_path / "pool", workers=2, plots=False)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        dask = run_campaign(c, tmp_path / "dask", scheduler=cluster.scheduler_address, plots=False)
    for other in (pool, dask):
        assert other.aggregates == serial.aggregates
        assert [(r["id"], r["status"], r["result"]) for r in other.records] == \
               [(r["id"], r["status"], r["result"]) for r in serial.records]
    assert len(executions(tmp_path)) == 36


#: pids of the processes that ran ``warm_toy_run.prepare`` (a forked worker inherits the list)
PREPARED: list[int] = []


def warm_toy_run(spec):
    return toy_run(spec)


warm_toy_run.prepare = lambda: PREPARED.append(os.getpid())


#: (task key, new state, runs processing on its worker) of each campaign run's transition to ``queued`` or
#: ``processing``, seen by ``_Dispatch`` on a LocalCluster's scheduler (which runs in this process)
DISPATCH: list[tuple[str, str, int]] = []


#: (topic, run id, the topic's events then stored) of each record a campaign's task published on the scheduler
#: of the ``local_cluster`` test
PUBLISHED: list[tuple[str, str, int]] = []


class _Dispatch:
    """A scheduler plugin recording how the scheduler hands out a campaign's runs (``DISPATCH``)."""

    idempotent = False
    name = "campaign-dispatch"

    def __init__(self, scheduler):
        self.scheduler = scheduler

    def log_event(self, topic, msg):
        if topic.startswith("feeddrive-campaign-"):  # a run's record, published as the run ended
            stored = len(self.scheduler.get_events(topic))
            PUBLISHED.append((topic, json.loads(msg)["id"], stored))

    def transition(self, key, start, finish, *args, **kwargs):
        if str(key).startswith("campaign-") and not str(key).startswith("campaign-prepare") \
                and finish in ("queued", "processing"):
            ws = self.scheduler.tasks[key].processing_on
            DISPATCH.append((str(key), finish, len(ws.processing) if ws is not None else 0))


@pytest.mark.slow
def test_local_cluster_forks_warm_workers_with_the_same_records(tmp_path, monkeypatch):
    """``local_cluster``: worker processes (not threads) forked from this process after the run's prepare hook
    ran here, so they start with its imports; the campaign's records are the serial run's. Its scheduler
    keeps the tasks (the 12 runs in 7 tasks, all submitted at once, more than twice its 2 threads) and gives
    each worker one at a time: no worker ever holds a second task behind the one it runs (cosim/campaign/
    execute.py ``_dask``). The runs are forked from a single-threaded zygote per worker (test_campaign_zygote.py)."""
    from distributed import Client
    from distributed.diagnostics.plugin import SchedulerPlugin
    from test_campaign_zygote import check_runs_forked_from_zygotes, check_server_closed
    from tqdm import tqdm

    from feeddrive.cosim.campaign import local_cluster

    c = campaign(tmp_path, fail_if_Cd=1.3)
    serial = run_campaign(c, tmp_path / "serial", run=warm_toy_run, plots=False)
    serial_ids = [r["id"] for r in serial.records]
    with tqdm(total=1, disable=False, file=open(os.devnull, "w")) as bar:  # noqa: SIM115 - closed by tqdm
        bar.update(1)
    monitor = tqdm.monitor  # a thread that takes tqdm's lock every 10 s: stopped before the zygote server's fork
    assert monitor is not None and monitor.is_alive()
    PREPARED.clear()
    DISPATCH.clear()
    PUBLISHED.clear()
    monkeypatch.setattr("feeddrive.cosim.campaign.arrivals.KEPT", 2)  # the scheduler's copies pruned every 2 runs
    with local_cluster(2, run=warm_toy_run) as cluster, Client(cluster) as client:
        cluster.scheduler.add_plugin(type("Dispatch", (_Dispatch, SchedulerPlugin), {})(cluster.scheduler))
        seen = client.run(lambda: (os.getpid(), list(PREPARED)))
        dask = run_campaign(c, tmp_path / "dask", scheduler=cluster.scheduler_address, run=warm_toy_run, plots=False)
        dispatch = list(DISPATCH)  # this campaign's runs
        # each run's record came as an event of the campaign's own topic as the run ended (cosim/campaign/
        # arrivals.py), whose copies the scheduler dropped as the campaign went (KEPT) and at its end
        published = list(PUBLISHED)
        assert not [topic for topic in client.get_events() if topic.startswith("feeddrive-campaign-")]
        server, server_pid = cluster.zygote_server, cluster.zygote_server.pid
        assert not monitor.is_alive() and "tqdm_monitor" not in server.threads_at_fork
        check_runs_forked_from_zygotes(cluster, client, tmp_path)  # on this cluster: its start is the test's time
        # its workers were told to send a heartbeat every 5 s (cluster.HEARTBEAT_S), not Dask's 0.5 s; a worker applies
        # it from the reply to its next heartbeat (it starts at 1 s): on a loaded machine that may still be coming
        deadline = time.monotonic() + 20
        while True:
            beats = client.run(lambda dask_worker: dask_worker.periodic_callbacks["heartbeat"].callback_time)
            if set(beats.values()) == {5000.0} or time.monotonic() > deadline:
                break
            time.sleep(0.2)
    check_server_closed(server, server_pid)
    assert list(beats.values()) == [5000.0, 5000.0]
    assert len(seen) == 2 and all(pid != os.getpid() and prepared == [os.getpid()] for pid, prepared in seen.values())
    # 12 runs in 7 tasks of 3, 3, 2, 1, 1, 1, 1 runs (execute.batches): never a second task queued on a worker
    processing = [n for _, state, n in dispatch if state == "processing"]
    assert len(processing) == 7 and max(processing) == 1
    assert sum(state == "queued" for _, state, _ in dispatch) >= 5  # all but the first task of each worker
    assert len({p[0] for p in published}) == 1 and sorted(p[1] for p in published) == sorted(serial_ids)
    stored = [p[2] for p in published]
    assert max(stored) < len(stored) and any(b < a for a, b in zip(stored, stored[1:]))  # pruned on the way
    assert dask.aggregates == serial.aggregates
    assert [(r["id"], r["status"], r["result"]) for r in dask.records] == \
           [(r["id"], r["status"], r["result"]) for r in serial.records]
    with pytest.raises(CampaignError, match="workers: expected >= 1, got 0"):
        local_cluster(0)


def test_campaign_file_errors_name_key_and_line(tmp_path):
    (tmp_path / "base.yaml").write_text("name: b\nplant: {parameters: {Cd: 1.2}}\n")
    good = {"name": "c", "base": "base.yaml", "sweep": {"plant.parameters.Cd": [1.2, 1.5]}}
    cases = [
        ({"sweeps": {}}, r"c\.yaml:5: sweeps: unknown key"),
        ({"draw": {"plant.parameters.R": {"uniform": [1.0, 0.5]}}}, r":7: draw\.plant\.parameters\.R\.uniform: expected \[low, high\]"),
        ({"draw": {"plant.parameters.R": {"uniform": [0, 1], "choice": [1]}}}, r":6: .*exactly one of uniform, normal, choice"),
        ({"draw": {"plant.parameters.Cd": {"choice": [1]}}}, r":1: .*keys given twice .*plant\.parameters\.Cd"),
        ({"sweep": {"plant..Cd": [1]}}, r":4: sweep\.plant\.\.Cd: not a dotted scenario key"),
        ({"sweep": {"plant.parameters.Cd": []}}, r":4: sweep\.plant\.parameters\.Cd: expected a non-empty list"),
        ({"base": "missing.yaml"}, r"c\.yaml:2: base: scenario file missing\.yaml not found"),
        ({"repetitions": 0}, r":5: repetitions: Input should be greater than 0"),
    ]
    path = tmp_path / "c.yaml"
    for change, pattern in cases:
        path.write_text(yaml.safe_dump(good | change, sort_keys=False, default_flow_style=None))
        with pytest.raises(CampaignError, match=pattern):
            load_campaign(path)
    path.write_text(yaml.safe_dump(good | {"sweep": {"sensors.current[3].offset": [0.1]}}))
    with pytest.raises(CampaignError, match=r"campaign c: sensors\.current\[3\]\.offset: the base scenario has no sensors\.current$"):
        expand(load_campaign(path))
    path.write_text(yaml.safe_dump(good))
    assert json.loads(json.dumps(load_campaign(tmp_path / "c.yaml").model_dump()))["name"] == "c"


@pytest.mark.slow
def test_cosimulation_campaign_tracks_cd_and_records_a_failing_fmu(tmp_path):
    """The real run function on the built-in FMU: 2 s tool changes at Cd = 1.2 and 1.8 N.m, and the same
    with an event making the electrical time constant L/R ~ 2e-8 s mid-run, far below the FMU's RK4
    substep: the integration diverges and the FMU refuses the step with fmi2Error."""
    base = {"name": "tiny", "step": 1e-4, "stop_time": 2.1, "plant": {"fmu": "builtin"},
            "nc": {"program": [{"dwell": {"time": 0.02}},
                               {"tool_change": {"position": 0.15, "v_max": 0.22, "accel": 0.8, "time": 0.02}}]},
            "monitor": {"baseline": "nominal"}}
    c = Campaign.model_validate({"name": "tiny", "base": base, "seed": 3, "root": str(tmp_path),
                                 "sweep": {"plant.parameters.Cd": [1.2, 1.8],
                                           "events": [[], [{"time": 0.5, "target": "plant.L", "value": 1e-8}]]}})
    bad = c.model_copy(update={"sweep": {"events": [[], [{"time": 0.5, "target": "plant.R", "value": -1.0}]]}})
    with pytest.raises(ScenarioError, match=r"campaign run 00001-\w+ .*events\[0\]\.value"):
        run_campaign(bad, tmp_path / "bad", plots=False)  # a bad scenario is found before anything runs
    assert not list((tmp_path / "bad" / "runs").glob("*.json"))
    res = run_campaign(c, tmp_path / "out", plots=False)
    ok = [r for r in res.records if r["status"] == "ok"]
    assert [r["overrides"]["events"] for r in ok] == [[], []] and len(res.failed) == 2
    assert all(r["reason"].startswith("FMIError: plant: fmi2DoStep returned fmi2Error at t=0.5") and "non-finite" in r["reason"]
               for r in res.failed), res.failed[0]["reason"]
    for r in ok:
        (motion,) = r["result"]["motions"]
        cd = r["overrides"]["plant.parameters.Cd"]
        assert motion["truth"]["Cd"] == cd and r["result"]["injected"]["plant"] == ({} if cd == 1.2 else {"Cd": pytest.approx(0.5)})
        for method in ("ls", "iv"):  # dry friction estimated within 3 % from one 2 s motion
            assert motion["methods"][method]["Cd"]["value"] == pytest.approx(cd, rel=0.03)
    rows = {r["fault_class"]: r for r in res.aggregates.detection}
    assert rows["plant:Cd"]["detection_rate"] == 1.0 and rows["plant:Cd"]["isolation_rate"] == 1.0
    assert rows["(failed)"]["runs"] == 2


def test_detection_curves_do_not_pool_the_other_swept_fault(tmp_path):
    """Cd x offset: each key's curve counts only the runs with the other key fault-free (offset 0, Cd 1.2).
    Pooled, Cd 1.3 (not diagnosed) showed detection 0.5 from the offset runs and offset 0 showed detection."""
    records = [{"status": "ok", "overrides": s.overrides, "result": toy_run(s)} for s in expand(campaign(tmp_path))]
    curves = detection_curves(records, ["plant.parameters.Cd", "sensors.current[0].offset"])
    cd, offset = curves["plant.parameters.Cd"], curves["sensors.current[0].offset"]
    assert cd["others"] == {"sensors.current[0].offset": 0.0} and offset["others"] == {"plant.parameters.Cd": 1.2}
    assert (cd["x"], cd["detection"], cd["false_alarm"], cd["runs"]) == (
        [1.2, 1.3, 1.5], [None, 0.0, 1.0], [0.0, None, None], [2, 2, 2])
    assert (offset["x"], offset["detection"], offset["isolation"], offset["false_alarm"]) == (
        [0.0, 0.2], [None, 1.0], [None, 1.0], [0.0, None])
    assert (cd["faulty"], cd["healthy"]) == ([0, 2, 2], [2, 0, 0])  # each rate's count, drawn with its interval
    from scipy.stats import binomtest

    from feeddrive.cosim.campaign.aggregate import _wilson

    for k, n in ((2, 2), (0, 2), (3, 7), (1, 30)):  # scipy's Wilson interval (the project's code imports no scipy.stats)
        ci = binomtest(k, n).proportion_ci(0.95, method="wilson")
        assert _wilson(k / n, n) == pytest.approx((ci.low, ci.high), rel=1e-12, abs=1e-15)
    assert (sweep_unit("sensors.current[0].offset"), sweep_unit("sensors.current[1].gain"),
            sweep_unit("plant.parameters.backlash"), sweep_unit("sensors.voltage.noise")) == ("A", "1", "rad", "V")
    (png,) = [p for p in plot_campaign(records, aggregate(records), tmp_path / "plots") if p.name == "detection_rate.png"]
    assert png.stat().st_size > 0


def test_a_swept_event_is_named_by_its_target_and_the_drift_figure_shows_a_diagnosed_run(tmp_path):
    """The wear campaign's figures read ``events[0].value`` without what it set or its unit, and showed the first
    drifting run (its smallest fault, not diagnosed) without saying which run it was or that it was missed."""
    base = {"events": [{"time": 6.05, "target": "plant.Cd", "value": 1.2}]}
    assert sweep_label("events[0].value", base) == "events[0].value (plant.Cd) [N.m]"
    assert (sweep_label("events[1].value", base), sweep_label("sensors.current[0].offset", base)) == (
        "events[1].value", "sensors.current[0].offset [A]")
    diagnosed = toy_drift(None)  # Cd +2 %/motion from motion 5, diagnosed above +15 %
    missed = toy_drift(None) | {"motions": [m | {"diagnosis": []} for m in toy_drift(None)["motions"][:8]]}
    records = [{"status": "ok", "id": f"0000{k}", "overrides": {}, "result": r} for k, r in enumerate((missed, diagnosed))]
    assert drift_run(records)["id"] == "00001"
    from feeddrive.cosim.campaign.aggregate import _change_text  # a swept events list ran off the title as its repr

    assert _change_text("events", [{"time": 3.24, "target": "plant.R", "value": 0.77}]) == "plant.R = 0.77 at 3.24 s"
    assert drift_outcome(diagnosed) == "diagnosed at motion 13 (the drift starts at motion 6)"
    assert drift_outcome(missed) == "not diagnosed (the drift starts at motion 6)"
    assert [p.name for p in plot_campaign(records, aggregate(records), tmp_path / "plots", base)] == ["drift.png"]


def test_resolved_scenario_is_reused_as_a_copy_until_its_fmu_changes(tmp_path, feeddrive_fmu):
    """``run_cosim``'s check resolves a run's scenario once per process; the run gets a copy of it (changing the
    copy leaves the next run's alone), and an FMU file rewritten since is resolved again (its new sha256)."""
    import hashlib
    import shutil
    import zipfile

    from feeddrive.cosim.campaign import cosim_run
    from feeddrive.cosim.scenario_plant import BUILTIN_MAP

    fmu = tmp_path / "plant.fmu"
    shutil.copy(feeddrive_fmu, fmu)
    base = {"name": "s", "step": 1e-3, "stop_time": 0.5, "nc": {"program": [{"dwell": {"time": 0.1}}]},
            "plant": {"fmu": "plant.fmu", "map": {r: {"var": v} for r, v in BUILTIN_MAP.items()}}}
    (spec,) = expand(Campaign(name="c", base=base, root=str(tmp_path), sweep={"plant.parameters.Cd": [1.5]}))
    cosim_run.run_cosim.validate(spec)
    first = cosim_run._scenario(spec)
    assert first.plant.sha256 == hashlib.sha256(fmu.read_bytes()).hexdigest() and first.plant.parameters["Cd"] == 1.5
    first.plant.parameters["Cd"] = 9.0
    assert cosim_run._scenario(spec).plant.parameters["Cd"] == 1.5
    with zipfile.ZipFile(fmu, "a") as z:  # still the same model, another archive
        z.writestr("documentation/note.txt", "rebuilt")
    again = cosim_run._scenario(spec)
    assert again.plant.sha256 == hashlib.sha256(fmu.read_bytes()).hexdigest() != first.plant.sha256


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("FEEDDRIVE_DASK_PROCESSES"), reason="spawns a Dask worker process (~5 s); "
                    "FEEDDRIVE_DASK_PROCESSES=1 runs it")
def test_preloaded_spawned_worker_has_the_runs_imports_before_its_first_task():
    """``--preload feeddrive.cosim.campaign.preload``: a spawned worker has every module of ``RUN_IMPORTS``
    before it runs anything (without the preload, statsmodels and the run's modules come with the first run),
    and its runs are forked from a zygote (cosim/campaign/preload.py)."""
    import sys
    import tempfile

    from distributed import Client, LocalCluster

    from feeddrive.cosim.campaign import preload
    from feeddrive.cosim.campaign.cosim_run import RUN_IMPORTS

    c = Campaign(name="z", base={"name": "s"}, run="test_campaign_zygote:where_am_i", repetitions=3)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None,
                      preload=["feeddrive.cosim.campaign.preload"]) as cluster, Client(cluster) as client:
        (missing,) = client.run(lambda: [m for m in RUN_IMPORTS if m not in sys.modules]).values()
        ((worker, server),) = client.run(lambda: (os.getpid(), preload.SERVER.pid)).values()
        res = run_campaign(c, Path(tempfile.mkdtemp()), scheduler=cluster.scheduler_address, plots=False)
    assert missing == []
    # its runs are forked from a one-thread zygote of the worker's own zygote server, not from the worker
    assert [r["result"]["parent_status"] for r in res.records] == [{"Threads": 1, "PPid": server}] * 3
    assert len({r["result"]["parent"] for r in res.records}) == 1 and server != worker


def test_a_discarded_campaign_run_writes_no_signals_and_gives_the_same_results(tmp_path, feeddrive_fmu):
    """run_scenario(signals=False), as a campaign run whose files are discarded: no signals.csv nor its sidecar
    (formatting them was a third of such a run), the same signals in memory and the same motions."""
    from feeddrive.cosim.run import run_scenario

    short = Path(__file__).parents[1] / "export" / "sensor_fault_short.yaml"
    full = run_scenario(short, tmp_path / "full", plots=False, page=False)
    lean = run_scenario(short, tmp_path / "lean", plots=False, page=False, signals=False)
    assert (tmp_path / "full" / "signals.csv").is_file()
    assert sorted(p.name for p in (tmp_path / "lean").iterdir()) == ["report.json", "scenario.resolved.yaml"]
    assert "signals" not in lean.report["files"] and lean.signals.keys() == full.signals.keys()
    for name, values in full.signals.items():
        assert np.array_equal(lean.signals[name], values, equal_nan=True), name
    strip = ("processing_s", "processing_cpu_s", "time", "wall_time_s")
    assert [{k: v for k, v in m.items() if k not in strip} for m in lean.report["motions"]] == \
           [{k: v for k, v in m.items() if k not in strip} for m in full.report["motions"]]


def test_dask_tasks_hold_fewer_runs_towards_the_campaigns_end():
    """``batches``: the runs in order, cut into tasks of ceil(R / (2 x threads)) of the R runs left (at most 8), so
    that the last tasks are single runs; every run in exactly one task."""
    from feeddrive.cosim.campaign.execute import batches

    specs = list(range(32))
    cut = batches(specs, 2)
    assert [len(b) for b in cut] == [8, 6, 5, 4, 3, 2, 1, 1, 1, 1] and sum(cut, []) == specs
    assert [len(b) for b in batches(specs[:5], 2)] == [2, 1, 1, 1] and batches([], 2) == []
    assert [len(b) for b in batches(list(range(200)), 4)] [:3] == [8, 8, 8] and sum(batches(specs, 1), []) == specs
