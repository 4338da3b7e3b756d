"""Co-simulation master: integer ticks of the finest rate, Gauss-Seidel order, timed events, recorder.

Rates. Time is ``t0 + k hf`` with an integer tick k of the finest step ``hf = step / oversample``.
Each component steps every ``d`` ticks (its rate divisor, ``d hf`` is its communication step): the
plant and the sensors every tick, the NC every ``nc.cycle / hf`` ticks, the monitor and the user
components every ``oversample`` ticks (the recording step). A component placed before the first
fine-rate component in the stepping order (the NC: it feeds the plant) steps at the start of its
period, the others at its end (they read what the fine components produced over it). Rows are
recorded every ``oversample`` ticks; events land on the finest grid.

Components run in order (NC -> plant -> sensors -> monitor -> user components); at step n each one
reads the newest outputs of its sources from one flat list, the signal bus ``Y``: outputs at t_{n+1}
of the components before it and at t_n of those after it (see cosim/component.py). Connections are
compiled once into index getters on ``Y``; constants (a source given as a number) live at the end
of ``Y``. Time is ``t0 + n h`` with an integer n.

Two loops, the same results bit for bit (tests/cosim/test_fastloop.py). The fast path (``Master.loop`` says
which ran and why; report.json has it as ``loop``): when the plant is an FMI 2.0 Co-Simulation FMU with Real
outputs and the standard sensors follow it at the finest rate (cosim/fastloop/fine.py ``plan``), the two
step in compiled blocks (cosim/fastloop/fineloop.c, driven by cosim/fastloop/blocks.py) from one tick at which
a Python component steps or an event lands to the next, recording the rows inside the block. The standard NC
steps in the block too, and the monitor's steps that only buffer a motion's samples; the NC's steps that
insert an identification, the monitor's at a motion's start or end, and the user components step in Python.
Otherwise (Model Exchange, FMI 3.0, other sensors,
a plant split into FMUs, no C compiler, ``FEEDDRIVE_FASTLOOP=0``) every tick runs the Python loop.

Default wiring of the standard components (by port name; a scenario's ``connections`` override it)::

    plant.speed_ref, plant.load           <- nc
    nc.position <- plant, nc.request <- monitor (0.0 without a monitor)
    sensors.<role>                        <- plant.<role> (voltage_ref <- plant.voltage if unmapped)
    monitor.<port>                        <- sensors, else nc (state, motion); a PMSM's servo inputs
                                             <- servo (wired by the scenario, Scenario.servo_drive)
"""
from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from operator import itemgetter
from pathlib import Path
from typing import Any

from tqdm import tqdm

from feeddrive.cosim import fastloop
from feeddrive.cosim.component import Component, load_component_class
from feeddrive.cosim.errors import InputError, ScenarioError, SimulationError, format_path
from feeddrive.cosim.fastloop import blocks
from feeddrive.cosim.nc import SETTLING
from feeddrive.cosim.port_units import mismatch
from feeddrive.cosim.recorder import Recorder

#: preferred source components of each standard component's inputs
DEFAULT_SOURCES = {"plant": ("nc",), "nc": ("plant", "monitor"), "sensors": ("plant",), "monitor": ("sensors", "nc")}
#: fallbacks when no source component has the port
DEFAULT_FALLBACKS = {"sensors.voltage_ref": "plant.voltage", "sensors.voltage_ref_mean": "plant.voltage_mean",
                     "nc.request": 0.0}
#: steps between progress-bar updates and recorder flushes
BLOCK = 1000
#: largest accepted difference between the NC's start and the plant's initial position [m]
START_TOLERANCE = 1e-6

ErrorFactory = Callable[[tuple, str], InputError]


def event_step(time: float, t0: float, h: float) -> int:
    """Index n of the first grid point t0 + n h >= time (tolerance 1e-9 h, see cosim/component.py)."""
    return max(0, math.ceil((time - t0) / h - 1e-9))


