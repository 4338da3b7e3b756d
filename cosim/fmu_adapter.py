"""The plant FMU as a co-simulation component (FMI 2.0 Co-Simulation, or Model Exchange + CVode).

Ports are the scenario's roles (``speed_ref``, ``load`` in; ``voltage``, ``voltage_ref``, ``current``,
``speed``, ``position`` out, in SI units) converted through the role map (``scale * x + offset``),
followed by the FMU's other Real outputs under their own names and units.

Every FMI function of the instance returns through ONE choke point, ``_check``, installed as the
ctypes ``errcheck`` of each status-returning function (so fmpy's own wrappers pass through it too):
fmi2Discard, fmi2Error and fmi2Fatal raise :class:`cosim.errors.FMIError` (``FMUDiscard`` for
fmi2Discard, which stops the run as well: the master has a fixed step and does not retry). The FMU's
log messages go to the logger ``cosim.fmu.<name>``; the last one is kept for the error message.

Per-step cost: the hot path calls the FMU's fmi2SetReal / fmi2DoStep / fmi2GetReal through ctypes
with value-reference and value arrays allocated once in ``setup``.

Input hold (``plant.input_hold``). ``zoh``: each input is held over the step. ``foh``: every continuous
input follows the linear extrapolation ``u(t) = value_n + slope (t - t_n)`` over step n, with
``slope = (value_n - value_(n-1)) / h`` (0 at the first step), so a sampled ramp is a ramp again, not a
staircase. In Co-Simulation the adapter passes the slopes with fmi2SetRealInputDerivatives (the FMU
must declare ``canInterpolateInputs``); in Model Exchange it sets u(t) itself at every right-hand-side
evaluation of CVode, for any FMU.
"""
from __future__ import annotations

import ctypes
import logging
import shutil
from collections.abc import Sequence
from typing import Any

from fmpy import calloc, extract, free
from fmpy.fmi2 import (
    FMU2Model,
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)

from feeddrive.cosim import fmi_progress, fmu_ports
from feeddrive.cosim.component import Component
from feeddrive.cosim.errors import FMIError, ScenarioError
from feeddrive.cosim.fmu_components import convert_links
from feeddrive.cosim.fmu_inspect import model_description
from feeddrive.cosim.fmu_me import MEAN_ROLES, ModelExchange
from feeddrive.cosim.scenario import INPUT_ROLES, OUTPUT_ROLES, ROLE_UNITS, PlantConfig

_SET_REAL, _DO_STEP, _GET_REAL = (fmi_progress.CODE[f] for f in ("fmi2SetReal", "fmi2DoStep", "fmi2GetReal"))
_SET_DERIVATIVES = fmi_progress.CODE["fmi2SetRealInputDerivatives"]
STATUS = ("fmi2OK", "fmi2Warning", "fmi2Discard", "fmi2Error", "fmi2Fatal", "fmi2Pending")
_LOG_LEVEL = (logging.DEBUG, logging.WARNING, logging.WARNING, logging.ERROR, logging.CRITICAL, logging.INFO)


class FMUDiscard(FMIError):
    """The FMU returned fmi2Discard: it could not complete the call (e.g. a step). The run stops."""

    def __init__(self, component: str, function: str, time: float, last_log: str = "",
                 status: str = "fmi2Discard") -> None:
        super().__init__(component, function, status, time, last_log)
        log = f" ({last_log})" if last_log else ""
        self.args = (f"{component}: {function} returned {status} at t={time:.6g} s: the FMU could not "
                     f"complete it{log}; the run stops (fixed communication step, no retry)",)


class NonFiniteOutput(FMIError):
    """fmi2GetReal returned NaN or an infinity for an output: the run stops (nothing downstream can use it)."""

    def __init__(self, component: str, output: str, variable: str, value: float, time: float) -> None:
        super().__init__(component, "fmi2GetReal", "a non-finite value", time)
        self.args = (f"{component}: fmi2GetReal returned {value} for {output} (FMU variable {variable}) at "
                     f"t={time:.6g} s; expected a finite number",)


