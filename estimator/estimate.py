"""One high-speed motion -> R, L, K, Jt, ft, Cd with uncertainties (paper sections 3-5); or the parameters of
any other drive model (``EstimationOptions.model``: the PMSM's R, L_d, L_q, psi_f, Jt, ft, Cd) by the same code.

Pipeline: identical low-pass of every signal (eq. 8) -> zero-forcing derivatives (eq. 3) ->
regressions derived from the model (eq. 4, 5) -> least squares, then instrumental variables with
instruments simulated from the model (IDIM-IV), then optionally output error (``estimator.oe``).

Uncertainty. The filtered equation errors are correlated over about 1/cutoff, so the textbook
``sigma^2 (Phi^T Phi)^-1`` would be far too optimistic. Covariances are sandwich estimates whose
middle term is a batch-means long-run variance (blocks of ``block_seconds``); confidence intervals
use Student's t with (blocks - parameters) degrees of freedom. Jt, ft, Cd (and T0) come from
theta_m = p / K and K by the delta method, K's uncertainty included; the two equations are treated
as independent.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import casadi as ca
import numpy as np

from feeddrive.estimator.derivative import FUTURE, PAST, matched_average, zero_forcing_derivative
from feeddrive.estimator.errors import EstimatorInputError, NotEnoughExcitation, NumericalFailure
from feeddrive.estimator.filtering import decimation_factor
from feeddrive.estimator.kernels import (
    equation_parameters_of,
    erode,
    measured_signals,
    parameter_defined_of,
    residual_symbols,
)
from feeddrive.estimator.linear_fit import _column_reference, _Fit, _solve
from feeddrive.estimator.model_terms import (
    constant_sensitivities,
    derived_estimates,
    find_partners,
    ls_parts,
    owners,
    signals_for,
    too_short,
    update_constants,
)
from feeddrive.estimator.motion import (
    FIELDS,
    METHODS,
    PHYSICAL,
    EstimationOptions,
    MethodResult,
    MotionData,
    MotionEstimate,
    ParameterEstimate,
    Prepared,
    check_result,
)
from feeddrive.estimator.regression import derive_regression
from feeddrive.estimator.simulation import MODEL, simulate
from feeddrive.models.drives import differentiated, measured

_signals_for = signals_for  # its former private name, still imported by partial and physical

# the data types live in .motion; they are re-exported here, where users have always found them
__all__ = ["METHODS", "PHYSICAL", "EstimationOptions", "MethodResult", "MotionData", "MotionEstimate",
           "ParameterEstimate", "Prepared", "constant_sensitivities", "derived_estimates",
           "instrumental_variables", "least_squares", "owners", "prepare", "too_short", "update_constants"]


def prepare(data: MotionData, options: EstimationOptions, strict: bool = True, remember: bool = True) -> Prepared:
    """Filter, differentiate and align the signals; derive the regressions the data allow.

    With ``strict`` False an equation without enough fast samples is left out and its parameters are
    listed in ``Prepared.refused`` with the reason, instead of raising ``NotEnoughExcitation``. With
    ``remember`` False the filtered signals are not kept for reuse (``FilterSpec.apply``).

    Returns
    -------
    Prepared
    """
    h = data.h
    model = options.model
    raw = data.raw()
    if "w" in raw:
        raw.pop("position", None)  # a tachometer is preferred to the differentiated encoder
    known_signals = measured_signals(model)
    unknown = sorted(set(raw) - set(FIELDS) - set(known_signals))
    # a torque signal: the normaliser times the output (DC: K i), or the model's own torque signal (PMSM)
    defined = parameter_defined_of(model)
    if unknown or (model is not MODEL and (("torque" in raw and "torque" not in defined)
                                           or set(raw) & {"u", "i"} - set(known_signals))):
        bad = (unknown or sorted({"torque", "u", "i"} & set(raw)))[0]
        raise EstimatorInputError(f"signal {bad!r} is not measured on the {model.name} model: expected "
                                  f"{', '.join(measured(model))} (and position)")
    edge = max(0, int(np.ceil(options.edge_guard / (options.filter.cutoff_hz * h))) - min(PAST, FUTURE))
    if options.filter.zero_phase and data.n <= 3 * (2 * len(options.filter.sos(h)) + 1):  # sosfiltfilt's padding
        raise too_short(data, options, edge)
    f = options.filter.apply(raw, h, remember)
    for name, delay in data.delays.items():
        if delay and name in f:  # a sample stamped t_n is the signal at t_n - delay: read it `delay` later
            x = f[name]
            k = np.arange(x.size, dtype=float)
            f[name] = np.interp(k + delay / h, k, x)  # the filtered signal is smooth on the sample scale
    # the filtered signals hold nothing near the Nyquist frequency: every D-th sample carries the model
    # (filtering.decimation_factor); the derivatives, guards and blocks below are at the period h D
    step = decimation_factor(options.filter.cutoff_hz, h, data.n, options.decimation)
    if step > 1:
        f = {k: np.ascontiguousarray(v[::step]) for k, v in f.items()}
        h = h * step
        edge = max(0, int(np.ceil(options.edge_guard / (options.filter.cutoff_hz * h))) - min(PAST, FUTURE))
    from_position = "position" in f
    if from_position:
        w, valid = zero_forcing_derivative(f.pop("position"), h)
        f = {k: v[valid] for k, v in f.items()} | {"w": w}
    if "w" not in f:
        raise EstimatorInputError("the motion has neither a speed nor a position signal")
    sig = {}
    for state in differentiated(model):
        if state in f:
            sig["D" + state], valid = zero_forcing_derivative(f[state], h)
    # the other signals as the derivative operator sees them (its gain error, see matched_average)
    # (a speed from the position already is one: D x = d/dt S x)
    sig.update({k: (v if k == "w" and from_position else matched_average(v))[PAST:len(v) - FUTURE]
                for k, v in f.items()})
    # the filter's start-up (both ends for zero phase: sosfiltfilt pads with a mirror image that does
    # not obey the model) would bias the fits: those samples are dropped, like the derivative's edges
    if edge:
        keep = slice(edge, -edge if options.filter.zero_phase else None)
        if len(sig["w"][keep]) < 10:
            raise too_short(data, options, edge)
        sig = {k: v[keep] for k, v in sig.items()}
    sig["sgn_w"] = np.sign(sig["w"])
    free = [v.name for v in options.physical if (options.offset or not v.optional) and v.name not in options.known]
    owner = owners(model)  # cheap: each equation's parameters are kept per model (kernels)
    regressions, overrides = [], {}
    for eq in model.equations.values():
        known, over, kept = dict(options.known), {}, ()
        if "torque" in sig and "torque" in defined \
                and ca.depends_on(eq.residual, model.variables["torque"].sym):
            kept = ("torque",)  # measured: it replaces its definition (1.5 p (psi_f i_q + (L_d - L_q) i_d i_q))
        elif eq.normaliser and "torque" in sig:
            known[eq.normaliser] = 1.0  # the torque signal is the normaliser times the output (K i)
            over[eq.output] = sig["torque"]
        mine = [n for n in free if owner.get(n) == eq.name or n == eq.normaliser]
        borrowed = tuple(n for n in equation_parameters_of(model, eq.name) if n in free and n not in mine)
        reg = derive_regression(model, eq.name, mine, known, borrowed, kept)
        if reg.names and all({**sig, **over}.get(x) is not None for x in reg.signals if x not in reg.constants):
            regressions.append(reg)
            overrides[eq.name] = over
    if not regressions and model is not MODEL:
        raise EstimatorInputError(f"no equation of the {model.name} model can be used with the signals {sorted(raw)}: "
                                  f"expected {', '.join(measured(model))} (a speed or a position at least)")
    if not regressions:
        raise EstimatorInputError(
            f"no model equation can be used with the signals {sorted(raw)}: the electrical equation "
            "(u = L di/dt + R i + K w) needs voltage, current and speed; the mechanical one (K i = Jt dw/dt + "
            "ft w + Cd sign(w)) needs current or torque, and speed. A speed is derived from the position when no "
            "speed is given (map position=COLUMN); map a current (current=COLUMN) or a torque or force "
            "(torque=COLUMN) too")
    rows, refused, notes = {}, {}, {}
    speed = np.abs(sig["w"])
    peak = float(speed.max())
    # relative to the motion's own speed range unless the user sets an absolute value
    threshold = options.speed_threshold if options.speed_threshold is not None else options.speed_fraction * peak
    for reg in regressions:
        r = np.ones(len(sig["w"]), dtype=bool)
        if "sgn_w" in reg.signals:
            fast = speed >= threshold
            if np.count_nonzero(fast) < 20 * len(reg.names):  # the real cause, with numbers, rather than "too short"
                names = list(reg.names) + ([reg.normaliser] if reg.normaliser else [])
                why = (f"{fast.size - np.count_nonzero(fast)} of {fast.size} samples have |speed| < speed_threshold {threshold:.3g} "
                       f"{options.speed_unit} (largest |speed| {peak:.3g} {options.speed_unit}); the {reg.equation} "
                       f"equation needs at least {20 * len(reg.names)} faster ones")
                if strict:
                    raise NotEnoughExcitation(names, why)
                refused.update({n: why for n in reg.names})
                continue
            # the filter smears sign(w) over about 1/cutoff around each zero crossing: widen the gap
            guard = int(np.ceil(options.sign_guard / (options.filter.cutoff_hz * h)))
            r &= erode(fast, guard, border=True)
            slow = fast.size - np.count_nonzero(fast)  # counts of the masks: r.sum()'s integers, in a third of its time
            used = np.count_nonzero(r)  # r is within the eroded fast samples: fast & ~r counts fast.size - slow - used
            notes[reg.equation] = (
                f"{used} of {r.size} samples usable: {slow} have |speed| < {threshold:.3g} "
                f"{options.speed_unit}, {fast.size - slow - used} more are within the sign guard of {guard} samples "
                f"({guard * h:.3g} s = sign_guard {options.sign_guard:g} / filter cut-off "
                f"{options.filter.cutoff_hz:.3g} Hz) around them")
        rows[reg.equation] = r
    block = max(1, int(round(options.block() / h)))
    regressions = [r for r in regressions if r.equation in rows]
    constants = {v.name: float(options.known.get(v.name, v.nominal or 0.0)) for v in options.physical}
    partners = find_partners(model, regressions, free, options.known, sig, rows, overrides)
    return Prepared(h, sig, regressions, rows, overrides, dict(options.known), block, refused, notes, constants,
                    tuple(v.name for v in options.physical), partners, step)


def _combine(method: str, p: Prepared, fits: dict[str, _Fit], iterations: int = 1,
             sensitivities: Mapping[str, Mapping[str, np.ndarray]] | None = None) -> MethodResult:
    """Physical parameters from the per-equation theta: p_j = theta_j n for a normalised equation (delta method).

    ``sensitivities`` (:func:`constant_sensitivities`): an equation whose output holds another equation's
    estimates (``Regression.constants``) inherits their errors, ``d theta_r = d theta_r0 + S d c``; the
    covariance of the stacked theta is ``M C0 M^T`` with ``C0`` the equations' own (independent) blocks.
    """
    theta, cov_blocks, names_t = [], [], []
    for reg in p.regressions:
        theta.extend(fits[reg.equation].theta)
        cov_blocks.append(fits[reg.equation].cov)
        names_t.extend((reg.equation, n) for n in reg.names)
    C = np.zeros((len(theta), len(theta)))
    k = 0
    for c in cov_blocks:
        C[k:k + len(c), k:k + len(c)] = c
        k += len(c)
    theta = np.array(theta)
    if sensitivities:
        M = np.eye(len(theta))
        for reg in p.regressions:  # model order: an equation's constants come from the equations before it
            for c, sens in sensitivities.get(reg.equation, {}).items():
                jc = next(j for j, (e, n) in enumerate(names_t) if n == c and e != reg.equation)
                rows_r = [names_t.index((reg.equation, n)) for n in reg.names]
                M[rows_r] += np.outer(sens, M[jc])
        C = M @ C @ M.T
    where = {n: j for j, (_, n) in enumerate(names_t)}
    names = [n for n in (p.order or [v.name for v in PHYSICAL]) if n in where]
    values = np.array([theta[where[n]] for n in names])
    J = np.zeros((len(names), len(theta)))
    for a, n in enumerate(names):
        J[a, where[n]] = 1.0
    for reg in p.regressions:
        if reg.normaliser is None:
            continue
        if reg.normaliser not in where:
            raise EstimatorInputError(
                f"{reg.normaliser} is needed to scale the {reg.equation} equation: give a voltage signal, "
                f"a known {reg.normaliser} or a torque signal")
        jn = where[reg.normaliser]
        for a, n in enumerate(names):
            if (reg.equation, n) in names_t and n in reg.names:
                jt = names_t.index((reg.equation, n))
                values[a] = theta[jt] * theta[jn]
                J[a] = 0.0
                J[a, jt], J[a, jn] = theta[jn], theta[jt]
    cov = J @ C @ J.T
    # Welch-Satterthwaite: a product theta_t theta_n mixes two variances with their own dof (the
    # equations' covariances are separate blocks of C)
    parts = J ** 2 * np.diag(C)
    dof_t = np.concatenate([fits[reg.equation].theta_dof for reg in p.regressions])
    with np.errstate(divide="ignore", invalid="ignore"):
        parameter_dof = parts.sum(axis=1) ** 2 / (parts ** 2 / dof_t).sum(axis=1)
    dof = min(f.dof for f in fits.values())
    parameter_dof = np.where(np.isfinite(parameter_dof), parameter_dof, dof)
    return MethodResult(method, tuple(names), values, cov, dof,
                        max(f.cond for f in fits.values()), max(f.fit for f in fits.values()), iterations,
                        parameter_dof=parameter_dof)


def least_squares(p: Prepared, options: EstimationOptions) -> MethodResult:
    """Ordinary least squares of every regression (eq. 4, 5)."""
    fits, refused = {}, []
    for reg in p.regressions:  # every equation is checked, so a refusal names all it cannot identify
        try:
            fits[reg.equation] = _solve(reg, ls_parts(p, reg), p.block, options,
                                        _column_reference(reg, _signals_for(p, reg), p.h), p.notes.get(reg.equation, ""))
        except NotEnoughExcitation as exc:
            refused.append(exc)
            continue
        update_constants(p, reg, fits[reg.equation].theta)
    if refused:
        raise NotEnoughExcitation([n for exc in refused for n in exc.unidentifiable],
                                  "; ".join(exc.reason for exc in refused),
                                  max(exc.condition_number for exc in refused))
    res = _combine("ls", p, fits, sensitivities=constant_sensitivities(p.regressions, [p], fits))
    check_result(res, options)
    return res


def instruments(source: Prepared, params: Mapping[str, float], options: EstimationOptions, shift: float = 0.0,
                n: int | None = None, skip: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """Noise-free copies of the signals, simulated from the model and ``params`` (IDIM-IV instruments).

    Each equation is simulated alone, solved for its derivative and driven by the measured filtered
    signals of ``source``; the instruments are the simulated states, their zero-forcing derivatives
    and sign, evaluated ``shift`` samples after the source's samples (cubic interpolation).

    Returns
    -------
    dict of str to ndarray, shape (n,)
        ``i``, ``w``, ``Di``, ``Dw``, ``sgn_w`` (those that can be simulated).
    """
    s, h, model = source.signals, source.h, options.model
    par = {**{v.name: v.nominal for v in options.physical if v.optional}, **params, **source.known}
    step = max(h, 0.125 / options.filter.cutoff_hz)
    n = n or len(s["w"])
    at = np.arange(n) + shift
    out, meas = {}, measured_signals(model)
    for reg in source.regressions:
        if reg.equation in skip:  # not simulated: its state is its own (measured) instrument
            continue
        eq = model.equations[reg.equation]
        sig = _signals_for(source, reg)
        inputs = {x: sig[x] for x in reg.signals if (x in meas or x == "torque") and x != eq.solves_for}
        # a torque signal replaces normaliser * output: simulate with the normaliser at 1
        values = dict(par, **{eq.normaliser: 1.0}) if source.overrides[reg.equation] else par
        out[eq.solves_for] = simulate((reg.equation,), inputs, values, h, {eq.solves_for: sig[eq.solves_for][0]},
                                      step, at=at, model=model)[eq.solves_for]
    # a state that the regressors use but whose own equation gives no regression (the PMSM's i_d: all the d-axis
    # equation's parameters come from the q axis) is simulated from its equation too, so no regressor keeps its noise
    used = {x for reg in source.regressions for x in reg.signals}
    for eq in model.equations.values():
        if eq.solves_for in out or eq.solves_for not in used or eq.name in skip or eq.solves_for not in s:
            continue
        syms = residual_symbols(model, eq.name)
        names = [x for x in meas if x != eq.solves_for and model.variables[x].sym.name() in syms]
        # an equation whose parameters were refused is not simulated: its measured state is its own instrument
        if all(x in s for x in names) and all(v.name in par for v in options.physical if v.sym.name() in syms):
            out[eq.solves_for] = simulate((eq.name,), {x: s[x] for x in names}, par, h,
                                          {eq.solves_for: s[eq.solves_for][0]}, step, at=at, model=model)[eq.solves_for]
    for k in list(out):
        d, valid = zero_forcing_derivative(out[k], h)
        out["D" + k] = np.concatenate([np.full(valid.start, d[0]), d, np.full(n - valid.stop, d[-1])])
    if "w" in out:
        out["sgn_w"] = np.sign(out["w"])
    return out


def split_halves(data: MotionData) -> tuple[MotionData, MotionData]:
    """Odd and even samples of a motion: two records of the same motion with independent white noise."""
    def half(k: int) -> MotionData:
        return MotionData(2 * data.h, *(None if x is None else x[k::2] for x in
                                        (data.u, data.i, data.w, data.position, data.torque)), data.t0 + k * data.h,
                          data.delays,  # the delays are in seconds: the same for either half
                          {n: x[k::2] for n, x in data.signals.items()})
    return half(1), half(0)


#: an IV iteration that has not converged is kept when its last step is below this many standard errors
UNSETTLED = 0.1


def instrumental_variables(data: MotionData, start: MethodResult, options: EstimationOptions,
                           check: bool = True, skip: tuple[str, ...] = ()) -> MethodResult:
    """Split-sample IDIM-IV, iterated to convergence from ``start``.

    The regression of the odd samples uses instruments simulated from the even samples, and the
    other way round. With white measurement noise the two halves carry independent noise, so the
    instruments are uncorrelated with the equation error even for the derivative of the current,
    whose only noise-free information is in the (noisy) voltage; instruments simulated from the
    same samples would bias L (about +15 % at 30 dB SNR here). Noise correlated from one sample to
    the next (not white) brings part of that bias back. The halves are sampled every 2 h (2 h D when
    the record is decimated by D: ``EstimationOptions.decimation``), so the filter cut-off must stay below
    0.45 of their Nyquist frequency (0.1125 / h before decimation). The equations in
    ``skip`` are not simulated (a derivative coefficient fixed at 0): their own state is its instrument.
    Raises NumericalFailure when the iterates have not settled (relative change below ``iv_tolerance``)
    after ``iv_iterations``: the callers fall back to LS with that reason.
    """
    odd, even = split_halves(data)
    # the halves stepped over by the record's own factor (decimation_factor's rule is about the halves: every
    # 2 h D), both alike so that sample k of either is at the same place of its half; the instruments are then
    # read one record sample, 1 / (2 D) of theirs, off
    every = decimation_factor(options.filter.cutoff_hz, data.h, data.n, options.decimation)
    half_options = replace(options, decimation=every)
    # the halves are new views of the record, filtered here only: not kept for reuse (no copy of their samples)
    # only the equations of ``start`` (LS's): a half may derive one that LS refused (UMich's mechanical equation, 22
    # usable samples), whose instruments need the refused parameters ("simulation needs parameter 'Jt'")
    halves = tuple(replace(h, regressions=[r for r in h.regressions if set(r.names) <= set(start.names)])
                   for h in (prepare(half, half_options, strict=check, remember=False) for half in (odd, even)))
    if [r.equation for r in halves[0].regressions] != [r.equation for r in halves[1].regressions]:
        raise NotEnoughExcitation(sorted(set(halves[0].refused) | set(halves[1].refused)),
                                  "the odd and even samples do not allow the same equations")
    measured = {(reg.equation, k): reg.evaluate(_signals_for(half, reg))
                for k, half in enumerate(halves) for reg in half.regressions}
    cur, step, change = start, None, np.inf
    # the same in every iteration: computed once
    reference = {reg.equation: _column_reference(reg, _signals_for(halves[0], reg), halves[0].h)
                 for reg in halves[0].regressions}
    memo = {reg.equation: {} for reg in halves[0].regressions}  # the measured regressors' rows and scale, kept
    for it in range(1, options.iv_iterations + 1):
        params = cur.as_dict()
        for k, half in enumerate(halves):  # outputs with parameters of other equations follow their estimates
            half.constants.update({n: v for n, v in params.items() if n in half.constants})
            measured.update({(reg.equation, k): reg.evaluate(_signals_for(half, reg))
                             for reg in half.regressions if reg.constants})
        z = (instruments(halves[1], params, options, +0.5 / every, len(halves[0].signals["w"]), skip),
             instruments(halves[0], params, options, -0.5 / every, len(halves[1].signals["w"]), skip))
        fits, parts = {}, {}
        for reg in halves[0].regressions:
            parts[reg.equation] = [(*measured[reg.equation, k], reg.regressors(_signals_for(half, reg, zh)),
                                    half.rows[reg.equation]) for k, (half, zh) in enumerate(zip(halves, z))]
            if reg.equation in halves[0].partners:  # the partner's sample sets, instruments from the other half too
                parts[reg.equation] += [part for half, zh in zip(halves, z) for part in ls_parts(half, reg, zh)[1:]]
            if reg.constants:  # its output follows the other equations' estimates: its column scale too
                reference[reg.equation] = _column_reference(reg, _signals_for(halves[0], reg), halves[0].h)
            try:
                fits[reg.equation] = _solve(reg, parts[reg.equation], halves[0].block, options,
                                            reference[reg.equation], covariance=False, memo=memo[reg.equation])
            except np.linalg.LinAlgError:  # numpy's "Singular matrix" says nothing to a user: what was singular
                raise NumericalFailure(_singular(reg, params, halves[0], z[0], options)) from None
        new = _combine("iv", halves[0], fits, it, constant_sensitivities(halves[0].regressions, list(halves), fits))
        step = np.abs(new.values - cur.values)
        change = np.max(step / np.maximum(np.abs(cur.values), 1e-12))
        cur = new
        if change < options.iv_tolerance or it == options.iv_iterations:
            # the last iteration's fits with their covariance (from the arrays they were solved with)
            last = {eq: fit.complete() for eq, fit in fits.items()}
            cur = _combine("iv", halves[0], last, it, constant_sensitivities(halves[0].regressions, list(halves), last))
            break
    if not change < options.iv_tolerance:
        # the last iterate of an iteration that does not settle is no estimate: on a record the model does not
        # fit (REGBOT's lagged current) the instruments simulated from the previous iterate jump from one
        # iterate to the next, and the 10th depends on the last bits of the data (a 1e-15 relative change of
        # the samples moved K by +-30 %). A last step far inside every interval (under UNSETTLED standard
        # errors) is kept, said so: the unsettled digits are noise (REGBOT's other file: 2e-4 relative)
        if step is None:
            raise NumericalFailure("IV: no iteration run (iv_iterations = 0)")
        std = np.sqrt(np.clip(np.diag(cur.covariance), 0, None))
        moved = float(np.max(step / np.maximum(std, 1e-300)))
        if not moved < UNSETTLED:
            raise NumericalFailure(f"IV did not converge in {options.iv_iterations} iterations (relative change "
                                   f"of the parameters {change:.3g} at the last, {moved:.3g} standard errors; "
                                   f"tolerance {options.iv_tolerance:g})")
        cur = replace(cur, message=(cur.message + "; " if cur.message else "") +
                      f"IV stopped after {options.iv_iterations} iterations: the last changed the parameters by "
                      f"{change:.3g} (relative), {moved:.2g} of their standard errors")
    if check:
        check_result(cur, options)
    return cur


def _singular(reg, params: Mapping[str, float], half: Prepared, z: Mapping[str, np.ndarray],
              options: EstimationOptions) -> str:
    """Why IV's system of ``reg`` is singular, in the user's words: its simulated instruments, with the parameters
    they were simulated at, and the state that diverged (peak over the measured one's) if one did."""
    at = ", ".join(f"{n} = {params[n]:.4g}" for n in reg.names if n in params)
    grown = [f"{x} [{options.model.variables[x].unit}] peaks at {np.max(np.abs(z[x])):.3g} (measured "
             f"{np.max(np.abs(half.signals[x])):.3g}): an unstable simulation" for x in z if x in half.signals and
             x in options.model.variables and not np.max(np.abs(z[x])) <= 1e6 * np.max(np.abs(half.signals[x]))]
    return (f"the {reg.equation} equation's instruments simulated at {at} leave its parameters undetermined (a "
            f"singular system{': the simulated ' + ', '.join(grown) if grown else ''})")


def fell_back(result: MethodResult, method: str, reason: str) -> MethodResult:
    """``result`` standing in for ``method``, which could not run: labelled ``method``, ``ran`` says what ran."""
    return replace(result, method=method, message=reason, ran=result.method_used)
