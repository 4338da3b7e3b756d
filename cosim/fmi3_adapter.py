"""The FMI 3.0 layer of the FMU adapter: fmpy's FMU3Slave / FMU3Model behind the same component.

Everything above the layer is shared with FMI 2.0 (cosim/fmu_adapter.py, cosim/fmu_me.py): the role
map, the ports, the Model Exchange integration and event iteration, the interval means, the timed
events, the progress record read by the supervisor. This module only says how FMI 3.0 names and
calls things: fmi3SetFloat64 / fmi3GetFloat64 take the number of values besides the number of value
references (arrays), fmi3DoStep reports a request to terminate, the log callback gets the formatted
message, and Model Exchange asks the FMU itself for its numbers of states and event indicators.

Every status-returning fmi3 function passes through the same choke point (``_check`` -> ``_raise``), so
fmi3Discard, fmi3Error and fmi3Fatal raise :class:`cosim.errors.FMIError` naming the fmi3 function; the
Co-Simulation hot path (set / doStep / get) compares the status itself and calls ``_raise`` (no Python
errcheck callback per call: one more FMU costs its doStep plus 0.8 to 1.6 us, benchmarks/bench_multi_fmu.py).

Input hold in Co-Simulation. FMI 3.0 has no fmi3SetInputDerivatives: a first-order hold is possible
only through intermediate update, when the FMU declares ``providesIntermediateUpdate`` and each of its
continuous Float64 inputs ``intermediateUpdate="true"``. The adapter then registers the
intermediateUpdate callback and, whenever the FMU asks to set inputs (``intermediateVariableSetRequested``)
at an internal time t, sets ``u(t) = u_n + slope (t - t_n)``. Otherwise the inputs are held (zoh) over
each step, with the cost stated in the README (the same staircase as an FMI 2.0 FMU without
``canInterpolateInputs``).
"""
from __future__ import annotations

import ctypes
from typing import Any

from fmpy.fmi3 import FMU3Model, FMU3Slave

from feeddrive.cosim import fmi_progress
from feeddrive.cosim.errors import FMIError, SimulationError
from feeddrive.cosim.fmu_adapter import FMUComponent
from feeddrive.cosim.fmu_inspect import with_intermediate_update

_SET, _DO_STEP, _GET = (fmi_progress.CODE[f] for f in ("fmi3SetFloat64", "fmi3DoStep", "fmi3GetFloat64"))


def _view_setter(view: memoryview) -> Any:
    """``values -> None`` writing the 1 to 3 input values into ``view`` (a memoryview of the ctypes array) by
    unpacking: cheaper per step than a ctypes slice assignment."""
    if len(view) == 1:
        def set_inputs(values: Any) -> None:
            view[0] = values[0]
    elif len(view) == 2:
        def set_inputs(values: Any) -> None:
            view[0], view[1] = values
    else:
        def set_inputs(values: Any) -> None:
            view[0], view[1], view[2] = values
    return set_inputs


