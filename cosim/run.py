"""One co-simulation run of a scenario, with everything it writes to its output directory.

Files in ``out_dir``::

    scenario.resolved.yaml   the scenario with every default filled, the FMU's absolute path and
                             sha256, the stop time and the complete connections (loadable again)
    signals.csv              time and every recorded signal, units in the header (partial on failure)
    signals.meta.json        how each column was sampled (cosim.recorder.Sampling): read by default
                             by ``cosim estimate`` and ``cosim monitor`` on this signals.csv
    report.json              run metadata, each component's report(), the monitor's motions
    report.html              the same as one self-contained page with every figure (cosim.report)
    plots/*.png              per high-speed motion: profiles and current residue (cosim.plots),
                             and the figures of components that draw their own (the monitor)

The monitor's history (SQLite) is ``monitor.db`` of the scenario; without it, ``cosim run`` uses
``runs/history.sqlite`` in the current directory (whatever the output directory) and other callers of
``run_scenario`` keep it in memory unless they pass ``default_history``.
"""
from __future__ import annotations

import datetime as _dt
import functools
import gc
import json
import os
import platform
import sys
import threading
import time as _time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from feeddrive.cosim.axis import parameter_units
from feeddrive.cosim.errors import InputError
from feeddrive.cosim.figure_jobs import FIGURE_MODULES, FigureBatch, run_figure_jobs
from feeddrive.cosim.master import Master
from feeddrive.cosim.plot_workers import PlotWorkers
from feeddrive.cosim.recorder import Sampling, write_sampling_sidecar
from feeddrive.cosim.scenario import Scenario, load_scenario

#: modules the monitor imports when it treats its first motion (estimator.distributions' scipy.special,
#: estimator.kernels' scipy.fft), imported while the simulation's compiled loop runs (cosim.run._import_meanwhile)
MONITOR_LATE_IMPORTS = ("scipy.special", "scipy.fft")
OUTPUTS = ("signals.csv", "signals.meta.json", "scenario.resolved.yaml", "report.json", "report.html")


class OutputExistsError(InputError):
    """The output directory is not empty and overwriting was not asked for."""


#: the YAML dumper of resolved.yaml: safe, in C when PyYAML was built with libyaml
_SAFE_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


@dataclass
class RunResult:
    """What a run produced.

    Attributes
    ----------
    out_dir : Path
    time : ndarray, shape (n,)
        Sample times [s].
    signals : dict name -> ndarray, shape (n,)
        Recorded signals (``component.port``).
    units : dict name -> str
    report : dict
        The content of report.json.
    paths : dict
        ``signals``, ``resolved``, ``report`` -> Path, and ``plots`` -> list of Path.
    """

    out_dir: Path
    time: np.ndarray
    signals: dict[str, np.ndarray]
    units: dict[str, str]
    report: dict
    paths: dict[str, Any] = field(default_factory=dict)


