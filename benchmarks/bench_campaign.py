"""Campaign throughput: runs per minute in this process, on a local process pool and on a Dask LocalCluster,
and the wall time of the drift example.

The same small campaign (short tool changes of the built-in plant, monitor in the loop, LS and IV
re-estimates) runs three times into fresh out dirs; the ratios are against the serial run measured in
the same invocation. The aggregates of the three must be identical (checked).

On a shared machine the wall-time speed-up says more about the other users than about the campaign, so
each mode's CPU time is measured too (``getrusage``: this process and the processes it waited for, the
pool's workers and the runs they forked; for Dask, read in each worker, with its zygotes' and their runs' for a
``local_cluster``, cosim/campaign/zygote.py), and the speed-up the mode would
have on ``--workers`` free cores is estimated as ``serial CPU / (this process's CPU + the workers' CPU /
workers)`` (the runs spread evenly over the workers). The pool's workers are forked from this process
once the run's imports are done; a fresh LocalCluster's workers import the stack with their first run
(``dask spawned``, Dask's default); ``dask warm`` is that cluster after one campaign, as a long-lived
cluster's workers are; ``dask`` is a fresh cluster of ``cosim.campaign.local_cluster``, whose workers are
forked from this process (warm, as the pool's), its runs in Dask tasks of a few (``execute.batches``) forked
from a zygote per worker. As for the pool, the campaign's time is ``run_campaign``'s;
a cluster's start is not in it and is printed apart (``start s``: the pool starts its workers inside
``run_campaign``). The load average is printed first.

Where the wall time goes: ``runs s`` is the time the runs took in their workers (the sum of the records'
``elapsed_s``, each run's ``execute``, divided by the workers: the wall time of perfectly balanced
workers), ``rest s`` the wall time beyond it: the serial parts in this process (the check of every run's
scenario before the first starts, the aggregation and its files), the executor's start and dispatch,
and the idle tail (one worker done while the other runs the last run).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_campaign.py [--runs 8] [--workers 2] [--drift-motions 20]
        [--repeat 1] [--dispatch] [--modes serial pool dask "dask spawned" "dask warm"]

``--dispatch`` measures only how long a ``local_cluster`` worker waits between two runs (runs that sleep,
so that the machine's load hardly matters), with the scheduler's queue and as the runs were submitted before.

``--repeat K`` runs every mode K times, in turn (serial, pool, dask, serial, ...), and prints each mode's
best round: the least wall time (its speed-up, ``runs s`` and ``rest s``) and the least CPU time (the CPU
columns and the speed-up on free cores); on a shared machine the best of several says more than one.
"""
from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
import warnings
from pathlib import Path

from feeddrive.cosim.campaign import Campaign, expand, run_campaign

ROOT = Path(__file__).resolve().parents[1]
BASE = {"name": "bench", "step": 1e-4, "stop_time": 2.1, "plant": {"fmu": "builtin"},
        "nc": {"program": [{"dwell": {"time": 0.02}},
                           {"tool_change": {"position": 0.15, "v_max": 0.22, "accel": 0.8, "time": 0.02}}]},
        "monitor": {"baseline": "nominal"}}


MODES = ("serial", "pool", "dask", "dask spawned", "dask warm")
#: wait before reading the CPU times [s]: a run's child is reaped in the background once its result is read
#: (cosim/supervise.py), and the last one's CPU was not counted yet (the serial campaign's CPU came out one
#: run short). A pool worker reaps its runs itself, the last ones as it exits (execute._pool_worker): all are
#: counted when the pool is shut down
SETTLE_S = 0.5


