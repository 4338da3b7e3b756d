"""Model Exchange for the FMU adapter (cosim/fmu_adapter.py): CVode over each communication step, the
event iteration, the first-order hold of the inputs inside CVode and the exact interval means.

A mixin of :class:`cosim.fmu_adapter.FMUComponent`; the FMI version layer provides ``_get_dx``,
``_new_discrete_states``, ``_set_real`` / ``_get_real`` and the numbers of states and event indicators.
"""
from __future__ import annotations

import ctypes
from typing import Any

from feeddrive.cosim.errors import FMIError, SimulationError
from feeddrive.cosim.scenario import ROLE_UNITS

#: the roles whose exact interval means a Model Exchange plant outputs (as ``<role>_mean``)
MEAN_ROLES = ("voltage", "voltage_ref", "current", "speed")


class _HeldInputs:
    """fmpy's root function re-applies inputs; ours are set once per communication step."""

    def apply(self, *args: Any, **kwargs: Any) -> None:
        pass


class _RampedInputs:
    """First-order hold in Model Exchange: ``apply(t)`` runs before each right-hand side and root function."""

    def __init__(self, plant: Any) -> None:
        n = len(plant._foh)
        self._plant, self._vr, self._values = plant, plant._dvr, (ctypes.c_double * n)()

    def apply(self, t: float, *args: Any, **kwargs: Any) -> None:
        p, values = self._plant, self._values
        dt = t - p._ramp_start
        for k, j in p._foh:
            values[j] = p._u[k] + p._du[j] * dt
        p._set_real(p._c, self._vr, len(self._vr), values)  # an FMI 3.0 array: one vr, several values




class ModelExchange:
    """The Model Exchange half of the FMU adapter (see the module docstring)."""

    # -- Model Exchange: exact interval means ------------------------------------------------------------
    def _start_means(self, roles: Any) -> None:
        """``<role>_mean`` outputs: CVode integrates q' = y with the states, q reset at each step."""
        lin = [roles[r].linear() for r in self._mean_roles]
        self.output_names += tuple(f"{r}_mean" for r in self._mean_roles)
        self.output_units += tuple(ROLE_UNITS[r] for r in self._mean_roles)
        self._mean_lin = lin
        self._means = [s * y + o for (s, o), y in zip(lin, self._y)]  # at t0: the instantaneous values
        base = self.get_outputs
        self.get_outputs = lambda: base() + self._means

    # -- Model Exchange: CVode over each communication step --------------------------------------------
    def _start_me(self, md: Any, t0: float) -> None:
        from fmpy.sundials import CVodeSolver

        class _CVode(CVodeSolver):
            def f(self, t, y, ydot, user_data):  # noqa: ANN001 - ctypes callback
                try:
                    self.input.apply(t)  # fmpy applies inputs in the root function only
                    return super().f(t, y, ydot, user_data)
                except FMIError:  # recorded by the choke point; -1 makes CVode stop
                    return -1

        fmu = self._fmu
        self._next_event = self._event_iteration()
        fmu.enterContinuousTimeMode()
        self._completed_needed = md.modelExchange.needsCompletedIntegratorStep
        nx = self._number_of_states(md)
        get_x, set_x, get_dx, nominals = (fmu.getContinuousStates, fmu.setContinuousStates, self._get_dx,
                                          fmu.getNominalsOfContinuousStates)
        if self.interval_means:  # quadrature states q' = y of the measured roles, after the FMU's states
            names = [self.config.map[r].var for r in MEAN_ROLES if r in self.config.map]
            nq = len(names)
            qvr = (ctypes.c_uint * nq)(*[self._vr[n] for n in names])
            ybuf = (ctypes.c_double * nq)()
            self._q = [0.0] * nq

            def get_x(px, n, _get=fmu.getContinuousStates):  # noqa: ANN001 - ctypes callback arguments
                _get(px, nx)
                for j, q in enumerate(self._q):
                    px[nx + j] = q

            def set_x(px, n, _set=fmu.setContinuousStates):  # noqa: ANN001
                _set(px, nx)

            def get_dx(pdx, n, _get=self._get_dx):  # noqa: ANN001
                _get(pdx, nx)
                self._get_real(self._c, qvr, nq, ybuf)
                for j in range(nq):
                    pdx[nx + j] = ybuf[j]

            def nominals(p, n, _get=fmu.getNominalsOfContinuousStates):  # noqa: ANN001
                _get(p, nx)
                for j in range(nq):
                    p[nx + j] = 1.0

            nx_total = nx + nq
        else:
            nx_total = nx
        self._nx = nx
        self._solver = _CVode(nx=nx_total, nz=self._number_of_event_indicators(md),
                              get_x=get_x, set_x=set_x,
                              get_dx=get_dx, get_z=fmu.getEventIndicators,
                              get_nominals=nominals, set_time=fmu.setTime,
                              input=_RampedInputs(self) if self.input_hold == "foh" else _HeldInputs(),
                              startTime=t0, maxStep=self._h,
                              relativeTolerance=self.config.tolerance)

    def _number_of_states(self, md: Any) -> int:
        return md.numberOfContinuousStates

    def _number_of_event_indicators(self, md: Any) -> int:
        return md.numberOfEventIndicators

    def _event_iteration(self) -> float | None:
        """fmi2NewDiscreteStates (fmi3UpdateDiscreteStates) until converged; returns the next time event or None."""
        while True:
            info = self._new_discrete_states()
            if info[1]:
                raise SimulationError(f"{self.name}: the FMU requested termination at "
                                      f"t={self._t0 + self._k * self._h:.6g} s")
            if not info[0]:
                return info[5] if info[4] else None

    def _step_me(self, n: int) -> None:
        fmu, solver = self._fmu, self._solver
        t, t1 = self._t0 + n * self._h, self._t0 + (n + 1) * self._h
        self._rec.time = t
        if self.input_hold == "foh" and n % self.input_period == 0:
            self._update_slopes(n)
            self._ramp_start = t
        self._set_real(self._c, self._uvr, self._nu, self._u)
        means = self._mean_roles
        if means:
            self._q = [0.0] * len(self._q)
        solver.reset(t)  # the inputs' value or slope changes at each step: restart at the discontinuity
        while t < t1 - 1e-9 * self._h:
            t_stop = t1 if self._next_event is None else min(t1, self._next_event)
            try:
                state_event, _, t = solver.step(t, t_stop)
            except RuntimeError as exc:
                if self._failure is not None:
                    raise self._failure from None
                raise SimulationError(f"{self.name}: {exc}") from None
            fmu.setTime(t)
            if means:  # the integrals so far (an event restarts CVode from them)
                px, nx = solver.px, self._nx
                self._q = [px[nx + j] for j in range(len(self._q))]
            step_event = self._completed_needed and fmu.completedIntegratorStep()[0]
            time_event = self._next_event is not None and t >= self._next_event - 1e-9 * self._h
            if state_event or step_event or time_event:
                fmu.enterEventMode()
                self._next_event = self._event_iteration()
                fmu.enterContinuousTimeMode()
                solver.reset(t)
        self._k = n + 1
        self._get_real(self._c, self._yvr, self._ny, self._y)
        if means:
            inv_h = 1.0 / self._h
            self._means = [sc * q * inv_h + o for (sc, o), q in zip(self._mean_lin, self._q)]

