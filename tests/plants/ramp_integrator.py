"""RampIntegrator: two integrators (x' = v, phi' = w) as an FMI 3.0 FMU (Co-Simulation and Model Exchange)
whose Co-Simulation asks the master for its inputs inside fmi3DoStep (intermediate update), compiled with
the system C compiler against the framework of the Modelica Reference-FMUs (read in place, never copied).

In Co-Simulation each 1 ms step runs four fixed substeps of 0.25 ms; at the end time of each one the FMU
calls the intermediateUpdate callback with intermediateVariableSetRequested, then advances with the mean of
the inputs at both ends of the substep (trapezoidal rule: exact for a ramp). Outputs: x [m], phi [rad], the
inputs' last values v_last [m/s], w_last [rad/s], and ``requests``, the number of set requests so far.
``build(..., intermediate=False)`` declares no intermediate update (the master registers no callback, the
inputs are held over each step). Also here: :class:`Ramp`, a component whose output is a ramp in time.
"""
from __future__ import annotations

from pathlib import Path

from ref_axis import pack

from feeddrive.cosim.component import Component

HERE = Path(__file__).parent / "ramp_integrator"
TOKEN = "{8e0f3a6c-2b7d-4c91-b5e4-7a1d9c3f0e52}"
#: name, value reference, causality, variability, unit, start
VARIABLES = [("v", 1, "input", "continuous", "m/s", "0"), ("w", 2, "input", "continuous", "rad/s", "0"),
             ("x", 3, "output", "continuous", "m", "0"), ("der(x)", 4, "local", "continuous", "m/s", None),
             ("phi", 5, "output", "continuous", "rad", "0"), ("der(phi)", 6, "local", "continuous", "rad/s", None),
             ("v_last", 7, "output", "continuous", "m/s", None), ("w_last", 8, "output", "continuous", "rad/s", None),
             ("requests", 9, "output", "discrete", "1", None)]
#: the FMU's substep [s] (FIXED_SOLVER_STEP in ramp_integrator/config.h)
SUBSTEP = 2.5e-4


def model_description(intermediate: bool = True) -> str:
    units = "".join(f'<Unit name="{u}"/>' for u in sorted({v[4] for v in VARIABLES}))
    rows = ['<Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>']
    for name, vr, caus, var, unit, start in VARIABLES:
        extra = f' derivative="{vr - 1}"' if name.startswith("der(") else ""
        extra += ' intermediateUpdate="true"' if intermediate and caus == "input" else ""
        initial = ' initial="exact"' if caus == "output" and start is not None else (
            ' initial="calculated"' if caus != "input" else "")
        s = f' start="{start}"' if start is not None else ""
        rows.append(f'<Float64 name="{name}" valueReference="{vr}" causality="{caus}" variability="{var}"'
                    f'{initial} unit="{unit}"{s}{extra}/>')
    outputs = "".join(f'<Output valueReference="{v[1]}"/>' for v in VARIABLES if v[2] == "output")
    unknowns = "".join(f'<InitialUnknown valueReference="{v[1]}"/>' for v in VARIABLES
                       if v[2] != "input" and v[5] is None)
    provides = ' providesIntermediateUpdate="true"' if intermediate else ""
    return ('<?xml version="1.0" encoding="UTF-8"?>\n<fmiModelDescription fmiVersion="3.0" '
            f'modelName="RampIntegrator" instantiationToken="{TOKEN}">\n'
            '<ModelExchange modelIdentifier="RampIntegrator"/>\n'
            '<CoSimulation modelIdentifier="RampIntegrator" canHandleVariableCommunicationStepSize="true" '
            f'fixedInternalStepSize="{SUBSTEP}"{provides}/>\n'
            f'<UnitDefinitions>{units}</UnitDefinitions>\n<ModelVariables>\n' + "\n".join(rows) +
            f'\n</ModelVariables>\n<ModelStructure>{outputs}<ContinuousStateDerivative valueReference="4"/>'
            f'<ContinuousStateDerivative valueReference="6"/>{unknowns}</ModelStructure>\n</fmiModelDescription>\n')


def build(out: Path, intermediate: bool = True) -> Path:
    """Compile and pack RampIntegrator (FMI 3.0) at ``out``; skips without the framework."""
    return pack(out, 3, HERE, "RampIntegrator", model_description(intermediate))


class Ramp(Component):
    """``r(t) = start + slope t`` [unit of the connected input], output ``r`` at the component's time.

    ``config``: ``{start, slope}`` (numbers). Placed after its consumer in the stepping order, the consumer
    reads r(t_n) at step n (Gauss-Seidel: the outputs at t_n of a later component)."""

    output_names = ("r",)

    def setup(self, t0: float, h: float, n_steps: int) -> None:
        self._t0, self._h = t0, h
        self._a, self._b = float(self.config.get("start", 0.0)), float(self.config["slope"])
        self.output_units = (str(self.config.get("unit", "")),)
        self._t = t0

    def step(self, n: int) -> None:
        self._t = self._t0 + (n + 1) * self._h

    def get_outputs(self) -> list[float]:
        return [self._a + self._b * self._t]
