"""The monitor's processing time per motion at 10 kHz, stage by stage, against one lstsq of the same size.

The healthy tool change of examples/tool_change.yaml (one 3.5 s motion at 10 kHz, 34879 samples) is
co-simulated once; ``MonitorPipeline.process`` (measurement validation, the residue check, LS + IV,
the paper's model check, diagnosis, history in memory; no plots) is then timed ``--repeat`` times (each on a
history opened and a pipeline built before its clock starts, as the monitor does once per run) and
the best CPU time (``time.process_time``: what the monitor's budget judges, and what a busy shared
machine disturbs least) and wall time are printed, with each stage's share (the stages' functions
wrapped with timers in the same runs) and the ratio against one ``numpy.linalg.lstsq`` of the
electrical regression (n x 3) measured in the same run. Target (issue 26): <= 50 ms per motion.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_monitor.py [--repeat 10] [--profile] [--decimation auto|D]

``--decimation`` sets ``EstimationOptions.decimation`` of the estimation and both model checks (default
``auto``; ``1``: every filtered sample, as before issue 26's decimation), so both are timed in the same hour.

``--profile`` adds the functions that take the time (cProfile, by own time). The machine's load is
printed first: absolute figures on a shared machine are only comparable at the same load.
"""
from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import sys
import tempfile
import time
from collections import defaultdict
from dataclasses import replace
from pathlib import Path

import numpy as np

import feeddrive.cosim.monitor_pipeline as monitor
from feeddrive.cosim.monitor import MEASUREMENTS, MonitorConfig, MonitorPipeline, centred_speed
from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import load_scenario
from feeddrive.estimator.estimate import EstimationOptions, MotionData, prepare
from feeddrive.estimator.filtering import clear_filter_memo
from feeddrive.estimator.history import History

ROOT = Path(__file__).resolve().parents[1]
TARGET_MS = 50.0
#: the stages of MonitorPipeline, as the names monitor_pipeline.py calls them by
STAGES = ("validate_measurements", "check_adequacy", "estimate_parameters", "check_signals", "check_model")


def tool_change() -> dict[str, np.ndarray]:
    """The monitor's inputs for the motion of examples/tool_change.yaml (as the component buffers them)."""
    with tempfile.TemporaryDirectory() as tmp:
        run = run_scenario(load_scenario(ROOT / "examples" / "tool_change.yaml"), tmp, overwrite=True, plots=False)
    rows = np.flatnonzero(run.signals["nc.state"] == 1)
    signals = {k: run.signals[f"sensors.{k}"][rows] for k in MEASUREMENTS}
    signals["w_enc"] = centred_speed(signals["theta_enc"], signals["w_enc"], run.report["step_s"],
                                     MonitorConfig().encoder_window_s)
    return signals


def timed(stage: str, fn, spent: dict[str, float]):
    def wrapper(*args, **kwargs):
        cpu = time.process_time()
        try:
            return fn(*args, **kwargs)
        finally:
            spent[stage] += time.process_time() - cpu
    return wrapper


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=10)
    parser.add_argument("--profile", action="store_true")
    parser.add_argument("--decimation", default="auto", help="auto (default) or a factor >= 1 (1: every sample)")
    args = parser.parse_args()
    decimation = args.decimation if args.decimation == "auto" else int(args.decimation)
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())} on {os.cpu_count()} CPUs, "
          f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}")
    signals, h = tool_change(), 1e-4
    config = MonitorConfig()
    # the baseline: one lstsq of the electrical regression of this motion on every sample (not decimated, so
    # that the ratios compare with the figures before the estimator decimated)
    reg = prepare(MotionData(h, u=0.5 * (signals["u"] + signals["u_ref"]), i=0.5 * (signals["Im1"] + signals["Im2"]),
                             w=signals["w_tach"]), EstimationOptions(filter=config.filter, decimation=1))
    elec = next(r for r in reg.regressions if r.equation == "electrical")
    y, Phi = elec.evaluate(reg.signals)
    lstsq = []
    for _ in range(5 * args.repeat):
        cpu = time.process_time()
        np.linalg.lstsq(Phi, y, rcond=None)
        lstsq.append(time.process_time() - cpu)
    base = min(lstsq)

    def run(clock: list[float] | None = None) -> dict:
        """One motion's ``process`` on a new history (the motion is the first of its axis, every repeat alike);
        ``clock`` receives (CPU, wall) of ``process`` alone: the history is opened and the pipeline built once per
        run of the monitor, not per motion, so they are outside the figure (opening the in-memory history and
        building the pipeline were ~2 ms of it before)."""
        clear_filter_memo()  # a new motion's signals: nothing filtered yet
        with History(":memory:") as history:
            pipeline = MonitorPipeline(config, history, "X")
            pipeline.estimation_options = replace(pipeline.estimation_options, decimation=decimation)
            tic, cpu = time.perf_counter(), time.process_time()
            result = pipeline.process(signals, h, 0.0, 1, 0.0).result
            if clock is not None:
                clock += [time.process_time() - cpu, time.perf_counter() - tic]
            return result

    result = run()  # warm: the compiled rollouts loaded, CasADi functions built
    best, wall, stages, whole = np.inf, np.inf, {}, np.inf
    originals = {s: getattr(monitor, s) for s in STAGES}
    try:
        for _ in range(args.repeat):
            spent: dict[str, float] = defaultdict(float)
            for s in STAGES:
                setattr(monitor, s, timed(s, originals[s], spent))
            clock: list[float] = []
            cpu = time.process_time()
            run(clock)
            whole = min(whole, time.process_time() - cpu)
            wall = min(wall, clock[1])
            if clock[0] < best:
                best, stages = clock[0], dict(spent)
    finally:
        for s in STAGES:
            setattr(monitor, s, originals[s])
    print(f"motion: {len(signals['u'])} samples at {1 / h:.0f} Hz, verdict {result['verdict']!r}, decimation "
          f"{decimation}: estimated at {result['estimation_rate_hz']:.0f} Hz")
    print(f"one lstsq ({len(y)} x {Phi.shape[1]}): {1e3 * base:.2f} ms CPU")
    print(f"monitor per motion: {1e3 * best:.1f} ms CPU ({best / base:.0f} x lstsq), best wall {1e3 * wall:.1f} ms; "
          f"target {TARGET_MS:.0f} ms (with opening the history and building the pipeline: {1e3 * whole:.1f} ms)")
    for s in STAGES:
        print(f"  {s:22} {1e3 * stages.get(s, 0.0):7.1f} ms  {stages.get(s, 0.0) / base:6.0f} x lstsq")
    other = best - sum(stages.values())
    print(f"  {'rest (diagnosis, history)':22} {1e3 * other:7.1f} ms")
    if args.profile:
        pr = cProfile.Profile(time.process_time)
        pr.enable()
        for _ in range(args.repeat):
            run()
        pr.disable()
        pstats.Stats(pr, stream=sys.stdout).sort_stats("tottime").print_stats(25)
    return 0


if __name__ == "__main__":
    sys.exit(main())
