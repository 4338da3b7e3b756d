"""Run an exported system with OSP libcosim (libcosimpy): the system description as another master reads it.

libcosimpy is an optional dependency (``pip install libcosimpy``, in the ``test`` extra).

pythonfmu 0.7's binary is not safe to unload from, or outlive in, a Python process that hosts it (the
process crashes on a later garbage collection or at exit), so ``run_osp_isolated`` runs the system in a
child process (``python -m feeddrive.cosim.export.libcosim``), which prints the results as JSON and
leaves with ``os._exit`` before any of that happens.
"""
from __future__ import annotations

import ctypes
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree import ElementTree

from feeddrive.cosim.errors import InputError, SimulationError
from feeddrive.cosim.export.system import OSP_NS, SCENARIO_FILE, SYSTEM_FILE


@dataclass
class OspRun:
    """An exported system run by libcosim.

    Attributes
    ----------
    values : dict
        ``"simulator.variable"`` -> its value at the stop time, for the observed variables.
    wall_s : float
        Wall time of ``simulate_until`` [s] (loading and FMU instantiation excluded).
    steps : int
    """

    values: dict[str, float | int] = field(default_factory=dict)
    wall_s: float = 0.0
    steps: int = 0


def run_osp(folder: str | Path, stop: float, observe: Mapping[str, Sequence[str]], *, events: bool = True,
            ssp: bool = False) -> OspRun:
    """Load ``folder/OspSystemStructure.xml`` (and ``OspScenario.json`` when ``events``) into libcosim, run it
    to ``stop`` [s] and return the last values of the ``observe``\\ d variables (simulator -> names). With
    ``ssp``, the system comes from the folder's SSP archive instead (the step from OspSystemStructure.xml).

    Only the observed variables are read from the FMUs at each step (a last-value observer would read all
    of them, which for the monitor's 50 variables costs more than the step itself).

    Raises
    ------
    InputError
        libcosimpy is missing, the folder holds no exported system, an observed variable does not exist.
    SimulationError
        libcosim refused the system or a step failed.
    """
    try:
        from libcosimpy.CosimEnums import CosimVariableType
        from libcosimpy.CosimExecution import CosimExecution
        from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
        from libcosimpy.CosimManipulator import CosimManipulator
        from libcosimpy.CosimObserver import CosimObserver
    except ImportError:
        raise InputError("libcosimpy is not installed; expected 'pip install libcosimpy'") from None
    folder = Path(folder)
    if not (folder / SYSTEM_FILE).is_file():
        raise InputError(f"{folder}: no {SYSTEM_FILE}; expected a folder written by 'cosim export-system'")
    log_output_level(CosimLogLevel.ERROR)
    step_ns = round(float(ElementTree.parse(folder / SYSTEM_FILE).getroot().findtext(f"{{{OSP_NS}}}BaseStepSize"))
                    * 1e9)
    archives = sorted(folder.glob("*.ssp"))
    if ssp and len(archives) != 1:
        raise InputError(f"{folder}: expected one .ssp archive, found {len(archives)}")
    try:
        execution = (CosimExecution.from_ssp_file(str(archives[0]), step_size=step_ns) if ssp
                     else CosimExecution.from_osp_config_file(str(folder)))
    except AssertionError as exc:  # libcosimpy asserts on a refused configuration
        raise SimulationError(f"libcosim refused the system in {folder}: {exc}") from None
    slaves = {s.name.decode(): s.index for s in execution.slave_infos()}
    observer = CosimObserver.create_time_series(buffer_size=4)
    execution.add_observer(observer)
    watched = []
    for sim, names in observe.items():
        if sim not in slaves:
            raise InputError(f"observe: no simulator {sim!r}; the system has {', '.join(slaves)}")
        variables = {v.name.decode(): v for v in execution.slave_variables(slaves[sim])}
        for name in names:
            v = variables.get(name)
            if v is None:
                raise InputError(f"observe: simulator {sim!r} has no variable {name!r}")
            kind = CosimVariableType(v.type)
            if kind not in (CosimVariableType.REAL, CosimVariableType.INTEGER):
                raise InputError(f"observe: {sim}.{name} is a {kind.name}; expected a Real or Integer variable")
            observer.start_time_series(slaves[sim], v.reference, kind)
            watched.append((sim, name, v.reference, kind))
    if events and (folder / SCENARIO_FILE).is_file():
        manager = CosimManipulator.create_scenario_manager()
        execution.add_manipulator(manager)
        if not execution.load_scenario(manager, str(folder / SCENARIO_FILE)):
            raise SimulationError(f"libcosim refused {folder / SCENARIO_FILE}")
    wall = time.perf_counter()
    if not execution.simulate_until(round(stop * 1e9)):
        raise SimulationError(f"libcosim: the run of {folder / SYSTEM_FILE} failed before {stop:g} s")
    run = OspRun(wall_s=time.perf_counter() - wall, steps=execution.status().current_time // step_ns)
    for sim, name, ref, kind in watched:
        get = (observer.time_series_real_samples if kind == CosimVariableType.REAL
               else observer.time_series_integer_samples)
        _, steps, values = get(slaves[sim], ref, from_step=max(run.steps - 1, 0), sample_count=2)
        run.values[f"{sim}.{name}"] = values[-1]
    # Destroying an execution unloads pythonfmu's binary, which leaves Python objects pointing into it, and
    # frees its instances from a thread without the interpreter's lock: the process then crashes later (in
    # garbage collection). The execution is leaked on purpose, with an extra reference so that not even the
    # interpreter's shutdown destroys it; the FMUs have written their results (the monitor's history and
    # report are committed at the end of every motion).
    ctypes.pythonapi.Py_IncRef(ctypes.py_object(execution))
    return run


def run_osp_isolated(folder: str | Path, stop: float, observe: Mapping[str, Sequence[str]], *,
                     events: bool = True, ssp: bool = False, timeout: float | None = None) -> OspRun:
    """``run_osp`` in a child process (see the module docstring); same arguments and result."""
    import json
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "feeddrive.cosim.export.libcosim", str(folder), repr(float(stop)),
           json.dumps({k: list(v) for k, v in observe.items()})] + ([] if events else ["--no-events"]) \
        + (["--ssp"] if ssp else [])
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("{")]
    if proc.returncode != 0 or not lines:
        last = (proc.stderr.strip().splitlines() or ["(no message)"])[-1]
        raise SimulationError(f"libcosim run of {folder} failed (exit status {proc.returncode}): {last}")
    result = json.loads(lines[-1])
    if "error" in result:
        raise (InputError if result["kind"] == "input" else SimulationError)(result["error"])
    return OspRun(**result)


def _child(argv: list[str]) -> None:
    import json
    import os
    import sys

    folder, stop, observe = argv[0], float(argv[1]), json.loads(argv[2])
    if hasattr(os, "sched_setaffinity"):
        # libcosim steps the FMUs in parallel threads, and every Python FMU call takes the one interpreter
        # lock: handing it between threads on different cores cost 3x (158 against 56 us per step for the
        # NC, sensors and monitor FMUs alone); on one core the hand-over is cheap
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    try:
        run = run_osp(folder, stop, observe, events="--no-events" not in argv, ssp="--ssp" in argv)
        out = {"values": run.values, "wall_s": run.wall_s, "steps": run.steps}
    except (InputError, SimulationError) as exc:
        out = {"error": str(exc), "kind": "input" if isinstance(exc, InputError) else "simulation"}
    sys.stdout.write(json.dumps(out) + "\n")
    sys.stdout.flush()
    os._exit(0)  # skip the interpreter's shutdown, which pythonfmu's loaded binary would crash


if __name__ == "__main__":  # pragma: no cover - run by run_osp_isolated
    import sys

    _child(sys.argv[1:])
