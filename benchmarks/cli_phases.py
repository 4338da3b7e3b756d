"""Where the wall time of ``cosim run``'s supervised child goes (``bench_cli.py --phases`` runs this).

    python benchmarks/cli_phases.py SCENARIO.yaml

Runs ``run_scenario`` as ``cosim run`` does, in this fresh interpreter (the drawing processes forked first, before
the run's imports, as cosim/cli/run.py does), and prints the time at which each phase ends (steps of the run wrapped
here to mark them; nothing else is changed): the drawing processes forked, imports, the scenario, the master made (the monitor's imports), each motion's run figures sent
to a drawing process when it ends, the simulation with the monitor in the loop, the figure jobs, report.html's preparation (while the figures are drawn), the figures,
report.json and report.html; and, per drawing process, when it warmed up and drew each figure (with the
figure's CPU time). Times depend on the machine's load.
"""
from __future__ import annotations

import os
import sys
import tempfile
import time

T0 = time.perf_counter()
MARKS: list[tuple[float, float, str]] = []  # (wall [s], this process's CPU [s], phase)

import feeddrive.cosim.plot_workers as pw  # noqa: E402

LOG = tempfile.mktemp(prefix="bench_cli_phases_")  # the drawing processes' lines (they are forked from here)
_job_call, _warm_up = pw.FigureJob.__call__, pw._warm_up


def mark(name: str) -> None:
    MARKS.append((time.perf_counter() - T0, time.process_time(), name))


def wrap(owner: object, attr: str, before: str | None = None, after: str | None = None) -> None:
    """Mark the start and end of ``owner.attr(...)``."""
    orig = getattr(owner, attr)

    def wrapper(*args, **kwargs):
        if before:
            mark(before)
        out = orig(*args, **kwargs)
        if after:
            mark(after)
        return out

    setattr(owner, attr, wrapper)


def _log(start: float, text: str) -> None:
    with open(LOG, "a", encoding="utf-8") as f:
        f.write(f"{start:.3f} {time.perf_counter() - T0:.3f} process {os.getpid()}: {text}\n")


def job_call(self):  # noqa: ANN001, ANN201 - FigureJob.__call__ in a drawing process
    start, cpu = time.perf_counter() - T0, time.process_time()
    out = _job_call(self)
    _log(start, f"{self.function} drawn ({time.process_time() - cpu:.2f} s CPU)")
    return out


def warm_up(preload: tuple[str, ...]) -> None:
    start, cpu = time.perf_counter() - T0, time.process_time()
    _warm_up(preload)
    _log(start, f"warmed up (matplotlib imported, a first figure drawn; {time.process_time() - cpu:.2f} s CPU)")


def main(scenario_path: str) -> None:
    pw.FigureJob.__call__, pw._warm_up = job_call, warm_up
    from feeddrive.cosim.figure_jobs import FIGURE_MODULES

    workers = pw.PlotWorkers(preload=FIGURE_MODULES)  # first, as cosim run does (cosim/cli/run.py)
    mark("drawing processes forked")
    import feeddrive.cosim.run as run
    from feeddrive.cosim.scenario import load_scenario

    mark("imports (cosim.run, cosim.scenario)")
    scenario = load_scenario(scenario_path)
    mark("scenario loaded")
    wrap(run.Master, "from_scenario", None, "master made (the monitor's imports)")
    wrap(pw.PlotWorkers, "submit", None, "a motion's run figures sent to a drawing process (the motion ended)")
    wrap(run, "plot_jobs", "simulation with the monitor (report.json wall_time_s)", "figure jobs made")
    wrap(run, "_prepare_page", None, "report.html prepared (while the figures are drawn)")
    wrap(pw.PlotWorkers, "draw", None, "figures drawn")
    wrap(run, "_write_page", "report.json written", "report.html written")
    with tempfile.TemporaryDirectory() as tmp:
        result = run.run_scenario(scenario, os.path.join(tmp, "run"), default_history=os.path.join(tmp, "h.sqlite"),
                                  workers=workers)
    workers.close()
    mark("run_scenario returned")
    rows = [(t, "", name, cpu) for t, cpu, name in MARKS]
    if os.path.exists(LOG):
        with open(LOG, encoding="utf-8") as f:
            for line in f:
                start, end, text = line.split(" ", 2)
                rows.append((float(end), f"(from {float(start):5.2f})", text.rstrip("\n"), 0.0))
        os.unlink(LOG)
    print("  end [s]  step [s]  CPU [s]   (CPU: of the run's process in the step: on an idle machine, the step's wall)")
    previous = previous_cpu = 0.0
    for t, start, name, cpu in sorted(rows):
        if start:  # a drawing process, alongside
            print(f"{t:8.2f}                     {name} {start}")
        else:
            print(f"{t:8.2f}  {t - previous:+7.2f}  {cpu - previous_cpu:7.2f}   {name}")
            previous, previous_cpu = t, cpu
    print(f"simulation with the monitor in the loop (wall_time_s): {result.report['wall_time_s']:.2f} s")


if __name__ == "__main__":
    main(sys.argv[1])