class FMU3Component(FMUComponent):
    """An FMI 3.0 FMU (Co-Simulation or Model Exchange) as a component; see :class:`FMUComponent`."""

    PREFIX = "fmi3"
    STATUS = ("fmi3OK", "fmi3Warning", "fmi3Discard", "fmi3Error", "fmi3Fatal")

    def _open(self, md: Any, cs: bool) -> Any:
        with_intermediate_update(md, self._unzip)  # before the hold is decided (fmpy does not read it)
        cls = FMU3Slave if cs else FMU3Model
        kind = md.coSimulation if cs else md.modelExchange
        return cls(guid=md.guid, unzipDirectory=self._unzip, modelIdentifier=kind.modelIdentifier,
                   instanceName=self.name)

    def _bind(self, fmu: Any) -> None:
        dll = fmu.dll
        set_f64, get_f64 = dll.fmi3SetFloat64, dll.fmi3GetFloat64
        self._set_f64, self._get_f64 = set_f64, get_f64
        # (instance, vrs, n, values) as in FMI 2.0; the number of values is the array's length (FMI 3.0 arrays)
        self._set_real = lambda c, vr, n, values: set_f64(c, vr, n, values, len(values))
        self._get_real = lambda c, vr, n, values: get_f64(c, vr, n, values, len(values))
        self._set_values = fmu.setFloat64
        self._get_dx = getattr(fmu, "getContinuousStateDerivatives", None)
        self._new_discrete_states = fmu.updateDiscreteStates

    def _on_log3(self, env: Any, status: int, category: bytes, message: bytes) -> None:
        self._on_log(env, b"", status, category, message)

    def _instantiate(self, md: Any, cs: bool, t0: float) -> None:
        fmu = self._fmu
        try:
            if cs:
                intermediate = self._intermediate_update if self._uses_intermediate_update(md) else None
                fmu.instantiate(loggingOn=True, logMessage=self._on_log3, intermediateUpdate=intermediate)
            else:
                fmu.instantiate(loggingOn=True, logMessage=self._on_log3)
        except FMIError:
            raise
        except Exception:  # fmpy raises a bare Exception when the instantiate function returns NULL
            function = "fmi3InstantiateCoSimulation" if cs else "fmi3InstantiateModelExchange"
            raise FMIError(self.name, function, "NULL", t0, self.last_log) from None

    def _initialize(self, t0: float) -> None:
        tolerance = self.config.tolerance if self.config.interface == "me" else None
        self._fmu.enterInitializationMode(tolerance=tolerance, startTime=t0)
        self._fmu.exitInitializationMode()  # CS without event mode: step mode; ME: event mode (cosim/fmu_me.py)

    def _uses_intermediate_update(self, md: Any) -> bool:
        hold = self.config.input_hold
        return hold != "zoh" and self.config.interface == "cs" and self.config.hold(md) == "foh"

    # -- Model Exchange: the FMU knows its sizes (arrays) --------------------------------------------
    def _number_of_states(self, md: Any) -> int:
        return self._fmu.getNumberOfContinuousStates()

    def _number_of_event_indicators(self, md: Any) -> int:
        return self._fmu.getNumberOfEventIndicators()

    # -- Co-Simulation ----------------------------------------------------------------------------
    def _start_cs(self) -> None:
        dll = self._fmu.dll
        self._hot_set, self._hot_step, self._hot_get = (self._unchecked(dll, f) for f in
                                                        ("fmi3SetFloat64", "fmi3DoStep", "fmi3GetFloat64"))
        self._event, self._terminate, self._early = ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool()
        self._last_time = ctypes.c_double()
        self._ref_event, self._ref_terminate, self._ref_early, self._ref_last = (
            ctypes.byref(x) for x in (self._event, self._terminate, self._early, self._last_time))
        # the per-step cost (benchmarks/bench_multi_fmu.py): the calls' arguments packed once, the progress
        # record written through memoryviews (cheaper than ctypes field descriptors), the outputs read as one list
        c = self._c
        self._set_args = (c, self._uvr, self._nu, self._u, len(self._u))
        self._get_args = (c, self._yvr, self._ny, self._y, len(self._y))
        self._step_tail = (True, self._ref_event, self._ref_terminate, self._ref_early, self._ref_last)
        record, fields = memoryview(self._rec).cast("B"), fmi_progress.Record
        self._rec_function = record[fields.function.offset:][:4].cast("i")  # Record.function (int32)
        self._rec_time = record[fields.time.offset:][:8].cast("d")  # Record.time (double)
        self._y_view = memoryview(self._y).cast("B").cast("d")
        if self.get_outputs == self._get_outputs_identity:  # no unit conversion of the outputs
            self.get_outputs = self._get_outputs_view
        if self.set_inputs == self._set_inputs_identity and 1 <= len(self._u) <= 3:
            self.set_inputs = _view_setter(memoryview(self._u).cast("B").cast("d"))
        self._terminate_view = memoryview(self._terminate).cast("B")

    def _get_outputs_view(self) -> list[float]:
        y = self._y_view.tolist()
        total = sum(y)
        if total - total != 0:  # NaN or an infinity somewhere
            self._non_finite(y)
        return y

    def step(self, n: int) -> None:
        # the hot path tests the status itself (an int comparison) and hands a failure to the choke point's
        # _raise: the same typed error as ``_check``, without a Python errcheck call per FMI call
        function, h = self._rec_function, self._h
        self._rec_time[0] = t = self._t0 + n * h
        function[0] = _SET
        if (status := self._hot_set(*self._set_args)) > 1:
            self._raise("fmi3SetFloat64", status)
        function[0] = _DO_STEP
        if (status := self._hot_step(self._c, t, h, *self._step_tail)) > 1:
            self._raise("fmi3DoStep", status)
        self._k = n + 1
        if self._terminate_view[0]:
            self._terminated_by_fmu(t + h)
        function[0] = _GET
        if (status := self._hot_get(*self._get_args)) > 1:
            self._raise("fmi3GetFloat64", status)
        function[0] = 0

    def _unchecked(self, dll: Any, name: str) -> Any:
        """A second ctypes pointer to ``dll.name`` without the errcheck: the hot path tests its status itself."""
        checked = getattr(dll, name)
        f = dll._FuncPtr((name, dll))
        f.argtypes, f.restype = checked.argtypes, checked.restype
        return f

    def _step_foh(self, n: int) -> None:
        self._update_slopes(n)  # before the values: inside an NC cycle it continues the inputs' ramp
        FMU3Component.step(self, n)
        if self._failure is not None:  # raised inside the callback, where ctypes would swallow it
            raise self._failure

    def _intermediate_update(self, env: Any, t: float, set_requested: bool, get_allowed: bool,
                             step_finished: bool, can_return_early: bool, early_return_requested: Any,
                             early_return_time: Any) -> None:
        """The FMU's call inside fmi3DoStep: set the ramped inputs at its internal time ``t`` when it asks."""
        early_return_requested[0] = False
        if not set_requested or self._failure is not None:
            return
        try:
            values, dt = self._dvalues, t - self._t0 - self._k * self._h
            for k, j in self._foh:
                values[j] = self._u[k] + self._du[j] * dt
            self._set_f64(self._c, self._dvr, len(self._dvr), values, len(values))
        except FMIError:  # recorded by the choke point; re-raised after fmi3DoStep returns
            pass

    def _start_cs_foh(self) -> None:
        self._dvalues = (ctypes.c_double * len(self._du))()
        self.step = self._step_foh

    def _terminated_by_fmu(self, t: float) -> None:
        self._state = "failed"
        raise SimulationError(f"{self.name}: the FMU requested termination (fmi3DoStep terminateSimulation) "
                              f"at t={t:.6g} s: {self.last_log or 'no message'}")