def _cpu() -> tuple[float, float]:
    """CPU seconds (user + system) of this process, and of the child processes it has waited for."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, children.ru_utime + children.ru_stime


def _worker_cpu() -> float:
    """In a Dask worker: its CPU seconds and its runs', with those of its zygotes (cosim/campaign/zygote.py), which
    fork the runs of a ``local_cluster`` and have not exited (their CPU is in no process's children yet)."""
    from feeddrive.cosim.campaign.zygote import zygote_cpu

    return sum(_cpu()) + sum(zygote_cpu())


def _late_imports(run, spec) -> list[str]:
    """The top-level names of the modules a run imports in a forked child after ``prepare``, as a campaign's runs."""
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: one run, then the modules it had to import
        os.close(read)
        before = set(sys.modules)
        run(spec)
        os.write(write, "\n".join(sorted({m.split(".")[0] if not m.startswith("feeddrive") else m
                                          for m in set(sys.modules) - before})).encode())
        os._exit(0)
    os.close(write)
    with os.fdopen(read) as f:
        text = f.read()
    os.waitpid(pid, 0)
    return text.split()


def _nap(spec) -> dict:
    """A run without CPU: 0.1 s asleep (``--dispatch``)."""
    time.sleep(0.1)
    return {"truth": {}, "injected": {"plant": {}, "sensors": {}}, "motions": []}


def _dispatch(workers: int, runs: int = 40, repeat: int = 3) -> None:
    """How long a ``local_cluster`` worker waits between two runs (``--dispatch``): runs that sleep 0.1 s, handed
    out by the scheduler's queue (``execute._dask``) or, as before, submitted by this process as runs end."""
    import importlib

    from feeddrive.cosim.campaign import local_cluster

    execute = importlib.import_module("feeddrive.cosim.campaign.execute")  # the module (the package's is the function)
    campaign, queues, best = Campaign(name="nap", base={"name": "s"}, repetitions=runs), execute._queues, {}
    with local_cluster(workers, run=_nap) as cluster, tempfile.TemporaryDirectory() as tmp:
        for k in range(repeat):
            for how in ("queued", "submitted one by one"):
                execute._queues = queues if how == "queued" else (lambda client, n: False)
                t = time.perf_counter()
                res = run_campaign(campaign, Path(tmp, f"{k}-{how[0]}"), scheduler=cluster.scheduler_address, run=_nap,
                                   plots=False)
                idle = (time.perf_counter() - t - sum(r["elapsed_s"] for r in res.records) / workers) / (runs / workers)
                best[how] = min(best.get(how, idle), idle)
    execute._queues = queues
    print(f"Dask dispatch, {runs} runs of 0.1 s asleep on {workers} workers, best of {repeat}: a worker waits "
          + "; ".join(f"{1e3 * t:.0f} ms a run {how}" for how, t in best.items()))


def _measure(mode: str, campaign: Campaign, out: Path, workers: int) -> dict:
    """One campaign with the executor of ``mode``: its result, wall time, CPU (this process, the workers),
    the cluster's start (Dask) and the runs' time in their workers."""
    from distributed import Client, LocalCluster

    from feeddrive.cosim.campaign import cosim_run, local_cluster

    # every mode resolves its runs' scenarios itself: none inherits those an earlier mode resolved here
    cosim_run._RESOLVED.clear()
    own, children = _cpu()
    start = None
    if mode.startswith("dask"):
        t = time.perf_counter()
        cluster = local_cluster(workers) if mode == "dask" else LocalCluster(
            n_workers=workers, threads_per_worker=1, dashboard_address=None)
        start = time.perf_counter() - t
        with cluster, Client(cluster) as client:
            if mode == "dask warm":  # a long-lived cluster: its workers ran a campaign before (another one)
                run_campaign(campaign.model_copy(update={"seed": 2}), Path(f"{out}-warm-up"),
                             scheduler=cluster.scheduler_address, plots=False)
            # the cluster's start-up is not the campaign's; the workers' CPU is read in the workers
            own, before = _cpu()[0], sum(client.run(_worker_cpu).values())
            t = time.perf_counter()
            res = run_campaign(campaign, out, scheduler=cluster.scheduler_address, plots=False)
            wall = time.perf_counter() - t
            time.sleep(SETTLE_S)
            own, children = _cpu()[0] - own, sum(client.run(_worker_cpu).values()) - before
    else:
        t = time.perf_counter()
        res = run_campaign(campaign, out, workers=1 if mode == "serial" else workers, plots=False)
        wall = time.perf_counter() - t
        time.sleep(SETTLE_S)
        own, children = (a - b for a, b in zip(_cpu(), (own, children)))
    return {"res": res, "wall": wall, "cpu": (own, children), "start": start,
            "busy": sum(r["elapsed_s"] or 0.0 for r in res.records)}  # each run's execute, in its worker


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=8, help="runs in the campaign")
    parser.add_argument("--workers", type=int, default=2, help="local processes and Dask workers")
    parser.add_argument("--drift-motions", type=int, default=20, help="motions of the drift example (0: skip)")
    parser.add_argument("--dispatch", action="store_true", help="only the Dask dispatch's wait between runs")
    parser.add_argument("--repeat", type=int, default=1, help="rounds of every mode; the best of each is printed")
    parser.add_argument("--modes", nargs="+", default=list(MODES), choices=MODES, help="the executors measured")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    if args.dispatch:
        _dispatch(args.workers)
        return 0
    from feeddrive.fmu_build import builtin_fmu

    builtin_fmu()  # build outside the timings
    from feeddrive.cosim.campaign.cosim_run import run_cosim

    run_cosim.prepare()  # this process's imports too: every mode starts from a process that has them
    campaign = Campaign(name="bench", base=BASE, seed=1, repetitions=args.runs,
                        sweep={"plant.parameters.Cd": [1.3]}, run_options={"methods": ["ls", "iv"]})
    # the first resolution's one-time costs (~0.13 s) outside the timings too, on another campaign's run: the
    # serial run, measured first, would otherwise pay them for every mode and flatter the speed-ups
    warm = expand(campaign.model_copy(update={"seed": 2}))[0]
    run_cosim.validate(warm)
    late = _late_imports(run_cosim, warm)
    if late:  # a run's child would import them again every run (cosim_run.RUN_IMPORTS)
        print(f"a run imports {len(late)} modules that run_cosim.prepare does not: {', '.join(late[:8])}", file=sys.stderr)
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())} on {os.cpu_count()} CPUs, "
          f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}")
    modes = ["serial"] + [m for m in MODES[1:] if m in args.modes]  # the serial run: the reference
    rounds: dict[str, list[dict]] = {mode: [] for mode in modes}
    aggregates = {}
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.repeat):  # the modes in turn, so that each round sees about the same load
            for mode in modes:
                m = _measure(mode, campaign, Path(tmp, f"{mode.replace(' ', '-')}-{k}"), args.workers)
                rounds[mode].append(m)
                aggregates[f"{mode} {k}"] = m["res"].aggregates
                if m["res"].failed:
                    print(f"{mode}: {len(m['res'].failed)} runs failed: {m['res'].failed[0]['reason']}", file=sys.stderr)
                    return 1
    # the best round of each mode: the least wall time, and (apart) the least CPU time
    times = {mode: min(r["wall"] for r in rs) for mode, rs in rounds.items()}
    best = {mode: min(rs, key=lambda r: r["wall"]) for mode, rs in rounds.items()}
    cpu = {mode: min((r["cpu"] for r in rs), key=sum) for mode, rs in rounds.items()}
    start = {mode: b["start"] for mode, b in best.items() if b["start"] is not None}
    busy = {mode: b["busy"] for mode, b in best.items()}
    same = all(a == aggregates["serial 0"] for a in aggregates.values())
    print(f"campaign of {args.runs} runs (2 s tool change, monitor, LS + IV), {args.workers} workers, best of "
          f"{args.repeat}; aggregates identical: {same}")
    print(f"{'mode':12} {'wall s':>8} {'runs/min':>9} {'speed-up':>9} {'CPU s':>7} {'(here':>6} {'workers)':>8} "
          f"{'on free cores':>14} {'start s':>8} {'runs s':>7} {'rest s':>7}")
    serial_cpu = sum(cpu["serial"])
    runs = {mode: busy[mode] / (1 if mode == "serial" else args.workers) for mode in times}
    for mode, t in times.items():
        own, children = cpu[mode]
        ideal = serial_cpu / (own + children / (1 if mode == "serial" else args.workers))
        print(f"{mode:12} {t:8.2f} {60 * args.runs / t:9.1f} {times['serial'] / t:9.2f} {own + children:7.1f} "
              f"{own:6.1f} {children:8.1f} {ideal:14.2f} {f'{start[mode]:8.2f}' if mode in start else '':8} "
              f"{runs[mode]:7.2f} {t - runs[mode]:7.2f}")
    print("this process's CPU a run (least of the rounds): " + ", ".join(
        f"{mode} {1e3 * cpu[mode][0] / args.runs:.1f} ms" for mode in times))
    if args.drift_motions:
        sys.path.insert(0, str(ROOT / "examples" / "drift_500"))
        from drift import run_drift

        with tempfile.TemporaryDirectory() as tmp:
            t = time.perf_counter()
            s = run_drift(Path(tmp), args.drift_motions, progress=False)
            wall = time.perf_counter() - t
        print(f"drift example: {s['motions']} motions in {wall:.1f} s ({wall / s['motions']:.2f} s/motion; "
              f"500 motions ~ {500 * wall / s['motions'] / 60:.1f} min)")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