def run_scenario(scenario: Scenario | str | Path, out_dir: str | Path, *, progress: bool = False,
                 overwrite: bool = False, plots: bool = True, default_history: str | Path | None = None,
                 page: bool = True, signals: bool = True, workers: PlotWorkers | None = None) -> RunResult:
    """Run a scenario and write its output directory.

    Parameters
    ----------
    scenario : Scenario or path
        A loaded scenario or the path of a scenario file.
    out_dir : path
        Output directory; created if needed. Must be empty unless ``overwrite``.
    progress : bool
        Show a tqdm progress bar (only on a terminal).
    overwrite : bool
        Replace the files of an earlier run in a non-empty ``out_dir``.
    plots : bool
        Draw plots/*.png.
    default_history : path or None
        History file of a default monitor whose scenario names no ``monitor.db``; None keeps that
        history in memory (nothing persists). ``cosim run`` passes ``runs/history.sqlite``.
    page : bool
        Write report.html (False: a campaign run whose files are discarded; the page took a third of it).
    signals : bool
        Write signals.csv and signals.meta.json (False: a campaign run whose files are discarded; formatting
        the rows was a third of such a run). The signals are in the result either way.
    workers : PlotWorkers or None
        Drawing processes forked by the caller before this run's imports (``cosim run`` forks them first thing:
        their warm-up overlaps the imports and the scenario's loading): the run draws with them and ends them
        once it has (the caller closes them too, for a run that fails before). None: forked here.

    Returns
    -------
    RunResult

    Raises
    ------
    OutputExistsError
        ``out_dir`` is not empty and ``overwrite`` is False.
    cosim.errors.ScenarioError, cosim.errors.SimulationError
        Bad scenario; a failure during the run (report.json then has ``status: failed`` and
        signals.csv the rows recorded before it).
    """
    if not isinstance(scenario, Scenario):
        scenario = load_scenario(scenario)
    out_dir = prepare_out_dir(out_dir, overwrite)
    for old in [out_dir / n for n in OUTPUTS] + sorted((out_dir / "plots").glob("*.png")):
        old.unlink(missing_ok=True)
    paths: dict[str, Any] = {"signals": out_dir / "signals.csv", "resolved": out_dir / "scenario.resolved.yaml",
                             "report": out_dir / "report.json", "page": out_dir / "report.html", "plots": []}
    if not signals:
        del paths["signals"]
    report = report_header(scenario) | {
        "started": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "status": "running", "versions": _versions()}
    if default_history is not None:
        db = Path(default_history).resolve()
        updated = with_history(scenario, db) or scenario
        if updated is not scenario:  # the default history is used: its folder (runs/) is made on first use
            db.parent.mkdir(parents=True, exist_ok=True)
        scenario = updated
    # the figures' processes start first (cosim.plot_workers): their import of matplotlib overlaps the import of
    # the monitor (scipy, when its component is made) and the simulation, on another CPU
    if not plots and workers is not None:
        workers.close()
    workers = (workers or PlotWorkers(preload=FIGURE_MODULES)) if plots else None
    collecting = gc.isenabled()
    gc.disable()  # the monitor's imports make long-lived objects: no collector's passes over them (6 to 20 % of them)
    try:
        master = Master.from_scenario(scenario)
    except BaseException:
        if workers is not None:
            workers.close()
        raise
    finally:
        if collecting:
            gc.enable()
    wall = _time.perf_counter()
    importer = None
    try:
        master.setup()
        resolved = scenario.to_dict() | {"stop_time": float(f"{master.stop_time:.12g}"),  # drop n*h rounding
                                         "connections": master.connections}
        # libyaml's emitter when PyYAML has it: the same text, 1.4 ms instead of 11 ms of every run (a campaign's too)
        paths["resolved"].write_text(yaml.dump(resolved, Dumper=_SAFE_DUMPER, sort_keys=False), encoding="utf-8")
        report |= {"step_s": master.h, "stop_time_s": master.stop_time, "steps": master.n_steps}
        if signals:
            master.recorder.stream(paths["signals"])  # kept up to the last block if the process dies
            # the first row's machine time as the run's monitor dates its motions: a replay lands on the same times
            clock0 = getattr(master.components.get("monitor"), "clock0", None)
            write_sampling_sidecar(paths["signals"], master.h, column_sampling(scenario, master.recorder.names),
                                   start=None if clock0 is None else clock0 + master.t0)
        # imported while the compiled loop runs: the monitor's on its first motion, report.html's at the end
        importer = _import_meanwhile((MONITOR_LATE_IMPORTS if scenario.monitor is not None else ())
                                     + (("feeddrive.cosim.report.page",) if page else ()))
        early = _draw_motions_early(master, workers, out_dir / "plots", scenario.name) if workers is not None else {}
        recorder = master.run(progress=progress, signals_path=paths["signals"] if signals else None)
        report["loop"] = master.loop  # compiled fine loop or Python loop, and why (cosim/fastloop)
        report["components"] = master.reports()
        report["wall_time_s"] = round(_time.perf_counter() - wall, 3)
        signals = recorder.signals()
        if "plant.position" in signals and "nc.x_ref" in signals:
            from feeddrive.cosim.axis import following_note

            following = following_note(signals, "rad" if scenario.axis.kind == "rotary" else "m")
            if following:
                report["following"] = following
        if workers is not None:
            # report.html's template is loaded while the workers draw (its imports were made during the loop)
            paths["plots"] = workers.draw(plot_jobs(master, recorder.time, signals, out_dir / "plots", scenario.name,
                                                    early), meanwhile=_prepare_page if page else None)
            workers.close(wait=False)  # idle now: they exit while report.json and report.html are written
    except BaseException as exc:
        rec = master.recorder
        report |= {"status": "interrupted" if isinstance(exc, KeyboardInterrupt) else "failed",
                   "error": "interrupted (Ctrl-C / SIGINT)" if isinstance(exc, KeyboardInterrupt)
                   else f"{type(exc).__name__}: {exc}",
                   "wall_time_s": round(_time.perf_counter() - wall, 3),
                   "recorded_until_s": float(rec.time[-1]) if rec is not None and rec.n else None}
        _keep_judged(master, report)
        paths["report"].write_text(json.dumps(report, indent=2, default=_json_default), encoding="utf-8")
        if page:
            _write_page(out_dir, report)
        raise
    finally:
        master.terminate()
        if importer is not None:  # no thread outlives the run: a fork amid its import would inherit a held lock
            importer.join()
        if workers is not None:
            workers.close()
    report["status"] = "ok"
    monitor = report["components"].get("monitor")
    if isinstance(monitor, dict) and "motions" in monitor:
        report["motions"] = monitor["motions"]
        report |= {k: v for k, v in _set_up_notes(scenario, report).items() if v}
    report["files"] = {k: ([os.path.relpath(p, out_dir) for p in v] if k == "plots" else v.name)
                       for k, v in paths.items()}
    paths["report"].write_text(json.dumps(report, indent=2, default=_json_default), encoding="utf-8")
    if page:
        _write_page(out_dir, report)
    return RunResult(out_dir, recorder.time, signals, dict(zip(recorder.names, recorder.units)), report, paths)