def default_connections(ports: Mapping[str, tuple[Sequence[str], Sequence[str]]],
                        plant_parts: Sequence[str] = ()) -> dict[str, str | float]:
    """Default wiring of the standard components present in ``ports`` (name -> (inputs, outputs)).

    ``plant_parts``: FMU components that map some of the plant's roles (a plant split into several FMUs);
    the NC and the sensors read a role from the plant or, where the plant lacks it, from such a part.
    """
    wiring: dict[str, str | float] = {}
    for dst, sources in DEFAULT_SOURCES.items():
        sources = tuple(x for s in sources for x in ((s, *plant_parts) if s == "plant" else (s,)))
        for port in ports.get(dst, ((), ()))[0]:
            src = next((f"{s}.{port}" for s in sources if s in ports and port in ports[s][1]), None)
            fallback = DEFAULT_FALLBACKS.get(f"{dst}.{port}")
            if src is None and isinstance(fallback, str):
                comp, _, p = fallback.partition(".")
                src = fallback if comp in ports and p in ports[comp][1] else None
            elif src is None:
                src = fallback
            if src is not None:
                wiring[f"{dst}.{port}"] = src
    return wiring


def _scenario_error(path: tuple, message: str) -> ScenarioError:
    return ScenarioError(f"{format_path(path)}: {message}")


