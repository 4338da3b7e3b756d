"""Output-error refinement: fit the simulated current and speed to the measured ones.

Both model equations are integrated together over the motion with the measured (filtered)
voltage as the only input, from the IV estimate, by Levenberg-Marquardt (Gauss-Newton with
damping) with CasADi forward sensitivities. The filtered signals are decimated to
``options.oe_rate_hz`` first. The initial current and speed are estimated with the parameters.
Each output is weighted by the inverse RMS of its residual at the IV estimate.

Covariance: sandwich ``A^-1 S A^-1`` with ``A = J^T J`` and ``S`` the batch-means long-run
variance of ``J_t^T r_t`` (blocks of at least 0.2 s: output errors are correlated over the
mechanical time constant). If the fit does not converge, the IV result is returned with the reason.
"""
from __future__ import annotations

import math
from dataclasses import replace
from functools import lru_cache

import casadi as ca
import numpy as np

from feeddrive.estimator.errors import FAILURES, NotEnoughExcitation
from feeddrive.estimator.motion import (
    EstimationOptions,
    MethodResult,
    Prepared,
    check_result,
    parameter_covariance,
)
from feeddrive.estimator.simulation import _ode, _rollout
from feeddrive.models.drives import differentiated, measured

MAX_ITERATIONS = 30
OE_W_EPS = 0.01


def _signals(model) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(outputs, inputs) of the simulation: the equations' states (DC ``i, w``), the other measured signals (``u``)."""
    states = differentiated(model)
    return states, tuple(sorted(x for x in measured(model) if x not in states))


@lru_cache(maxsize=8)
def _sensitivities(n: int, free: tuple[str, ...], model) -> tuple[ca.Function, ca.Function]:
    """``f(q, U (2 m, n-1), fixed, h) -> X (k, n-1)`` and ``(X, dX/dq)``; q = free parameters, then the initial
    states in ``_signals(model)[0]`` order (DC: ``i0, w0``); m inputs, k states."""
    outputs, inputs = _signals(model)
    equations = tuple(model.equations)
    roll = _rollout(model, equations, inputs, n, 2)
    _, states, phys, _ = _ode(model, equations, inputs)
    q = ca.MX.sym("q", len(free) + len(outputs))
    fixed = ca.MX.sym("fixed", len(phys) + 1)  # every physical parameter and w_eps; free ones overwritten
    p = ca.vertcat(*[q[free.index(v.name)] if v.name in free else fixed[j] for j, v in enumerate(phys)],
                   fixed[len(phys)])
    U, h = ca.MX.sym("U", 2 * len(inputs), n - 1), ca.MX.sym("h")
    x0 = ca.vertcat(*[q[len(free) + outputs.index(s)] for s in states])
    X = roll(x0, U, p, h)
    if states != outputs:
        X = X[[states.index(s) for s in outputs], :]
    return (ca.Function("oe_sim", [q, U, fixed, h], [X]),
            ca.Function("oe_jac", [q, U, fixed, h], [X, ca.jacobian(ca.vec(X), q)]))


def _fallback(start: MethodResult, reason: str) -> MethodResult:
    return replace(start, method="oe", message=f"output error fell back to {start.method_used.upper()}: {reason}",
                   ran=start.method_used)


def output_error(p: Prepared, start: MethodResult, options: EstimationOptions) -> MethodResult:
    """Refine ``start`` (the IV result) by output error; see the module docstring.

    Returns
    -------
    MethodResult
        Method ``oe``; or ``start`` relabelled ``oe`` with ``message`` saying why it fell back (a
        non-finite simulation or a singular system included: never an exception).
    """
    try:
        with np.errstate(all="ignore"):  # non-finite values are tested for and become a fallback
            return _output_error(p, start, options)
    except FAILURES as exc:  # the estimator's own failures only: a coding error (a shape mismatch) is raised
        return _fallback(start, f"a singular system ({exc})" if isinstance(exc, np.linalg.LinAlgError) else str(exc))


