"""What the estimator needs from a model beyond its regressions: which equation estimates each parameter,
the other equations' estimates as constants (with their errors), the equations fitted jointly with another
(a partner whose parameters are all its host's: the PMSM's d axis), derived quantities (K_t, K_e), and why a
motion is too short. Model-generic: nothing here names a motor (see ``models.drives``).
"""
from __future__ import annotations

from collections.abc import Mapping

import casadi as ca
import numpy as np

from feeddrive.estimator.derivative import FUTURE, PAST
from feeddrive.estimator.distributions import t_ppf
from feeddrive.estimator.errors import NotEnoughExcitation
from feeddrive.estimator.kernels import equation_parameters_of as equation_parameters  # derived once per model
from feeddrive.estimator.motion import EstimationOptions, MethodResult, MotionData, ParameterEstimate, Prepared
from feeddrive.estimator.regression import Regression, derive_regression
from feeddrive.models.drives import derived_quantities


def owners(model) -> dict[str, str]:
    """Physical parameter -> the equation that estimates it: the first, in model order, whose residual holds it
    other than as its normaliser (DC: R, L, K electrical; Jt, ft, Cd, T0 mechanical. PMSM: R, L_q, L_d, psi_f
    from the q-axis voltage equation). The other equations take it as a constant (``Regression.constants``)."""
    out: dict[str, str] = {}
    for eq in model.equations.values():
        for n in equation_parameters(model, eq.name):
            if n != eq.normaliser:
                out.setdefault(n, eq.name)
    return out


def update_constants(p: Prepared, reg: Regression, theta: np.ndarray) -> None:
    """An equation without normaliser estimates its parameters themselves: the later ones take them."""
    if reg.normaliser is None:
        p.constants.update(zip(reg.names, map(float, theta)))


def derived_estimates(result: MethodResult, model) -> dict[str, ParameterEstimate]:
    """The model's derived quantities (PMSM: K_t, K_e) from ``result``, standard errors by the delta method.

    Each interval uses the t quantile of the fewest degrees of freedom among the parameters it depends on.
    Quantities whose parameters are not all estimated or known design values are left out.
    """
    out = {}
    est = result.parameters
    for name, (_, _, expr) in derived_quantities(model).items():
        deps = [v for v in model.parameters if ca.depends_on(expr, v.sym)]
        if any(v.kind == "physical" and v.name not in est for v in deps):
            continue
        free = [v for v in deps if v.name in est]
        x = ca.vertcat(*[v.sym for v in free])
        fixed = [v for v in deps if v.name not in est]
        e = ca.substitute(expr, ca.vertcat(*[v.sym for v in fixed]), ca.DM([float(v.nominal) for v in fixed])) \
            if fixed else expr
        f = ca.Function("d", [x], [e, ca.jacobian(e, x)])
        idx = [result.names.index(v.name) for v in free]
        val, jac = f([result.values[j] for j in idx])
        jac = np.asarray(jac, dtype=float).ravel()
        std = float(np.sqrt(max(jac @ np.asarray(result.covariance)[np.ix_(idx, idx)] @ jac, 0.0)))
        dof = result.dof if result.parameter_dof is None else float(np.min(np.asarray(result.parameter_dof)[idx]))
        q = float(t_ppf(0.975, max(dof, 1)))
        v = float(val)
        out[name] = ParameterEstimate(v, std, (v - q * std, v + q * std))
    return out


def too_short(data: MotionData, options: EstimationOptions, edge: int) -> NotEnoughExcitation:
    """Why a motion is too short, in one line: what each equation needs at this rate, and what is left."""
    h, n, model = data.h, data.n, options.model
    free = [v.name for v in options.physical if (options.offset or not v.optional) and v.name not in options.known]
    have = set(data.raw()) - {"position"}
    have |= {"w"} if data.position is not None else set()
    needs, wanted = [], []
    owner = owners(model)
    for eq in model.equations.values():
        mine = [n for n in free if owner.get(n) == eq.name or n == eq.normaliser]
        borrowed = tuple(n for n in equation_parameters(model, eq.name) if n in free and n not in mine)
        reg = derive_regression(model, eq.name, mine, dict(options.known), borrowed)
        base = {x[1:] if x.startswith("D") else x for x in reg.signals if x != "sgn_w" and x not in reg.constants}
        if eq.normaliser and "torque" in have:
            base = (base - {eq.output}) | {"torque"}
        names = reg.names if base <= have else ()
        if names:
            wanted += [n for n in (*names, reg.normaliser) if n and n not in wanted]
            need = 2 * edge + 20 * len(names) + PAST + FUTURE
            needs.append(f"the {eq.name} equation needs {need} ({need * h:.3g} s)")
    order = [v.name for v in options.physical]
    return NotEnoughExcitation(
        sorted(wanted, key=order.index) or free,
        f"motion too short: {n} samples ({n * h:.3g} s at {1 / h:.3g} Hz); the filter's start-up (cut-off "
        f"{options.filter.cutoff_hz:.3g} Hz) takes {edge} at each end; " + ", ".join(needs)
        + ": nothing can be estimated from this motion")