class Master:
    """Runs components over ``n_steps`` steps of ``step`` seconds.

    Parameters
    ----------
    components : sequence of (name, Component)
        In stepping order.
    step : float
        Communication step h [s].
    n_steps : int
        Number of steps; the run ends at t0 + n_steps h.
    t0 : float
        Start time [s].
    connections : mapping
        ``"component.input" -> "component.output"`` or a number; overrides the default wiring.
    events : iterable of (time, "component.name", value)
        Timed events (applied at the first grid point >= time, before that step's inputs).
    record : "all" or sequence of "component.port"
        Signals to record.
    error : callable (key path, message) -> InputError, optional
        Builds wiring errors (a scenario's ``error`` method names file and line).
    oversample : int
        Finest ticks per recording step (``hf = step / oversample``), >= 1.
    rates : mapping of str to int, optional
        Component name -> ticks per step of that component; default ``oversample`` (the recording step).
    plant_parts : sequence of str
        FMU components mapping some of the plant's roles (see :func:`default_connections`).
    """

    #: recorded rows per block (the compiled loop's row buffer reads it here: no import back into master)
    block = BLOCK

    def __init__(self, components: Sequence[tuple[str, Component]], *, step: float, n_steps: int,
                 t0: float = 0.0, connections: Mapping[str, str | float] | None = None,
                 events: Iterable[tuple[float, str, Any]] = (), record: str | Sequence[str] = "all",
                 error: ErrorFactory | None = None, oversample: int = 1,
                 rates: Mapping[str, int] | None = None, plant_parts: Sequence[str] = ()) -> None:
        self.components = dict(components)
        if len(self.components) != len(components):
            raise InputError("component names must be unique")
        self.h, self.n_steps, self.t0 = float(step), int(n_steps), float(t0)
        if int(oversample) != oversample or oversample < 1:
            raise InputError(f"oversample must be an integer >= 1, got {oversample!r}")
        self.m = int(oversample)
        self.hf = self.h / self.m
        self.rates = {n: self.m for n in self.components} | dict(rates or {})
        bad = {n: d for n, d in self.rates.items() if n not in self.components or int(d) != d or d < 1}
        if bad:
            raise InputError(f"rates: expected component names with integer tick counts >= 1, got {bad}")
        self.user_connections = dict(connections or {})
        self.plant_parts = tuple(plant_parts)
        self.events = list(events)
        self.record = record
        self._error = error or _scenario_error
        self.connections: dict[str, str | float] = {}
        self.recorder: Recorder | None = None
        self._ready = False
        self._terminated: set[str] = set()
        #: which loop stepped the plant and the sensors, and why (set by ``run``; see cosim/fastloop)
        self.loop = "not run"

    @classmethod
    def from_scenario(cls, scenario: Any) -> Master:
        """The standard components of a :class:`cosim.scenario.Scenario`, plus its user components."""
        from feeddrive.cosim.fmu_factory import fmu_component
        from feeddrive.cosim.nc import NCComponent
        from feeddrive.cosim.sensors import SensorsComponent

        m = scenario.plant.oversample
        comps: list[tuple[str, Component]] = []
        rates: dict[str, int] = {}
        if scenario.nc is not None:  # the drive; without nc: a system of components only
            cycle = scenario.nc_cycle_ticks()
            nc = NCComponent("nc", scenario.nc)
            plant = fmu_component("plant", scenario.plant, input_period=cycle)
            comps += [("nc", nc), ("plant", plant), ("sensors", SensorsComponent(
                "sensors", scenario.sensors, oversample=m, exact_means=plant.interval_means))]
            rates |= {"nc": cycle, "plant": 1, "sensors": 1}
        specs = [(("monitor", "class"), scenario.monitor)] if scenario.monitor is not None else []
        specs += [(("components", k, "class"), spec) for k, spec in enumerate(scenario.components)]
        # a PMSM's servo sensors step before the monitor, which reads them at the same step as the q-axis sensors
        # (a sample later, the d axis lagged the q axis: L_d -40 %, R -10 % on the built-in PMSM); only on a PMSM
        # axis: elsewhere a component named servo is a user component like any other
        if getattr(scenario, "servo_drive", False):
            specs.sort(key=lambda item: item[1].name != "servo")
        for where, spec in specs:
            if spec.fmu is not None:  # an FMU component: its own ports, step multiple and watchdog
                comps.append((spec.name, fmu_component(spec.name, spec.config, own_inputs=True)))
                part = bool(spec.config.map) and scenario.nc is not None  # a part of the plant: the plant's rate
                rates[spec.name] = spec.config.step_multiple or (1 if part else m)
                continue
            try:
                cls_ = load_component_class(spec.class_, where="class")
            except ScenarioError as exc:
                raise scenario.error(where, str(exc).removeprefix("class: ")) from None
            try:
                comps.append((spec.name, cls_(spec.name, spec.config)))
            except (ValueError, TypeError) as exc:  # the component refuses its config
                raise scenario.error(where[:-1] + ("config",), f"{spec.class_}: {exc}") from None
            if getattr(comps[-1][1], "fine_rate", False):  # it samples the plant's sub-steps (servo sensors' means)
                rates[spec.name] = 1
        parts = [s.name for s in scenario.components if s.fmu is not None and s.config.map]
        if parts and scenario.nc is not None:  # a plant split into FMUs: its parts step with it, before the sensors
            k = [n for n, _ in comps].index("plant") + 1
            comps = comps[:k] + [c for c in comps if c[0] in parts] + [c for c in comps[k:] if c[0] not in parts]
        connections = dict(scenario.connections)
        for spec in scenario.components:
            connections.update({f"{spec.name}.{port}": src for port, src in spec.inputs.items()})
        stop = scenario.stop_time if scenario.stop_time is not None else nc.duration() + SETTLING
        return cls(comps, step=scenario.step, n_steps=event_step(stop, 0.0, scenario.step),
                   connections=connections, events=[(e.time, e.target, e.value) for e in scenario.events],
                   record=scenario.record, error=scenario.error, oversample=m, rates=rates,
                   plant_parts=parts)

    @property
    def stop_time(self) -> float:
        return self.t0 + self.n_steps * self.h

    # -- set-up -------------------------------------------------------------------------------------
    def setup(self) -> None:
        """Set up every component, compile the connections, events and recorder. Idempotent."""
        if self._ready:
            return
        name = "?"
        try:
            ticks = self.n_steps * self.m
            for name, comp in self.components.items():
                d = self.rates[name]
                comp.setup(self.t0, d * self.hf, -(-ticks // d))
            self._compile()
            self._check_start_position()
        except BaseException as exc:
            self.terminate()
            if isinstance(exc, (InputError, SimulationError)) or not isinstance(exc, Exception):
                raise
            raise SimulationError(f"{name}: set-up failed: {type(exc).__name__}: {exc}") from exc
        self._ready = True

    def _check_start_position(self) -> None:
        """The NC's program must start where the plant is (a mismatch would be a huge position step)."""
        nc, plant = self.components.get("nc"), self.components.get("plant")
        if nc is None or plant is None or self.connections.get("nc.position") != "plant.position":
            return
        x0 = plant.get_outputs()[list(plant.output_names).index("position")]
        start = getattr(nc.config, "start", x0)
        if abs(x0 - start) > START_TOLERANCE:
            raise self._error(("nc", "start"), f"the NC program starts at {start:.6g} m but the plant at {x0:.6g} m; "
                              "set nc.start, or the plant's initial position through plant.start (e.g. the motor "
                              "angle theta [rad] of the built-in plant)")

    def _compile(self) -> None:
        ports = {n: (tuple(c.input_names), tuple(c.output_names)) for n, c in self.components.items()}
        index: dict[str, int] = {}
        names, units = [], []
        for n, c in self.components.items():
            u = tuple(c.output_units) or ("",) * len(c.output_names)
            for port, unit in zip(c.output_names, u):
                index[f"{n}.{port}"] = len(names)
                names.append(f"{n}.{port}")
                units.append(unit)
        self.n_signals = len(names)
        for dst in self.user_connections:
            comp, _, port = dst.partition(".")
            if port not in ports.get(comp, ((), ()))[0]:
                raise self._error(("connections", dst), f"no input {dst!r}; inputs are: "
                                  f"{', '.join(f'{n}.{p}' for n, (i, _) in ports.items() for p in i)}")
        self.connections = default_connections(ports, self.plant_parts) | self.user_connections
        constants: list[float] = []
        self._getters: list[Callable] = []
        self._input_index: dict[str, list[int]] = {}  # each component's inputs' indices in Y (the fast path reads them)
        for n, c in self.components.items():
            idx = self._input_index[n] = []
            for port in c.input_names:
                dst = f"{n}.{port}"
                src = self.connections.get(dst)
                if src is None:
                    raise self._error(("connections",), f"input {dst!r} is not connected; add "
                                      f"'{dst}: <component.output or number>' to connections")
                if isinstance(src, str):
                    if src not in index:
                        raise self._error(("connections", dst), f"unknown source {src!r}; outputs are: "
                                          f"{', '.join(names)}")
                    declared = tuple(getattr(c, "input_units", ()))
                    problem = mismatch(units[index[src]], declared[len(idx)] if len(declared) > len(idx) else "")
                    if problem:
                        raise self._error(("connections", dst), f"{src} -> {dst}: {problem}")
                    idx.append(index[src])
                else:
                    idx.append(self.n_signals + len(constants))
                    constants.append(float(src))
            self._getters.append(_getter(idx))
        self._constants = constants
        if self.record == "all":
            rec = list(range(self.n_signals))
        else:
            rec = []
            for k, name in enumerate(self.record):
                if name not in index:
                    raise self._error(("record", k), f"unknown signal {name!r}; expected one of: {', '.join(names)}")
                rec.append(index[name])
        self._rec_get = _getter(rec)
        self._rec_index = rec
        self.recorder = Recorder([names[j] for j in rec], [units[j] for j in rec], self.n_steps + 1, self.t0, self.h)
        order = list(self.components)
        self._events = []
        for k, (time, target, value) in enumerate(self.events):
            comp, _, name = target.partition(".")
            if comp not in self.components or not name:
                raise self._error(("events", k, "target"), f"expected '<component>.<name>' with component one "
                                  f"of {', '.join(order)}, got {target!r}")
            self._events.append((event_step(time, self.t0, self.hf), comp, name, value))
        self._events.sort(key=lambda e: e[0])  # stable: same-step events keep their declaration order

    # -- the run --------------------------------------------------------------------------------------
    def run(self, *, progress: bool = False, signals_path: str | Path | None = None) -> Recorder:
        """Run all steps; returns the recorder. Call ``reports()`` then ``terminate()`` afterwards.

        On a failure the rows recorded so far are kept (and written to ``signals_path`` when given),
        the components are terminated and the error propagates; errors that are neither input nor
        simulation errors are wrapped in a SimulationError naming the component and the time.
        """
        self.setup()
        comps = list(self.components.values())
        Y = [0.0] * self.n_signals + self._constants
        schedule, period = self._schedule()
        fine, self.loop = fastloop.plan(self)
        fast = blocks.tables(self, fine, schedule, period) if fine is not None else None
        where: list[Any] = [0, None]  # the fast path's tick and component, for the error message
        for c in comps:
            a, b = self._slices[c]
            Y[a:b] = c.get_outputs()
        rec, recorder, m = self._rec_get, self.recorder, self.m
        rows = [rec(Y)]
        events = self._events
        e = 0
        next_event = events[0][0] if events else -1
        k = -1
        c = None
        ticks = self.n_steps * m
        try:
            with tqdm(total=self.n_steps, unit="s", unit_scale=self.h, disable=None if progress else True,
                      leave=False, desc="co-simulation", bar_format="{desc}: {percentage:3.0f}%|{bar}| "
                      "{n:.2f}/{total:.2f} s [{elapsed}<{remaining}, {rate_fmt}]") as bar:
                for k0 in range(0, ticks, BLOCK * m):
                    k1 = min(k0 + BLOCK * m, ticks)
                    if fine is not None:  # the plant and the sensors in compiled blocks
                        e, next_event = blocks.run_blocks(self, fine, fast, k0, k1, Y, rows, e, next_event, where)
                        k = k1 - 1
                    else:
                        for k in range(k0, k1):
                            while k == next_event:
                                _, name, param, value = events[e]
                                c = self.components[name]
                                c.set_parameter(param, value)
                                e += 1
                                next_event = events[e][0] if e < len(events) else -1
                            for c, set_inputs, getter, step, get_outputs, a, b, d in schedule[k % period]:
                                set_inputs(getter(Y))
                                step(k // d)
                                Y[a:b] = get_outputs()
                            if m == 1 or (k + 1) % m == 0:
                                rows.append(rec(Y))
                    recorder.extend(rows)
                    rows.clear()
                    bar.update((k + 1 - k0) // m)
            recorder.extend(rows)  # the t0 row when there are no steps
        except BaseException as exc:
            if fine is not None:
                fine.sync()
                k, c = where
            recorder.extend(rows)
            if signals_path is not None:
                recorder.write_csv(signals_path)
            self.terminate()
            if isinstance(exc, (InputError, SimulationError)) or not isinstance(exc, Exception):
                raise
            name = next((k for k, v in self.components.items() if v is c), "?")
            raise SimulationError(f"{name}: {type(exc).__name__}: {exc} (in step {max(k, 0) // m} from t="
                                  f"{self.t0 + max(k, 0) * self.hf:.6g} s)") from exc
        if fine is not None:
            fine.sync()
        if signals_path is not None:
            recorder.write_csv(signals_path)
        return recorder

    def _schedule(self) -> tuple[list[list[tuple]], int]:
        """Per tick residue ``k % period``: the components that step at tick k, in stepping order.

        A component with rate divisor d steps at the ticks with ``k % d == 0`` when it precedes the first
        fine-rate (d = 1) component in the order (it feeds it: the NC's command for the coming cycle), else
        at ``k % d == d - 1`` (it reads what the faster components produced over its period).
        """
        names = list(self.components)
        rates = [self.rates[n] for n in names]
        first_fine = next((j for j, d in enumerate(rates) if d == 1), len(names))
        period = math.lcm(*rates) if rates else 1
        self._slices = {}
        entries = []
        a = 0
        for j, (c, getter, d) in enumerate(zip(self.components.values(), self._getters, rates)):
            b = a + len(c.output_names)
            self._slices[c] = (a, b)
            entries.append(((c, c.set_inputs, getter, c.step, c.get_outputs, a, b, d), d, 0 if j < first_fine else d - 1))
            a = b
        return [[x for x, d, phase in entries if r % d == phase] for r in range(period)], period

    def reports(self) -> dict[str, dict]:
        """Each component's ``report()`` (call after the run)."""
        return {n: c.report() for n, c in self.components.items()}

    def __enter__(self) -> Master:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.terminate()

    def terminate(self) -> None:
        """Terminate every component (once each; never raises)."""
        for name, c in self.components.items():
            if name in self._terminated:
                continue
            self._terminated.add(name)
            try:
                c.terminate()
            except Exception:  # noqa: BLE001 - the contract says terminate must not raise; keep going
                pass


def _getter(idx: Sequence[int]) -> Callable[[list], tuple]:
    """``Y -> tuple(Y[i] for i in idx)``, as fast as the number of indices allows."""
    if len(idx) > 1:
        return itemgetter(*idx)
    if len(idx) == 1:
        i = idx[0]
        return lambda Y: (Y[i],)
    return lambda Y: ()
