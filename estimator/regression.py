"""Linear-in-parameters regressions (paper eq. 4, 5) derived from the CasADi model.

Each implicit equation ``residual(signals, derivatives, parameters) = 0`` of ``models`` is linear in
its physical parameters: ``residual = sum_j p_j phi_j(signals) + r0(signals)``. The regressors
``phi_j`` are the jacobian of the residual with respect to the parameters, so an added model term
(the optional offset ``T0``, say) changes the estimator without touching this module.

* no normaliser (eq. 4): ``y = -r0`` (``u`` for the electrical equation), ``theta_j = p_j``;
* normaliser ``n`` free (eq. 5, ``n = K``): the term ``n * output`` gives ``y = output``,
  ``theta_j = p_j / n``;
* known parameters are moved to the output side (``y = K i`` with K known, or a torque signal).
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache

import casadi as ca
import numpy as np

from feeddrive.estimator.errors import EstimatorInputError

_UNARY = {ca.OP_NEG: np.negative, ca.OP_SQ: np.square, ca.OP_SQRT: np.sqrt, ca.OP_EXP: np.exp, ca.OP_LOG: np.log,
          ca.OP_TANH: np.tanh, ca.OP_SIN: np.sin, ca.OP_COS: np.cos, ca.OP_FABS: np.abs, ca.OP_SIGN: np.sign,
          ca.OP_ASSIGN: lambda a: a, ca.OP_TWICE: lambda a: 2 * a, ca.OP_INV: np.reciprocal}
_BINARY = {ca.OP_ADD: np.add, ca.OP_SUB: np.subtract, ca.OP_MUL: np.multiply, ca.OP_DIV: np.divide,
           ca.OP_POW: np.power, ca.OP_CONSTPOW: np.power, ca.OP_FMIN: np.fmin, ca.OP_FMAX: np.fmax}


def numpy_function(f: ca.Function):
    """Vectorised numpy version of a scalar-input SX Function ``f(x (m,)) -> (k,)``.

    Runs CasADi's instruction list on arrays: one numpy operation per instruction, so a regression
    over 40 000 samples costs microseconds per operation instead of a CasADi map call.
    Returns None if the function uses an operation not listed here.
    """
    ops = [(f.instruction_id(k), f.instruction_input(k), f.instruction_output(k), f.instruction_constant(k))
           for k in range(f.n_instructions())]
    if any(op not in _UNARY and op not in _BINARY and op not in (ca.OP_INPUT, ca.OP_OUTPUT, ca.OP_CONST)
           for op, *_ in ops):
        return None

    def run(x: np.ndarray | Sequence[np.ndarray], first: int = 0) -> np.ndarray:
        """``x``: the inputs' rows, (m, n) or a sequence of m arrays (n,) (read by index, never stacked). The
        output's rows from ``first`` on (those before are not written)."""
        work: dict[int, np.ndarray | float] = {}
        out = np.empty((f.nnz_out(0) - first, len(x[0])))
        for op, i, o, c in ops:
            if op == ca.OP_INPUT:
                work[o[0]] = x[i[1]]
            elif op == ca.OP_OUTPUT:
                if o[1] >= first:
                    out[o[1] - first] = work[i[0]]
            elif op == ca.OP_CONST:
                work[o[0]] = c
            elif op in _UNARY:
                work[o[0]] = _UNARY[op](work[i[0]])
            else:
                work[o[0]] = _BINARY[op](work[i[0]], work[i[1]])
        return out

    # the input whose value is the output's first row itself (y = u, y = i), else None: evaluate reads it there
    source: dict[int, int | None] = {}
    for op, i, o, _ in ops:
        if op == ca.OP_INPUT:
            source[o[0]] = i[1]
        elif op == ca.OP_OUTPUT:
            if o[1] == 0:
                run.direct = source.get(i[0])
        else:
            source[o[0]] = None
    return run


def _is_zero(expr: ca.SX) -> bool:
    """True if ``expr`` is identically zero (checked at random points: CasADi does not cancel ``-i + i``)."""
    syms = ca.symvar(expr)
    f = ca.Function("z", syms, [expr])
    rng = np.random.default_rng(0)
    return all(abs(float(f.call(list(rng.normal(size=len(syms))))[0])) < 1e-12 for _ in range(3))