def _keep_judged(master: Master, report: dict) -> None:
    """The motions the monitor judged before a run failed or was interrupted, into ``report`` (they are in the
    history already): a failed run keeps its results up to the failure."""
    component = master.components.get("monitor")
    if component is None:
        return
    try:  # the monitor's report alone: a failed FMU's is not asked for (its instance may be gone)
        monitor = component.report()
    except Exception:  # noqa: BLE001 - the failure is what the report says; its motions are a bonus
        return
    if isinstance(monitor, dict):  # its motions, thresholds and the motion it was inside (never judged)
        report["components"] = {"monitor": monitor}
        if monitor.get("motions"):
            report["motions"] = monitor["motions"]


def plot_jobs(master: Master, time: np.ndarray, signals: dict[str, np.ndarray], folder: Path, title: str,
              early: dict[int, list] | None = None) -> list:
    """The run's figures (cosim.plots) and those of components that draw their own (the monitor): as
    ``FigureJob`` s for the drawing processes, or a component's ``write_plots`` drawn in this process; a motion's
    run figures sent while the run went on (``early``: motion -> its submitted jobs) in their place."""
    jobs: list = run_figure_jobs(time, signals, folder, title, done=early)
    if jobs:  # made before any figure: the workers draw in any order
        folder.mkdir(parents=True, exist_ok=True)
    for comp in master.components.values():
        if callable(getattr(comp, "plot_jobs", None)):
            jobs += comp.plot_jobs(folder)
        elif callable(getattr(comp, "write_plots", None)):
            jobs.append(functools.partial(comp.write_plots, folder))
    return jobs


