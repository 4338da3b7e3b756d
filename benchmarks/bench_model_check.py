"""The monitor's processing time per motion with the model check of issue 12 against the one before it.

Both are measured in the same run on the same motions: the healthy tool change of
examples/tool_change.yaml and a slow one (0.05 m/s, 0.4 m/s^2; ~6 s of motion), co-simulated once
each. ``MonitorPipeline.process`` (validation, estimation, model check, history in memory) is timed
alternately with the current ``check_model`` and with the former one, loaded from ``git show
REF:estimator/mismatch.py`` (default: b648c1d, the commit before the new check), best of ``--repeat``.
Target: ratio <= 1.5.

    python benchmarks/bench_model_check.py [--repeat 3] [--ref b648c1d]

As bench_estimator.py says, run with ``OPENBLAS_NUM_THREADS=1`` on a busy machine.
"""
from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import feeddrive.cosim.monitor as monitor
from feeddrive.cosim.monitor import MEASUREMENTS, MonitorConfig, MonitorPipeline, centred_speed
from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import load_scenario, scenario_from_dict
from feeddrive.estimator.history import History

ROOT = Path(__file__).resolve().parents[1]


def former_check(ref: str):
    """``check_model`` of ``ref`` behind the current call signature (its alpha 1e-3 and rms_tol 0.01)."""
    source = subprocess.run(["git", "-C", str(ROOT), "show", f"{ref}:estimator/mismatch.py"], check=True,
                            capture_output=True, text=True).stdout
    path = Path(tempfile.mkdtemp()) / "former_mismatch.py"
    path.write_text(source, encoding="utf-8")
    spec = importlib.util.spec_from_file_location("former_mismatch", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while the class is built
    spec.loader.exec_module(module)

    def check(u, i, w, h, parameters, filter, alpha, covariance=None, names=None, **_):
        return module.check_model(u, i, w, h, parameters, filter, 1e-3, rms_tol=0.01, covariance=covariance,
                                  names=names)
    return check


def motions() -> list[tuple[str, dict]]:
    base = load_scenario(ROOT / "examples" / "tool_change.yaml")
    slow = base.to_dict()
    slow["nc"]["program"][1]["tool_change"] |= {"v_max": 0.05, "accel": 0.4, "position": 0.15}
    out = []
    for name, scenario in (("tool change", base), ("slow tool change", scenario_from_dict(slow, base_dir=ROOT / "examples"))):
        with tempfile.TemporaryDirectory() as tmp:
            run = run_scenario(scenario, tmp, overwrite=True, plots=False)
        rows = np.flatnonzero(run.signals["nc.state"] == 1)
        signals = {k: run.signals[f"sensors.{k}"][rows] for k in MEASUREMENTS}
        signals["w_enc"] = centred_speed(signals["theta_enc"], signals["w_enc"], run.report["step_s"],
                                         MonitorConfig().encoder_window_s)
        out.append((name, signals))
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--ref", default="b648c1d")
    args = parser.parse_args()
    checks = {"new": monitor.check_model, "former": former_check(args.ref)}
    total = dict.fromkeys(checks, 0.0)
    for name, signals in motions():
        best = dict.fromkeys(checks, np.inf)
        for _ in range(args.repeat):
            for label, check in checks.items():  # alternately, so that a load change hits both
                monitor.check_model = check
                with History(":memory:") as history:
                    pipeline = MonitorPipeline(MonitorConfig(), history, "X")
                    tic = time.perf_counter()
                    pipeline.process(signals, 1e-4, 0.0, 1, 0.0)
                    best[label] = min(best[label], time.perf_counter() - tic)
        monitor.check_model = checks["new"]
        print(f"{name}: {len(signals['u'])} samples, monitor {best['new']:.3f} s with the new check, "
              f"{best['former']:.3f} s with the former one: ratio {best['new'] / best['former']:.2f}")
        for k in total:
            total[k] += best[k]
    ratio = total["new"] / total["former"]
    print(f"total: ratio {ratio:.2f} (target <= 1.5)")
    return 0 if ratio <= 1.5 else 1


if __name__ == "__main__":
    sys.exit(main())