def signal_names(model) -> dict[str, str]:
    """Map CasADi symbol names to the estimator's signal names (``der_i`` -> ``Di``)."""
    names = {v.sym.name(): v.name for v in model.variables.values()}
    names.update({sym.name(): "D" + state for state, sym in model.derivative.items()})
    return names


@dataclass(frozen=True)
class Regression:
    """``y = Phi theta`` for one model equation.

    Attributes
    ----------
    equation : str
        Model equation name (``electrical``, ``mechanical``).
    names : tuple of str
        Physical parameters, one per column of Phi.
    normaliser : str or None
        Free parameter that divides the others (``theta_j = p_j / normaliser``), or None.
    signals : tuple of str
        Signals the regression needs (``u``, ``i``, ``w``, ``Di``, ``Dw``, ``sgn_w``, ...).
    function : casadi.Function
        ``signals (len(signals),) -> [y, phi_1, ..., phi_p]``.
    vectorised : callable or None
        ``numpy_function(function)``: the same on arrays (len(signals), n) -> (1 + p, n).
    constants : tuple of str
        Parameters among ``signals``: estimated by another equation (``borrowed``) and given as constant
        arrays at evaluation (the PMSM's reluctance torque ``1.5 p (L_d - L_q) i_d i_q / psi_f`` on the
        output side of the mechanical regression).
    """

    equation: str
    names: tuple[str, ...]
    normaliser: str | None
    signals: tuple[str, ...]
    function: ca.Function
    vectorised: Callable[[np.ndarray], np.ndarray] | None = field(default=None, compare=False, repr=False)
    constants: tuple[str, ...] = ()

    def evaluate(self, values: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Evaluate output and regressors on sampled signals.

        Parameters
        ----------
        values : mapping of str to ndarray, each shape (n,)
            Every name in ``signals``.

        Returns
        -------
        y : ndarray, shape (n,)
        Phi : ndarray, shape (n, p)
        """
        return self._evaluate(values, 0)

    def regressors(self, values: Mapping[str, np.ndarray]) -> np.ndarray:
        """``evaluate(values)[1]`` without forming ``y`` (the instruments' regressors): Phi (n, p), the same
        values and layout."""
        return self._evaluate(values, 1)

    def _evaluate(self, values: Mapping[str, np.ndarray], first: int):
        missing = [s for s in self.signals if values.get(s) is None]
        if missing:
            raise EstimatorInputError(f"{self.equation} regression needs signals {missing}")
        rows = [np.asarray(values[s], dtype=float) for s in self.signals]
        direct = getattr(self.vectorised, "direct", None) if not first else None
        if direct is not None and rows[direct].ndim == 1 and rows[direct].flags.c_contiguous:
            # y is an input itself: a read-only view of it, not a copy (its values; contiguous as the copy was)
            y = rows[direct].view()
            y.setflags(write=False)
            return y, self.vectorised(rows, 1).T
        if self.vectorised is not None:  # the signals' rows as they are: a stacked copy of them was read only
            out = self.vectorised(rows, first)
        else:  # an operation numpy_function does not know: CasADi's own (slower) map
            stack = np.vstack(rows)
            out = np.asarray(self.function.map(stack.shape[1])(stack))[first:]
        return out.T if first else (out[0], out[1:].T)


def derive_regression(model, equation: str, free: list[str], known: Mapping[str, float],
                      borrowed: tuple[str, ...] = (), measured: tuple[str, ...] = ()) -> Regression:
    return _derive(model, equation, tuple(free), tuple(sorted(known.items())), tuple(borrowed), tuple(measured))


def equation_residual(model, equation: str, measured: tuple[str, ...] = ()) -> ca.SX:
    """The residual of one equation as the estimator sees it: no load (inputs zero), and the algebraic
    signals defined from physical parameters (the PMSM's air-gap torque) replaced by their definition,
    unless they are ``measured`` (a torque signal: then the residual holds it as a signal)."""
    from feeddrive.models.drives import parameter_defined

    residual = model.equations[equation].residual
    inputs = [v.sym for v in model.inputs]
    residual = ca.substitute(residual, ca.vertcat(*inputs), ca.DM.zeros(len(inputs)))
    subs = [n for n in parameter_defined(model)
            if n not in measured and ca.depends_on(residual, model.variables[n].sym)]
    if subs:
        residual = ca.substitute(residual, ca.vertcat(*[model.variables[n].sym for n in subs]),
                                 ca.vertcat(*[model._substitute_algebraic(model.algebraic[n]) for n in subs]))
    return residual


def equation_parameters(model, equation: str) -> tuple[str, ...]:
    """Physical parameters the equation's residual (:func:`equation_residual`) depends on, in model order."""
    r = equation_residual(model, equation)
    return tuple(v.name for v in model.of_kind("physical") if ca.depends_on(r, v.sym))


@lru_cache(maxsize=64)
def _derive(model, equation: str, free: tuple[str, ...], known_items: tuple, borrowed: tuple[str, ...] = (),
            measured: tuple[str, ...] = ()) -> Regression:
    """Derive the regression of one model equation.

    Parameters
    ----------
    model : models.Model
        The feed-drive model.
    equation : str
        Key of ``model.equations``.
    free : list of str
        Physical parameters to estimate; those of the equation that are neither free nor known
        take their nominal value (optional terms such as ``T0`` are 0 unless requested).
    known : mapping of str to float
        Parameters fixed to a known value.
    borrowed : tuple of str
        Parameters estimated by another equation: kept as symbols, evaluated as constant signals.
    measured : tuple of str
        Parameter-defined algebraic signals that are measured (``torque``): kept as signals.

    Returns
    -------
    Regression
    """
    known = dict(known_items)
    eq = model.equations[equation]
    # no machining during a high-speed motion: inputs (load torque) are zero
    residual = equation_residual(model, equation, measured)
    params = [v for v in model.parameters if ca.depends_on(residual, v.sym)]
    names = [v.name for v in params if v.name in free and v.name not in known and v.name not in borrowed]
    fixed = [v for v in params if v.name not in names and v.name not in borrowed]
    residual = ca.substitute(residual, ca.vertcat(*[v.sym for v in fixed]),
                             ca.DM([float(known.get(v.name, v.nominal)) for v in fixed])) if fixed else residual
    p = ca.vertcat(*[model.variables[n].sym for n in names])
    jac = ca.jacobian(residual, p)
    if ca.depends_on(jac, p):
        raise EstimatorInputError(f"model equation {equation!r} is not linear in the parameters {names}")
    r0 = ca.substitute(residual, p, ca.DM.zeros(len(names)))
    phis = [jac[j] for j in range(len(names))]
    normaliser = eq.normaliser if eq.normaliser in names else None
    if normaliser is not None:
        out = model.variables[eq.output].sym
        k = names.index(normaliser)
        coef = ca.jacobian(phis[k], out)
        if not coef.is_constant() or not _is_zero(phis[k] - coef * out):
            raise EstimatorInputError(f"equation {equation!r}: the {normaliser} term is not {normaliser}*{eq.output}")
        held = [model.variables[b].sym for b in borrowed]
        if not _is_zero(r0) and not any(ca.depends_on(r0, b) for b in held):
            raise EstimatorInputError(
                f"equation {equation!r}: fixing other parameters needs a known {normaliser} (or a torque signal)")
        # terms in parameters of other equations go to the output side, scaled by the normaliser's value
        # (given, like them, as a constant): out + r0 / (coef n) = sum_j (p_j / n) (-phi_j / coef)
        y = out if _is_zero(r0) else out + r0 / (coef * model.variables[normaliser].sym)
        phis = [-phi / coef for j, phi in enumerate(phis) if j != k]
        names = [n for n in names if n != normaliser]
    else:
        y = -r0
    expr = ca.vertcat(y, *phis)
    syms = ca.symvar(expr)
    lookup = signal_names(model)
    sig = tuple(lookup[s.name()] for s in syms)
    fun = ca.Function(f"{equation}_regression", [ca.vertcat(*syms)], [expr])
    constants = tuple(x for x in sig if x in model.variables and model.variables[x].is_parameter)
    return Regression(equation, tuple(names), normaliser, sig, fun, numpy_function(fun), constants)