def _draw_motions_early(master: Master, workers: PlotWorkers, folder: Path, title: str) -> dict[int, list]:
    """Send each motion's run figures (cosim.plots) to a drawing process when the motion ends, while the run
    simulates the rest and the monitor treats the motion, instead of after the simulation. Returns the
    dict that collects ``motion -> [Submitted]``, filled as the motions end (for :func:`plot_jobs`).

    The monitor says when a motion ended (``Monitor.motion_ended``); the motion's samples are all recorded by
    then when the compiled loop runs (it hands its rows to the recorder before the monitor's step), not always in
    the Python loop (rows handed over per block): a motion not yet recorded whole is drawn at the end."""
    early: dict[int, list] = {}
    recorder = master.recorder

    def ended(motion: int, t_last: float) -> None:
        if recorder.n == 0 or recorder.t0 + (recorder.n - 1) * recorder.h < t_last - 0.5 * recorder.h:
            return
        jobs = run_figure_jobs(recorder.time, recorder.signals(), folder, title, only=motion)
        if jobs:
            folder.mkdir(parents=True, exist_ok=True)
            early[motion] = [workers.submit(FigureBatch(tuple(jobs)))]

    for comp in master.components.values():
        if hasattr(comp, "motion_ended"):  # the monitor (cosim.monitor.Monitor)
            comp.motion_ended = ended
    return early


def column_sampling(scenario: Scenario, names: Sequence[str]) -> dict[str, Sampling]:
    """How each recorded column is sampled (signals.meta.json): the sensors' analogue channels as their
    ``sampling`` says (a mean of one plant step is the instantaneous value), the encoder speed as the mean
    over its window, the plant's ``<role>_mean`` outputs over the plant's step, everything else instant."""
    h, m = scenario.step, scenario.plant.oversample
    sensors = scenario.sensors
    channels = {"Im1": sensors.current[0], "Im2": sensors.current[1], "u": sensors.voltage,
                "u_ref": sensors.voltage_ref, "w_tach": sensors.tachometer}
    out = {}
    for name in names:
        comp, _, port = name.partition(".")
        chan = channels.get(port) if comp == "sensors" else None
        if chan is not None and chan.sampling == "lowpass":
            out[name] = Sampling("lowpass", 1 / h, cutoff_hz=chan.cutoff_hz or 0.25 / h, order=chan.order)
        elif chan is not None and chan.sampling == "mean" and m > 1:
            out[name] = Sampling("mean", 1 / h, window_s=h)
        elif comp == "sensors" and port == "w_enc":
            window = max(1, round(sensors.encoder.speed_window / h)) * h
            out[name] = Sampling("mean", 1 / h, window_s=window)
        elif comp == "plant" and port.endswith("_mean"):
            out[name] = Sampling("mean", 1 / h, window_s=h / m)
        else:
            out[name] = Sampling("instant", 1 / h)
    return out


def _set_up_notes(scenario: Scenario, report: dict) -> dict[str, str | None]:
    """cosim.held_inputs' notes for this run (report.json ``held_inputs`` and ``sampling_bias``), from its plant's
    input hold, oversampling and voltage/current sampling; none for a user's plant component or the servo drive's
    own sensors (nothing is known of their sampling)."""
    from feeddrive.cosim.held_inputs import held_input_note, sampling_bias_note

    sensors, plant = scenario.sensors, report["components"].get("plant")
    if not isinstance(plant, dict) or not hasattr(sensors, "voltage") or not hasattr(sensors, "current"):
        return {}
    sampling = {"voltage": sensors.voltage.sampling, "current": sensors.current[0].sampling}
    hold, m, motions = plant.get("input_hold"), scenario.plant.oversample, report["motions"]
    return {"held_inputs": held_input_note(hold, m, sampling, motions),
            "sampling_bias": sampling_bias_note(hold, scenario.step, m, sampling, motions)}


def _write_page(out_dir: Path, report: dict) -> None:
    """report.html beside report.json, from the JSON just written (so the page shows exactly its values).

    A page that cannot be drawn must not hide the run's own result or error: it is reported on stderr."""
    from feeddrive.cosim.report import write_run_page

    try:
        write_run_page(out_dir, json.loads((out_dir / "report.json").read_text(encoding="utf-8")))
    except Exception as exc:  # noqa: BLE001 - the run's outcome is what matters here
        print(f"{out_dir / 'report.html'}: not written ({type(exc).__name__}: {exc})", file=sys.stderr)


