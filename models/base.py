"""Model container: variables with metadata, physical equations, and the derived ODE.

A model is written once, as

* ``Variable`` objects (states, inputs, parameters, outputs, algebraic signals), each with
  unit, description, nominal value and kind;
* ``Equation`` objects: the paper's physical laws in implicit residual form
  ``residual(signals, derivatives, parameters) = 0``, each solving for one state derivative;
* explicit derivatives for the remaining states (controllers, kinematics);
* output and algebraic expressions.

``fmu_build`` asks a ``Model`` for its explicit ODE and output functions; ``estimator`` asks it
for the implicit equations, from which it derives the linear-in-parameters regressions.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import casadi as ca

KINDS = ("state", "input", "physical", "design", "algebraic")


@dataclass(frozen=True)
class Variable:
    """One named quantity of the model.

    Attributes
    ----------
    name : str
        Name used everywhere (FMU variable name, scenario keys, estimator output).
    unit : str
        SI unit, as written in modelDescription.xml (``"Ohm"``, ``"rad/s"``, ...).
    description : str
        One line, in the paper's words.
    kind : str
        ``state``, ``input``, ``physical`` (a parameter the monitor estimates),
        ``design`` (a known parameter), or ``algebraic`` (a signal defined by an expression).
    nominal : float or None
        Default value (start value for states, inputs and parameters).
    source : str
        Where the default comes from.
    lower : float or None
        Physical lower bound; ``lower_strict`` makes it exclusive (``R > 0``).
    tunable : bool
        Parameters only: may change during a run (fault injection). Fixed parameters may
        change only before initialisation.
    optional : bool
        Physical parameters only: estimated on request (for example a torque offset).
    output : bool
        States and algebraic signals only: exposed as an FMU output.
    """

    name: str
    unit: str
    description: str
    kind: str
    nominal: float | None = None
    source: str = ""
    lower: float | None = None
    lower_strict: bool = False
    upper: float | None = None
    tunable: bool = True
    optional: bool = False
    output: bool = False
    sym: ca.SX = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"variable {self.name!r}: kind must be one of {KINDS}, got {self.kind!r}")
        if self.output and self.kind not in ("state", "algebraic"):
            raise ValueError(f"variable {self.name!r}: only states and algebraic signals can be outputs")
        if self.sym is None:
            object.__setattr__(self, "sym", ca.SX.sym(self.name))

    @property
    def is_parameter(self) -> bool:
        return self.kind in ("physical", "design")


@dataclass(frozen=True)
class Equation:
    """A physical law in implicit form, ``residual == 0``.

    Attributes
    ----------
    name : str
        ``electrical`` or ``mechanical`` for the feed drive.
    residual : casadi.SX
        Scalar expression in signals, derivative symbols and parameters.
    solves_for : str
        The state whose time derivative this equation determines in the ODE.
    output : str
        The signal the paper puts on the left-hand side of its regression (``u`` for eq. 4,
        ``i`` for eq. 5).
    normaliser : str or None
        Parameter that multiplies ``output`` in the residual and divides the regression
        (``K`` in eq. 5), or None when ``output`` has coefficient 1.
    paper_ref : str
        Equation numbers in the paper.
    """

    name: str
    residual: ca.SX
    solves_for: str
    output: str
    normaliser: str | None
    paper_ref: str


class Model:
    """A model assembled from variables and equations; see the module docstring."""

    def __init__(
        self,
        name: str,
        variables: list[Variable],
        equations: list[Equation],
        explicit_derivatives: Mapping[str, ca.SX],
        algebraic: Mapping[str, ca.SX],
        description: str,
        derivative_symbols: Mapping[str, ca.SX] | None = None,
    ) -> None:
        self.name = name
        self.description = description
        self.variables = {v.name: v for v in variables}
        if len(self.variables) != len(variables):
            raise ValueError(f"model {name}: duplicate variable names")
        self.equations = {e.name: e for e in equations}
        self._explicit = dict(explicit_derivatives)
        self.algebraic = dict(algebraic)
        given = dict(derivative_symbols or {})
        self.derivative = {s.name: given.get(s.name, ca.SX.sym("der_" + s.name)) for s in self.states}
        solved = {e.solves_for for e in equations}
        missing = {s.name for s in self.states} - solved - set(self._explicit)
        if missing:
            raise ValueError(f"model {name}: no derivative for states {sorted(missing)}")
        undefined = {v.name for v in self.of_kind("algebraic")} ^ set(self.algebraic)
        if undefined:
            raise ValueError(f"model {name}: algebraic signals without definition or variable: {sorted(undefined)}")

    # -- variables ---------------------------------------------------------------
    def of_kind(self, *kinds: str) -> list[Variable]:
        return [v for v in self.variables.values() if v.kind in kinds]

    @property
    def states(self) -> list[Variable]:
        return self.of_kind("state")

    @property
    def inputs(self) -> list[Variable]:
        return self.of_kind("input")

    @property
    def parameters(self) -> list[Variable]:
        """Physical parameters first, then design parameters (the FMU's parameter order)."""
        return self.of_kind("physical") + self.of_kind("design")

    @property
    def outputs(self) -> list[Variable]:
        """States and algebraic signals exposed as outputs, in declaration order."""
        return [v for v in self.variables.values() if v.output]

    def nominal(self, kinds: tuple[str, ...] = ("physical", "design")) -> dict[str, float]:
        return {v.name: float(v.nominal) for v in self.of_kind(*kinds)}

    def symbol(self, name: str) -> ca.SX:
        """The symbol of a variable, or of a state's time derivative as ``der(name)``."""
        if name.startswith("der(") and name.endswith(")"):
            return self.derivative[name[4:-1]]
        return self.variables[name].sym

    # -- derived expressions ---------------------------------------------------
    def _substitute_algebraic(self, expr: ca.SX) -> ca.SX:
        """Replace algebraic symbols by their defining expressions (possibly nested)."""
        names = list(self.algebraic)
        for _ in range(len(names) + 1):
            deps = [n for n in names if ca.depends_on(expr, self.variables[n].sym)]
            if not deps:
                return expr
            expr = ca.substitute(
                expr,
                ca.vertcat(*[self.variables[n].sym for n in deps]),
                ca.vertcat(*[self.algebraic[n] for n in deps]),
            )
        raise ValueError(f"model {self.name}: algebraic definitions are cyclic")

    def state_derivatives(self) -> ca.SX:
        """Explicit ODE right-hand side, in state order, in states, inputs and parameters.

        Each implicit equation is linear in its derivative symbol; it is solved exactly as
        ``der = -residual(der=0) / (d residual / d der)``.
        """
        rhs = []
        for s in self.states:
            if s.name in self._explicit:
                rhs.append(self._substitute_algebraic(self._explicit[s.name]))
                continue
            eq = next(e for e in self.equations.values() if e.solves_for == s.name)
            d = self.derivative[s.name]
            r = self._substitute_algebraic(eq.residual)
            slope = ca.jacobian(r, d)
            if ca.depends_on(slope, d):
                raise ValueError(f"equation {eq.name} is not linear in d{s.name}/dt")
            rhs.append(-ca.substitute(r, d, 0) / slope)
        return ca.vertcat(*rhs)

    def output_expressions(self) -> ca.SX:
        return ca.vertcat(*[self._substitute_algebraic(o.sym) for o in self.outputs])

    def vectors(self) -> tuple[ca.SX, ca.SX, ca.SX]:
        """Symbol vectors ``(x, u, p)``: states, inputs, parameters in model order."""
        return (
            ca.vertcat(*[v.sym for v in self.states]),
            ca.vertcat(*[v.sym for v in self.inputs]),
            ca.vertcat(*[v.sym for v in self.parameters]),
        )

    def rhs_function(self, name: str | None = None) -> ca.Function:
        """``f(x, u, p) -> dx/dt`` as a CasADi Function."""
        x, u, p = self.vectors()
        return ca.Function(name or f"{self.name}_rhs", [x, u, p], [self.state_derivatives()],
                           ["x", "u", "p"], ["xdot"])

    def output_function(self, name: str | None = None) -> ca.Function:
        """``g(x, u, p) -> y`` as a CasADi Function, outputs in model order."""
        x, u, p = self.vectors()
        return ca.Function(name or f"{self.name}_out", [x, u, p], [self.output_expressions()],
                           ["x", "u", "p"], ["y"])

    def describe(self) -> str:
        """Human-readable table of every variable, for ``cosim info`` and documentation."""
        rows = [f"{'name':8} {'kind':9} {'unit':10} {'nominal':>12}  description"]
        for v in self.variables.values():
            nom = "" if v.nominal is None else f"{v.nominal:12.6g}"
            rows.append(f"{v.name:8} {v.kind:9} {v.unit:10} {nom:>12}  {v.description}")
        return "\n".join(rows)