def signals_for(p: Prepared, reg: Regression, instruments: Mapping[str, np.ndarray] | None = None) -> dict:
    out = {**p.signals, **(instruments or {}), **p.overrides[reg.equation]}
    if reg.constants:  # parameters of other equations, at their current estimate
        n = len(p.signals["w"])
        out.update({c: np.full(n, p.constants[c]) for c in reg.constants})
    return out


def constant_sensitivities(regressions: list[Regression], sources: list[Prepared], fits: dict) -> dict:
    """``{equation: {constant: d theta / d constant}}`` for the constants another equation of ``fits`` estimates.

    ``sources`` are the sample sets of each fit (one Prepared for LS, the two halves for IV), whose
    ``constants`` hold the values the outputs were evaluated with. The outputs are differentiated
    numerically (relative step 1e-6); the regressors do not depend on the constants in these models.
    """
    estimated = {n for r in regressions if r.normaliser is None and r.equation in fits for n in r.names}
    out: dict[str, dict[str, np.ndarray]] = {}
    for reg in regressions:
        fit = fits.get(reg.equation)
        if fit is None or fit.lin is None:
            continue
        for c in reg.constants:
            if c not in estimated or c in reg.names:
                continue
            dys = []
            for src in sources:
                base = src.constants[c]
                d = 1e-6 * max(abs(base), 1e-12)
                y0 = reg.evaluate(signals_for(src, reg))[0]
                src.constants[c] = base + d
                try:
                    y1 = reg.evaluate(signals_for(src, reg))[0]
                finally:
                    src.constants[c] = base
                dys.append((y1 - y0) / d)
            out.setdefault(reg.equation, {})[c] = fit.lin(dys)
    return out


def find_partners(model, regressions: list[Regression], free: list[str], known: Mapping[str, float],
                  sig: Mapping[str, np.ndarray], rows: dict, overrides: dict) -> dict[str, Regression]:
    """``Prepared.partners``: host equation -> the regression of an equation whose free parameters one other,
    unscaled equation estimates (the PMSM's d axis: R, L_d, L_q are the q axis's). Its rows (all samples) and
    overrides (none) are added to ``rows`` and ``overrides``."""
    owner = owners(model)
    partners = {}
    for eq in model.equations.values():  # an equation whose parameters one other (unscaled) equation all estimates
        held = [n for n in equation_parameters(model, eq.name) if n in free]
        hosts = {owner.get(n) for n in held}
        host = next((r for r in regressions if r.equation in hosts and r.normaliser is None), None)
        if held and len(hosts) == 1 and host is not None and host.equation != eq.name and "sgn_w" not in host.signals:
            reg = derive_regression(model, eq.name, list(host.names), dict(known))
            if reg.names and not reg.constants and all(sig.get(x) is not None for x in reg.signals):
                partners[host.equation] = reg
                rows[eq.name], overrides[eq.name] = np.ones(len(sig["w"]), dtype=bool), {}
    return partners


def ls_parts(p: Prepared, reg: Regression, instruments: Mapping[str, np.ndarray] | None = None) -> list[tuple]:
    """The sample sets ``(y, Phi, Z, rows)`` of one regression: its own, and its partner's (``Prepared.partners``)
    with the columns in its order; ``instruments`` (IV) give Z, else Z is None (LS)."""
    out = []
    for r in (reg, p.partners.get(reg.equation)):
        if r is None:
            continue
        y, Phi = r.evaluate(signals_for(p, r))
        Z = None if instruments is None else r.regressors(signals_for(p, r, instruments))
        if r is not reg:  # the partner's columns where the host has them, zero for the others (psi_f)
            idx = [r.names.index(n) if n in r.names else None for n in reg.names]
            Phi, Z = ([np.zeros(len(y)) if j is None else M[:, j] for j in idx] for M in (Phi, Z if Z is not None else Phi))
            Phi, Z = np.column_stack(Phi), (None if instruments is None else np.column_stack(Z))
        out.append((y, Phi, Z, p.rows[r.equation]))
    return out