def _import_meanwhile(modules: Sequence[str]) -> threading.Thread | None:
    """Import ``modules`` in a background thread: the simulation's compiled loop releases the GIL (ctypes), so
    the import runs on another CPU instead of in the monitor's treatment of the first motion. A module the
    monitor asks for before the thread is done waits for it (Python's per-module import lock); a failure is
    left to the monitor's own import to report. Returns the thread (None: nothing to import)."""
    import importlib

    def load() -> None:
        for name in modules:
            try:
                importlib.import_module(name)
            except Exception:  # noqa: BLE001 - the monitor's own import reports it
                pass

    if not modules:
        return None
    thread = threading.Thread(target=load, name="feeddrive-imports", daemon=True)
    thread.start()
    return thread


def _prepare_page() -> None:
    """Load what report.html needs (jinja2, the template compiled) before the run's data is final."""
    from feeddrive.cosim.report import prepare

    prepare()


def prepare_out_dir(out_dir: str | Path, overwrite: bool) -> Path:
    """Create ``out_dir``; refuse a non-empty one unless ``overwrite`` (raises OutputExistsError)."""
    out_dir = Path(out_dir)
    if out_dir.is_dir() and any(out_dir.iterdir()) and not overwrite:
        raise OutputExistsError(f"output directory {out_dir} is not empty; choose another one or allow "
                                "overwriting (--overwrite)")
    out_dir.mkdir(parents=True, exist_ok=True)
    return out_dir


def report_header(scenario: Scenario) -> dict[str, Any]:
    """The head of a run's report.json: scenario, axis and its drive chain, units, source and plant."""
    # the drive chain, and the units of the parameters (estimated on the motor side)
    return {"scenario": scenario.name, "axis": scenario.axis.name, "drive_chain": scenario.axis.model_dump(),
            "parameter_units": parameter_units("motor", scenario.axis.kind), "source": scenario.source,
            "plant": {"fmu": scenario.plant.fmu, "sha256": scenario.plant.sha256,
                      "interface": scenario.plant.interface} if scenario.nc is not None else None,
            # a unit the plant's map took on trust (not declared by the FMU) stays with the results, not only on
            # the console
            "unit_notes": [f"plant.map: {note}" for note in scenario.unit_notes]}


def with_history(scenario: Scenario, db: Path, replace: bool = False) -> Scenario | None:
    """The scenario with the built-in monitor's history file set to ``db``: when it names none, or
    always with ``replace`` (``cosim run --db``). None: the monitor is a user class (no ``db`` to set)."""
    spec = scenario.monitor
    config = getattr(spec, "config", None)
    if config is None or not hasattr(config, "db"):
        return None
    if config.db is not None and not replace:
        return scenario
    return scenario.model_copy(update={"monitor": spec.model_copy(
        update={"config": config.model_copy(update={"db": str(db)})})})


#: the packages whose versions report.json records, and their modules: a loaded module's ``__version__`` is read
#: (the distribution's metadata is searched for along sys.path: 25 ms a package, in the run before its simulation)
VERSIONED = (("feeddrive-monitor", "feeddrive.cosim"), ("fmpy", "fmpy"), ("numpy", "numpy"), ("casadi", "casadi"))


def _versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for pkg, module in VERSIONED:
        loaded = getattr(sys.modules.get(module), "__version__", None)
        if isinstance(loaded, str) and loaded != "0+unknown":  # feeddrive.cosim's mark of a tree never installed
            out[pkg] = loaded
            continue
        from importlib.metadata import PackageNotFoundError, version

        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            pass
    return out


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    if hasattr(obj, "model_dump"):
        return obj.model_dump(mode="json")
    if hasattr(obj, "to_dict"):
        return obj.to_dict()
    raise TypeError(f"report.json: cannot serialise {type(obj).__name__}")