def _marked(rec: fmi_progress.Record, code: int, function: Any) -> Any:
    """``function`` (one of fmpy's wrappers of an FMI function) recording itself in progress in ``rec``."""
    def call(*args: Any) -> Any:
        rec.function = code
        try:
            return function(*args)
        finally:
            rec.function = fmi_progress.IDLE
    return call


class FMUComponent(ModelExchange, Component):
    """An FMI 2.0 FMU as a component; ``config`` is a resolved :class:`cosim.scenario.PlantConfig`.

    Events: ``set_parameter(name, value)`` sets a Real parameter of the FMU (fmi2SetReal; in Model
    Exchange inside an event iteration).
    """

    def __init__(self, name: str, config: PlantConfig, input_period: int = 1, own_inputs: bool = False) -> None:
        super().__init__(name, config)
        #: the FMU's Real inputs that no role maps are ports under their own names (an FMU component; the
        #: plant leaves them at their start values)
        self.own_inputs = own_inputs
        #: Model Exchange: also output ``<role>_mean``, the exact mean of each measured role over the last step
        #: (a quadrature integrated by CVode with the states), for the sensors' ``mean`` sampling
        self.interval_means = config.interface == "me" and config.oversample > 1
        #: plant steps per change of the inputs (the NC's cycle): a first-order hold ramps over the whole cycle
        self.input_period = int(input_period)
        self.log = logging.getLogger(f"cosim.fmu.{name}")
        self.last_log = ""
        self._fmu: Any = None
        self._unzip: str | None = None
        self._state = "new"  # new -> instantiated -> running -> failed / fatal -> terminated
        self._k = 0
        self.input_hold = "zoh"  # the effective plant.input_hold, set in setup

    # -- the choke point ------------------------------------------------------------------------
    def _check(self, status: int, func: Any, args: tuple) -> int:
        if status > 1:
            self._raise(func.__name__, status)
        return status

    def _raise(self, function: str, status: int) -> None:
        t = self._t0 + self._k * self._h
        self._rec.function = fmi_progress.IDLE  # the call has returned: the watchdog must not time the failure's aftermath
        self._state = "fatal" if status == 4 else "failed"
        if status == 2:
            exc: FMIError = FMUDiscard(self.name, function, t, self.last_log, self.STATUS[2])
        else:
            exc = FMIError(self.name, function, self.STATUS[status] if status < len(self.STATUS) else f"status {status}", t,
                           self.last_log)
        self._failure = exc
        raise exc

    def _on_log(self, env: Any, instance: bytes, status: int, category: bytes, message: bytes) -> None:
        text = (message or b"").decode("utf-8", "replace").strip()
        self.last_log = " ".join(text.split())  # one line, for the error message
        self.log.log(_LOG_LEVEL[status] if 0 <= status < 6 else logging.ERROR, "%s", text)

    # -- set-up -----------------------------------------------------------------------------------
    def setup(self, t0: float, h: float, n_steps: int) -> None:
        cfg: PlantConfig = self.config
        self._t0, self._h, self._failure = t0, h, None
        # read once per process (fmu_inspect's cache): a campaign's run inherits it from its worker, which
        # resolved the run's scenario. The FMU is still extracted and loaded, and instantiated, by each run:
        # a run is a forked child (cosim/supervise.py) whose FMU dies with it, so it never needs a reset, and
        # runs share no folder an FMU might write into, nor a library whose globals a run changed
        md = model_description(cfg.fmu)
        cs = cfg.interface == "cs"
        self._unzip = extract(cfg.fmu)
        self._fmu = fmu = self._open(md, cs)
        # the supervisor (cosim/supervise.py) reads which FMI function is in progress from this record
        self._rec = rec = fmi_progress.record()  # this component's own: its name and watchdog
        rec.component, rec.call_timeout, rec.time = self.name.encode("utf-8")[:63], cfg.call_timeout, t0
        for fname, code in fmi_progress.CODE.items():
            if code and fname.startswith(self.PREFIX) and callable(getattr(fmu, fname, None)):
                setattr(fmu, fname, _marked(rec, code, getattr(fmu, fname)))
        for fname in dir(type(fmu)):
            if fname.startswith(self.PREFIX):
                f = getattr(fmu.dll, fname, None)
                if f is not None and f.restype is ctypes.c_int:
                    f.errcheck = self._check
        self._bind(fmu)
        self._instantiate(md, cs, t0)
        self._state = "instantiated"
        variables = {v.name: v for v in md.modelVariables}
        vr = {name: v.valueReference for name, v in variables.items()}
        values = {**cfg.start, **cfg.parameters}
        if values:
            self._set_values([vr[n] for n in values], list(values.values()))
        self._initialize(t0)
        self._vr = vr

        roles = cfg.map
        mapped = {e.var for e in roles.values()}
        in_roles = tuple(r for r in INPUT_ROLES if r in roles)
        own_in = fmu_ports.own_inputs(md, mapped, cfg.interface) if self.own_inputs else []
        self.input_names = in_roles + tuple(p for v in own_in for p in v.ports())
        self.input_units = tuple(ROLE_UNITS[r] for r in in_roles) + tuple(v.unit for v in own_in for _ in range(v.size))
        reserved = mapped | set(OUTPUT_ROLES + INPUT_ROLES)
        extras, others = fmu_ports.extra_outputs(md, reserved)
        out_roles = tuple(r for r in OUTPUT_ROLES if r in roles)
        self.output_names = out_roles + tuple(p for v in extras + others for p in v.ports())
        self._mean_roles = tuple(r for r in MEAN_ROLES if r in roles) if self.interval_means and not cs else ()
        self.output_units = tuple(ROLE_UNITS[r] for r in out_roles) + tuple(
            v.unit for v in extras + others for _ in range(v.size))
        in_vars = [roles[r].var for r in in_roles] + [v.name for v in own_in]
        out_vars = [roles[r].var for r in out_roles] + [v.name for v in extras]
        n_own, n_extra = fmu_ports.total(own_in), fmu_ports.total(extras)
        self._nu, self._ny = len(in_vars), len(out_vars)  # variables; the value arrays may hold more (arrays)
        self._uvr = (ctypes.c_uint * self._nu)(*[vr[n] for n in in_vars])
        starts = [float(variables[n].start or 0.0) for n in in_vars[:len(in_roles)]]
        for v in own_in:  # an array's start is a space-separated list
            given = str(variables[v.name].start or "").split()
            starts += [float(x) for x in given] if len(given) == v.size else [0.0] * v.size
        self._u = (ctypes.c_double * len(starts))(*starts)
        self._yvr = (ctypes.c_uint * self._ny)(*[vr[n] for n in out_vars])
        self._y = (ctypes.c_double * (len(out_roles) + n_extra))()
        self._in_lin = [(k, *roles[r].linear()) for k, r in enumerate(in_roles)]
        self._in_lin += [(k, 1.0, 0.0) for k in range(len(in_roles), len(in_roles) + n_own)]
        self._out_lin = [roles[r].linear() for r in out_roles] + [(1.0, 0.0)] * n_extra
        self.input_units, self._in_lin = convert_links(self.input_names, self.input_units, self._in_lin, cfg._links)
        if all(s == 1 and o == 0 for _, s, o in self._in_lin):
            self.set_inputs = self._set_inputs_identity
        if all(s == 1 and o == 0 for s, o in self._out_lin):
            self.get_outputs = self._get_outputs_identity
        self._c = fmu.component
        try:
            self.input_hold = cfg.hold(md)
        except ValueError as exc:
            raise ScenarioError(f"{self.name}: plant.input_hold: {exc}") from None
        if self.input_hold == "foh":  # the roles and an FMU component's own inputs (an array: several values)
            self._start_foh(variables, in_vars, [1] * len(in_roles) + [v.size for v in own_in])
        if cs:
            self._start_cs()
        else:
            self._start_me(md, t0)
            self.step = self._step_me
        self._get_real(self._c, self._yvr, self._ny, self._y)
        if others:
            read, base = fmu_ports.other_getter(fmu, self.PREFIX == "fmi3", others), self.get_outputs
            self.get_outputs = lambda: base() + read()
        if self._mean_roles:
            self._start_means(roles)
        self._state = "running"

    # -- the FMI 2.0 layer (cosim/fmi3_adapter.py overrides it for FMI 3.0) -------------------------------
    PREFIX = "fmi2"
    STATUS = STATUS

    def _open(self, md: Any, cs: bool) -> Any:
        cls = FMU2Slave if cs else FMU2Model
        kind = md.coSimulation if cs else md.modelExchange
        return cls(guid=md.guid, unzipDirectory=self._unzip, modelIdentifier=kind.modelIdentifier,
                   instanceName=self.name)

    def _bind(self, fmu: Any) -> None:
        """The ctypes functions of the hot path: ``(instance, vrs, n, values)`` set / get of Reals."""
        self._set_real, self._get_real = fmu.dll.fmi2SetReal, fmu.dll.fmi2GetReal
        self._set_values, self._get_dx = fmu.setReal, getattr(fmu, "getDerivatives", None)
        self._new_discrete_states = getattr(fmu, "newDiscreteStates", None)

    def _instantiate(self, md: Any, cs: bool, t0: float) -> None:
        self._callbacks = cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(self._on_log)
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        from fmpy.logging import addLoggerProxy

        addLoggerProxy(ctypes.byref(cb))  # formats the variadic message in C
        try:
            self._fmu.instantiate(callbacks=cb, loggingOn=True)  # some FMUs (pythonfmu) report errors only then
        except Exception:  # fmpy raises a bare Exception when fmi2Instantiate returns NULL
            raise FMIError(self.name, "fmi2Instantiate", "NULL", t0, self.last_log) from None

    def _initialize(self, t0: float) -> None:
        self._fmu.setupExperiment(startTime=t0)
        self._fmu.enterInitializationMode()
        self._fmu.exitInitializationMode()

    def _start_cs(self) -> None:
        self._do_step = self._fmu.dll.fmi2DoStep

    def _start_cs_foh(self) -> None:
        self._set_derivatives = self._fmu.dll.fmi2SetRealInputDerivatives
        self.step = self._step_foh


    # -- Co-Simulation: the hot path ------------------------------------------------------------------
    def set_inputs(self, values: Sequence[float]) -> None:
        u = self._u
        for k, scale, offset in self._in_lin:
            u[k] = scale * values[k] + offset

    def _set_inputs_identity(self, values: Sequence[float]) -> None:
        self._u[:] = values

    def step(self, n: int) -> None:
        c, h, rec = self._c, self._h, self._rec
        rec.time = t = self._t0 + n * h
        rec.function = _SET_REAL
        self._set_real(c, self._uvr, self._nu, self._u)
        rec.function = _DO_STEP
        self._do_step(c, t, h, 1)
        self._k = n + 1
        rec.function = _GET_REAL
        self._get_real(c, self._yvr, self._ny, self._y)
        rec.function = 0

    def _start_foh(self, variables: dict, in_vars: list[str], sizes: list[int]) -> None:
        starts = [sum(sizes[:k]) for k in range(len(sizes))]  # index of each variable's first value in _u
        cont = [k for k, name in enumerate(in_vars) if variables[name].variability == "continuous"]
        values = [starts[k] + i for k in cont for i in range(sizes[k])]
        self._foh = [(k, j) for j, k in enumerate(values)]  # (value index, derivative index)
        self._dvr = (ctypes.c_uint * len(cont))(*[self._uvr[k] for k in cont])
        self._du = (ctypes.c_double * len(values))()
        self._order = (ctypes.c_int * len(values))(*[1] * len(values))
        self._u_prev: list[float] | None = None  # the values of the previous step, from the first step on
        self._ramp_start = self._t0  # Model Exchange: t_n of the current ramp
        if self.config.interface == "cs":
            self._start_cs_foh()

    def _update_slopes(self, n: int) -> None:
        """``du <- (u_n - u_(n-r)) / (r h)`` for the continuous inputs (0 at the first step), at the start of
        each input period of r = ``input_period`` steps; inside it the inputs continue that ramp."""
        u, du, r = self._u, self._du, self.input_period
        j = n % r
        if j:  # the inputs are held between the NC's cycles: continue the ramp started at its cycle
            dt = j * self._h
            for k, i in self._foh:
                u[k] += du[i] * dt
            return
        prev = self._u_prev
        if prev is None:
            prev = self._u_prev = u[:]
        inv = 1.0 / (r * self._h)
        for k, i in self._foh:
            v = u[k]
            du[i] = (v - prev[k]) * inv
            prev[k] = v

    def _step_foh(self, n: int) -> None:
        c, h, rec = self._c, self._h, self._rec
        rec.time = t = self._t0 + n * h
        self._update_slopes(n)  # before the values: inside an NC cycle it continues the inputs' ramp
        rec.function = _SET_REAL
        self._set_real(c, self._uvr, self._nu, self._u)
        rec.function = _SET_DERIVATIVES
        self._set_derivatives(c, self._dvr, len(self._du), self._order, self._du)
        rec.function = _DO_STEP
        self._do_step(c, t, h, 1)
        self._k = n + 1
        rec.function = _GET_REAL
        self._get_real(c, self._yvr, self._ny, self._y)
        rec.function = 0

    def get_outputs(self) -> list[float]:
        y = [s * y + o for (s, o), y in zip(self._out_lin, self._y)]
        total = sum(y)
        if total - total != 0:  # NaN or an infinity somewhere (one subtraction: the per-step cost)
            self._non_finite(y)
        return y

    def _get_outputs_identity(self) -> list[float]:
        y = self._y[:]
        total = sum(y)
        if total - total != 0:
            self._non_finite(y)
        return y

    def _non_finite(self, y: list[float]) -> None:
        import math

        bad = next((k for k, v in enumerate(y) if not math.isfinite(v)), None)
        if bad is None:  # finite values whose sum overflowed
            return
        role_or_var = self.output_names[bad]
        entry = self.config.map.get(role_or_var)
        variable = entry.var if entry is not None else role_or_var
        self._state = "failed"
        raise NonFiniteOutput(self.name, role_or_var, variable, y[bad], self._t0 + self._k * self._h)

    # -- events, report, terminate ---------------------------------------------------------------------
    def set_parameter(self, name: str, value: Any) -> None:
        if name not in self._vr:
            raise ScenarioError(f"{self.name}: the FMU has no variable {name!r}")
        vr, val = [self._vr[name]], [float(value)]
        if self.config.interface == "me":
            self._fmu.enterEventMode()
            self._set_values(vr, val)
            self._next_event = self._event_iteration()
            self._fmu.enterContinuousTimeMode()
        else:
            self._set_values(vr, val)

    def report(self) -> dict:
        cfg = self.config
        return {"fmu": cfg.fmu, "sha256": cfg.sha256, "interface": cfg.interface, "input_hold": self.input_hold,
                "step_s": getattr(self, "_h", None), "input_period_steps": self.input_period,
                "interval_means": bool(getattr(self, "_mean_roles", ())),
                "map": {r: e.model_dump() for r, e in cfg.map.items()}, "last_log": self.last_log}

    def terminate(self) -> None:
        fmu, state = self._fmu, self._state
        self._state = "terminated"
        try:
            if state == "running":
                fmu.terminate()
            if state in ("instantiated", "running", "failed"):
                fmu.freeInstance()
            elif fmu is not None:
                fmu.freeLibrary()
        except Exception as exc:  # noqa: BLE001 - terminate must not raise (component contract)
            self.log.warning("terminating the FMU failed: %s", exc)
        finally:
            self._fmu = None
            if self._unzip:
                shutil.rmtree(self._unzip, ignore_errors=True)
                self._unzip = None
