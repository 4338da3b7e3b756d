"""Wall time of a scenario under OSP libcosim with the exported FMUs, against ``cosim run``, in the same run.

Two runs of the same scenario (default: the healthy example), each timed over its stepping only:

* cosim     ``Master.run`` of the scenario (NC -> plant FMU -> sensors -> monitor; set-up, CSV, plots excluded)
* libcosim  the system written by ``export_system`` (plant FMU + pythonfmu FMUs of the NC, sensors and
            monitor) run by libcosimpy's ``simulate_until`` in a child process (loading excluded)

Prints both times, microseconds per step and the ratio libcosim / cosim (no target: it tells users what the
portability costs), and the monitor's R from each (they differ by the plant's input hold, see the README).

    python benchmarks/bench_export.py [--scenario examples/tool_change.yaml] [--repeat 1]
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from feeddrive.cosim.export.libcosim import run_osp_isolated
from feeddrive.cosim.export.system import export_system, stop_time
from feeddrive.cosim.master import Master
from feeddrive.cosim.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", type=Path, default=ROOT / "examples" / "tool_change.yaml")
    parser.add_argument("--repeat", type=int, default=1, help="runs of each; the best is reported")
    args = parser.parse_args()
    scenario = load_scenario(args.scenario)
    cosim_times, osp_times = [], []
    with tempfile.TemporaryDirectory(prefix="bench_export_") as tmp:
        for k in range(args.repeat):
            monitor = scenario.monitor.config.model_copy(update={"db": str(Path(tmp) / f"cosim{k}.sqlite")})
            s = scenario.model_copy(update={"monitor": scenario.monitor.model_copy(update={"config": monitor})})
            master = Master.from_scenario(s)
            master.setup()
            t = time.perf_counter()
            master.run()
            cosim_times.append(time.perf_counter() - t)
            cosim_r = master.components["monitor"].results[-1]["parameters"]["R"]["value"]
            master.terminate()
            steps = master.n_steps
            out = Path(tmp) / f"system{k}"
            monitor = scenario.monitor.config.model_copy(update={"db": str(out / "history.sqlite")})
            s = scenario.model_copy(update={"monitor": scenario.monitor.model_copy(update={"config": monitor})})
            export_system(s, out, ssp=False)
            run = run_osp_isolated(out, stop_time(s), {"monitor": ["R", "motions"]})
            osp_times.append(run.wall_s)
    c, o = min(cosim_times), min(osp_times)
    print(f"{scenario.name}: {steps} steps of {scenario.step:g} s")
    print(f"  cosim run   {c:8.2f} s  {1e6 * c / steps:8.1f} us/step   R = {cosim_r:.6g}")
    print(f"  libcosim    {o:8.2f} s  {1e6 * o / steps:8.1f} us/step   R = {run.values['monitor.R']:.6g} "
          f"({run.values['monitor.motions']} motion(s))")
    print(f"  ratio libcosim / cosim run = {o / c:.1f}")


if __name__ == "__main__":
    main()