def _output_error(p: Prepared, start: MethodResult, options: EstimationOptions) -> MethodResult:
    def fallback(reason: str) -> MethodResult:
        return _fallback(start, reason)

    s, model = p.signals, options.model
    outputs, inputs = _signals(model)
    owned = {n for r in p.regressions if r.normaliser is None for n in r.names}
    if (any(x not in s for x in outputs + inputs) or any(p.overrides.values())
            or any(r.normaliser and r.normaliser not in owned for r in p.regressions)):
        return fallback(f"needs {', '.join(measured(model))} (voltage, current and speed), with no torque signal")
    # every k-th sample, at most oe_rate_hz: on a decimated record (h = 0.7 ms at 10 kHz, D = 7) rounding gave
    # 1429 Hz, 43 % more steps to integrate with sensitivities than the option says
    k = max(1, math.ceil(1.0 / (options.oe_rate_hz * p.h) - 1e-9))
    u, y = np.vstack([s[x][::k] for x in inputs]), np.vstack([s[x][::k] for x in outputs])
    n, h = u.shape[1], k * p.h
    free = start.names
    sim, sens = _sensitivities(n, free, model)
    values = {**{v.name: v.nominal for v in options.physical}, **p.known, **start.as_dict()}
    fixed = [float(values[v.name]) for v in options.physical] + [OE_W_EPS]
    U = np.vstack([u[:, :-1], u[:, 1:]])
    q = np.concatenate([start.values, y[:, 0]])
    scale = np.concatenate([np.abs(start.values).clip(1e-9), np.sqrt(np.mean(y ** 2, axis=1)).clip(1e-9)])

    def jacobian(q):
        X, J = sens(q, U, fixed, h)
        return np.asarray(X), np.asarray(ca.densify(J)).reshape(len(outputs), n - 1, -1, order="F")

    X, J = jacobian(q)
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(J))):
        return fallback(f"the simulation from the {start.method_used.upper()} estimate is unstable or non-finite "
                        f"at the {h:.3g} s step")
    weight = 1.0 / np.sqrt(np.mean((y[:, 1:] - X) ** 2, axis=1)).clip(1e-12)[:, None]

    def residual(X):
        return (y[:, 1:] - X) * weight

    r = residual(X)
    cost, lam, converged = np.sum(r ** 2), 1e-3, False
    for it in range(1, MAX_ITERATIONS + 1):
        Jw = (J * weight[:, :, None]).reshape(-1, len(q)) * scale
        A, g = Jw.T @ Jw, Jw.T @ r.ravel()
        while True:
            step = np.linalg.solve(A + lam * np.diag(np.diag(A)), g) * scale
            Xn = np.asarray(sim(q + step, U, fixed, h))  # trial steps: no sensitivities
            rn = residual(Xn)
            cost_n = np.sum(rn ** 2)
            if np.isfinite(cost_n) and cost_n <= cost:
                break
            lam *= 10
            if lam > 1e8:
                return fallback(f"no descent step after {it} iterations")
        q, r = q + step, rn
        X, J = jacobian(q)
        # the cost is about the number of residuals: a relative decrease of 1e-6 is far below noise
        small = np.max(np.abs(step) / scale) < 1e-7 or cost - cost_n < 1e-6 * cost
        cost, lam = cost_n, max(lam / 10, 1e-9)
        if small:
            converged = True
            break
    if not converged:
        return fallback(f"not converged in {MAX_ITERATIONS} iterations")
    Jw = (J * weight[:, :, None])  # (2, n-1, nq)
    A = Jw.reshape(-1, len(q)).T @ Jw.reshape(-1, len(q))
    G = np.einsum("ctq,ct->tq", Jw, r)
    block = max(1, int(round(max(0.2, options.block()) / h)))
    cov, dof, nb = parameter_covariance(G, np.linalg.inv(A), block)
    cov = cov[:len(free), :len(free)]
    sv = np.linalg.svd(Jw.reshape(-1, len(q)) * scale, compute_uv=False)
    if not (np.all(np.isfinite(cov)) and sv[-1] > 0):
        return fallback("singular or non-finite output-error covariance")
    fit = float(np.max(np.sqrt(np.sum((y[:, 1:] - X) ** 2, axis=1) / np.sum(y[:, 1:] ** 2, axis=1))))
    result = MethodResult("oe", free, q[:len(free)].copy(), cov, nb - len(q), float(sv[0] / sv[-1]), fit, it,
                          parameter_dof=dof[:len(free)])
    try:
        check_result(result, options)
    except NotEnoughExcitation as exc:
        return fallback(str(exc))
    return result
