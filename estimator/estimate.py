"""One high-speed motion -> R, L, K, Jt, ft, Cd with uncertainties (paper sections 3-5).

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
from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import binary_erosion

from feeddrive.estimator.derivative import FUTURE, PAST, matched_average, zero_forcing_derivative
from feeddrive.estimator.errors import EstimatorInputError, NotEnoughExcitation, NumericalFailure
from feeddrive.estimator.motion import (
    MEASURED,
    METHODS,
    PHYSICAL,
    EstimationOptions,
    MethodResult,
    MotionData,
    MotionEstimate,
    ParameterEstimate,
    Prepared,
    check_result,
    parameter_covariance,
    stationary_score_covariance,
)
from feeddrive.estimator.regression import Regression, derive_regression
from feeddrive.estimator.simulation import MODEL, simulate

# the data types live in .motion; they are re-exported here, where users have always found them
__all__ = ["METHODS", "PHYSICAL", "EstimationOptions", "MethodResult", "MotionData", "MotionEstimate",
           "ParameterEstimate", "Prepared", "estimate_motion", "instrumental_variables", "least_squares", "prepare"]


def prepare(data: MotionData, options: EstimationOptions, strict: bool = True) -> Prepared:
    """Filter, differentiate and align the signals; derive the regressions the data allow.

    With ``strict`` False an equation without enough fast samples is left out and its parameters are
    listed in ``Prepared.refused`` with the reason, instead of raising ``NotEnoughExcitation``.

    Returns
    -------
    Prepared
    """
    h = data.h
    raw = {k: getattr(data, k) for k in ("u", "i", "w", "position", "torque") if getattr(data, k) is not None}
    if data.w is not None:
        raw.pop("position", None)  # a tachometer is preferred to the differentiated encoder
    edge = max(0, int(np.ceil(options.edge_guard / (options.filter.cutoff_hz * h))) - min(PAST, FUTURE))
    if options.filter.zero_phase and data.n <= 3 * (2 * len(options.filter.sos(h)) + 1):  # sosfiltfilt's padding
        raise too_short(data, options, edge)
    f = options.filter.apply(raw, h)
    for name, delay in data.delays.items():
        if delay and name in f:  # a sample stamped t_n is the signal at t_n - delay: read it `delay` later
            x = f[name]
            k = np.arange(x.size, dtype=float)
            f[name] = np.interp(k + delay / h, k, x)  # the filtered signal is smooth on the sample scale
    from_position = "position" in f
    if from_position:
        w, valid = zero_forcing_derivative(f.pop("position"), h)
        f = {k: v[valid] for k, v in f.items()} | {"w": w}
    if "w" not in f:
        raise EstimatorInputError("the motion has neither a speed nor a position signal")
    sig = {}
    for state in ("i", "w"):
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
    free = [v.name for v in PHYSICAL if (options.offset or not v.optional) and v.name not in options.known]
    regressions, overrides = [], {}
    for eq in MODEL.equations.values():
        known, over = dict(options.known), {}
        if eq.normaliser and "torque" in sig:
            known[eq.normaliser] = 1.0  # the torque signal is the normaliser times the output (K i)
            over[eq.output] = sig["torque"]
        reg = derive_regression(MODEL, eq.name, free, known)
        if reg.names and all({**sig, **over}.get(x) is not None for x in reg.signals):
            regressions.append(reg)
            overrides[eq.name] = over
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
            if fast.sum() < 20 * len(reg.names):  # the real cause, with numbers, rather than "too short"
                names = list(reg.names) + ([reg.normaliser] if reg.normaliser else [])
                why = (f"{int((~fast).sum())} of {fast.size} samples have |speed| < speed_threshold {threshold:.3g} "
                       f"{options.speed_unit} (largest |speed| {peak:.3g} {options.speed_unit}); the {reg.equation} "
                       f"equation needs at least {20 * len(reg.names)} faster ones")
                if strict:
                    raise NotEnoughExcitation(names, why)
                refused.update({n: why for n in reg.names})
                continue
            # the filter smears sign(w) over about 1/cutoff around each zero crossing: widen the gap
            guard = int(np.ceil(options.sign_guard / (options.filter.cutoff_hz * h)))
            r &= binary_erosion(fast, iterations=guard, border_value=True)
            notes[reg.equation] = (
                f"{int(r.sum())} of {r.size} samples usable: {int((~fast).sum())} have |speed| < {threshold:.3g} "
                f"{options.speed_unit}, {int((fast & ~r).sum())} more are within the sign guard of {guard} samples "
                f"({guard * h:.3g} s = sign_guard {options.sign_guard:g} / filter cut-off "
                f"{options.filter.cutoff_hz:.3g} Hz) around them")
        rows[reg.equation] = r
    block = max(1, int(round(options.block() / h)))
    regressions = [r for r in regressions if r.equation in rows]
    return Prepared(h, sig, regressions, rows, overrides, dict(options.known), block, refused, notes)


def too_short(data: MotionData, options: EstimationOptions, edge: int) -> NotEnoughExcitation:
    """Why a motion is too short, in one line: what each equation needs at this rate, and what is left."""
    h, n = data.h, data.n
    free = [v.name for v in PHYSICAL if (options.offset or not v.optional) and v.name not in options.known]
    have = {k for k in ("u", "i", "w", "torque") if getattr(data, k) is not None}
    have |= {"w"} if data.position is not None else set()
    needs, wanted = [], []
    for eq in MODEL.equations.values():
        reg = derive_regression(MODEL, eq.name, free, dict(options.known))
        base = {x[1:] if x.startswith("D") else x for x in reg.signals if x != "sgn_w"}
        if eq.normaliser and "torque" in have:
            base = (base - {eq.output}) | {"torque"}
        names = reg.names if base <= have else ()
        if names:
            wanted += [n for n in (*names, reg.normaliser) if n and n not in wanted]
            need = 2 * edge + 20 * len(names) + PAST + FUTURE
            needs.append(f"the {eq.name} equation needs {need} ({need * h:.3g} s)")
    order = [v.name for v in PHYSICAL]
    return NotEnoughExcitation(
        sorted(wanted, key=order.index) or free,
        f"motion too short: {n} samples ({n * h:.3g} s at {1 / h:.3g} Hz); the filter's start-up (cut-off "
        f"{options.filter.cutoff_hz:.3g} Hz) takes {edge} at each end; " + ", ".join(needs)
        + ": nothing can be estimated from this motion")


def _signals_for(p: Prepared, reg: Regression, instruments: Mapping[str, np.ndarray] | None = None) -> dict:
    return {**p.signals, **(instruments or {}), **p.overrides[reg.equation]}


@dataclass
class _Fit:
    theta: np.ndarray
    cov: np.ndarray
    dof: int
    cond: float
    fit: float
    theta_dof: np.ndarray  # (p,) effective dof of each theta's variance


def _column_reference(reg: Regression, signals: Mapping[str, np.ndarray], h: float) -> np.ndarray:
    """The norm each regressor column would have if its signals kept their own RMS level (a derivative
    ``Dx``: the RMS of ``x`` per motion duration; sign(w): 1). A column far below it (1e-9) is rounding
    noise, e.g. the derivative of a constant speed. Unit-free: nothing refers to nominal parameters."""
    n = len(signals["w"])
    duration = n * h

    def rms(x: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.square(x)))) or 1.0

    proxy = {}
    for name in reg.signals:
        if name == "sgn_w":
            proxy[name] = 1.0
        elif name.startswith("D") and signals.get(name[1:]) is not None:
            proxy[name] = rms(signals[name[1:]]) / duration
        else:
            proxy[name] = rms(signals[name])
    _, Phi = reg.evaluate({k: np.full(n, v) for k, v in proxy.items()})
    return np.sqrt(np.einsum("ij,ij->j", Phi, Phi))


def _solve(reg: Regression, parts: list[tuple], block: int, options: EstimationOptions,
           reference: np.ndarray | None = None, note: str = "") -> _Fit:
    """LS or basic IV on the usable rows of one or more sample sets, column-scaled.

    Each part is ``(y (n,), Phi (n, p), Z (n, p) or None, rows (n,) bool)``. With ``Z`` None: LS
    (``lstsq``, not the normal equations), after the excitation check. Otherwise IV: ``theta = (sum Z^T Phi)^-1 sum Z^T y``. The parts are
    sample sets of the same time span (sample k of every part near the same time), so their score
    contributions are added sample by sample before the long-run covariance.
    """
    p = parts[0][1].shape[1]
    used = sum(int(r.sum()) for *_, r in parts)
    if used < 20 * p:
        raise NotEnoughExcitation(list(reg.names) + ([reg.normaliser] if reg.normaliser else []),
                                  f"motion too short: {used} usable samples in the {reg.equation} "
                                  f"equation, its {p} parameters ({', '.join(reg.names)}) need at least {20 * p}"
                                  + (f" ({note})" if note else ""))
    def rows(x, r):
        return x if r.all() else x[r]

    Xr = [rows(Phi, r) for _, Phi, _, r in parts]
    ys = [rows(y, r) for y, _, _, r in parts]
    scale = np.sqrt(sum(np.einsum("ij,ij->j", X, X) for X in Xr))
    # a column that is rounding noise (a derivative at constant speed) is empty, however well conditioned
    # column scaling makes it look; judged against the column's own scale (see _column_reference)
    empty = scale <= 1e-9 * reference if reference is not None else np.zeros(p, dtype=bool)
    scale[empty] = 1.0
    Xs = [X / scale for X in Xr]
    # singular values of the scaled regressor from its p x p Gram matrix (cheap; fine up to cond ~1e7)
    eig, V = np.linalg.eigh(sum(X.T @ X for X in Xs)[np.ix_(~empty, ~empty)])
    sv, Vt = np.sqrt(np.clip(eig[::-1], 0, None)), V[:, ::-1].T
    cond = sv[0] / sv[-1] if sv[-1] > 0 and not empty.any() else np.inf
    if parts[0][2] is None:
        if cond > options.max_condition:
            weak = np.zeros(p, dtype=bool)
            weak[~empty] = np.abs(Vt[sv < sv[0] / options.max_condition]).max(axis=0, initial=0) > 0.1
            bad = [n for n, b in zip(reg.names, weak | empty) if b]
            raise NotEnoughExcitation(bad, f"{reg.equation} regressor condition number {cond:.3g} > "
                                      f"{options.max_condition:.3g} (constant speed, no speed reversal?)", cond)
        Ws = Xs
        theta_s = np.linalg.lstsq(np.vstack(Xs), np.concatenate(ys), rcond=None)[0]
    else:
        Zr = [rows(Z, r) for _, _, Z, r in parts]
        zscale = np.sqrt(sum(np.einsum("ij,ij->j", Z, Z) for Z in Zr)).clip(1e-300)
        Ws = [Z / zscale for Z in Zr]
        theta_s = np.linalg.solve(sum(W.T @ X for W, X in zip(Ws, Xs)), sum(W.T @ y for W, y in zip(Ws, ys)))
    A = sum(W.T @ X for W, X in zip(Ws, Xs))
    n = min(len(y) for y, *_ in parts)
    G = np.zeros((n, p))
    res2 = out2 = 0.0
    stationary = []  # (instruments, errors) with the unused rows zero, for the stationary-error floor
    for (y, _, _, r), W, X, yr in zip(parts, Ws, Xs, ys):
        e = yr - X @ theta_s
        g = np.zeros((len(y), p))
        g[r] = W * e[:, None]
        G += g[:n]
        res2 += e @ e
        out2 += yr @ yr
        ef = np.zeros(len(y))
        ef[r] = e
        Wf = np.zeros((len(y), p))
        Wf[r] = W
        stationary.append((Wf, ef))
    cov, dof, nb = parameter_covariance(G, np.linalg.inv(A), block, stationary_score_covariance(stationary, block))
    return _Fit(theta_s / scale, cov / np.outer(scale, scale), nb - p, float(cond),
                float(np.sqrt(res2 / out2)), dof)


def _combine(method: str, p: Prepared, fits: dict[str, _Fit], iterations: int = 1) -> MethodResult:
    """Physical parameters from the per-equation theta: p_j = theta_j n for a normalised equation (delta method)."""
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
    where = {n: j for j, (_, n) in enumerate(names_t)}
    names = [v.name for v in PHYSICAL if v.name in where]
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
        y, Phi = reg.evaluate(_signals_for(p, reg))
        try:
            fits[reg.equation] = _solve(reg, [(y, Phi, None, p.rows[reg.equation])], p.block, options,
                                        _column_reference(reg, _signals_for(p, reg), p.h), p.notes.get(reg.equation, ""))
        except NotEnoughExcitation as exc:
            refused.append(exc)
    if refused:
        raise NotEnoughExcitation([n for exc in refused for n in exc.unidentifiable],
                                  "; ".join(exc.reason for exc in refused),
                                  max(exc.condition_number for exc in refused))
    res = _combine("ls", p, fits)
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
    s, h = source.signals, source.h
    par = {**{v.name: v.nominal for v in PHYSICAL if v.optional}, **params, **source.known}
    step = max(h, 0.125 / options.filter.cutoff_hz)
    n = n or len(s["w"])
    at = np.arange(n) + shift
    out = {}
    for reg in source.regressions:
        if reg.equation in skip:  # not simulated: its state is its own (measured) instrument
            continue
        eq = MODEL.equations[reg.equation]
        sig = _signals_for(source, reg)
        inputs = {x: sig[x] for x in reg.signals if x in MEASURED and x != eq.solves_for}
        # a torque signal replaces normaliser * output: simulate with the normaliser at 1
        values = dict(par, **{eq.normaliser: 1.0}) if source.overrides[reg.equation] else par
        out[eq.solves_for] = simulate((reg.equation,), inputs, values, h, {eq.solves_for: sig[eq.solves_for][0]},
                                      step, at=at)[eq.solves_for]
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
                          data.delays)  # the delays are in seconds: the same for either half
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
    the next (not white) brings part of that bias back. The halves are sampled every 2 h, so the
    filter cut-off must stay below 0.45 of their Nyquist frequency (0.1125 / h). The equations in
    ``skip`` are not simulated (a derivative coefficient fixed at 0): their own state is its instrument.
    Raises NumericalFailure when the iterates have not settled (relative change below ``iv_tolerance``)
    after ``iv_iterations``: the callers fall back to LS with that reason.
    """
    odd, even = split_halves(data)
    halves = (prepare(odd, options, strict=check), prepare(even, options, strict=check))
    if [r.equation for r in halves[0].regressions] != [r.equation for r in halves[1].regressions]:
        raise NotEnoughExcitation(sorted(set(halves[0].refused) | set(halves[1].refused)),
                                  "the odd and even samples do not allow the same equations")
    measured = {(reg.equation, k): reg.evaluate(_signals_for(half, reg))
                for k, half in enumerate(halves) for reg in half.regressions}
    cur = start
    for it in range(1, options.iv_iterations + 1):
        params = cur.as_dict()
        z = (instruments(halves[1], params, options, +0.5, len(halves[0].signals["w"]), skip),
             instruments(halves[0], params, options, -0.5, len(halves[1].signals["w"]), skip))
        fits = {}
        for reg in halves[0].regressions:
            parts = [(*measured[reg.equation, k], reg.evaluate(_signals_for(half, reg, zh))[1],
                      half.rows[reg.equation]) for k, (half, zh) in enumerate(zip(halves, z))]
            fits[reg.equation] = _solve(reg, parts, halves[0].block, options,
                                        _column_reference(reg, _signals_for(halves[0], reg), halves[0].h))
        new = _combine("iv", halves[0], fits, it)
        step = np.abs(new.values - cur.values)
        change = np.max(step / np.maximum(np.abs(cur.values), 1e-12))
        cur = new
        if change < options.iv_tolerance:
            break
    else:
        # the last iterate of an iteration that does not settle is no estimate: on a record the model does not
        # fit (REGBOT's lagged current) the instruments simulated from the previous iterate jump from one
        # iterate to the next, and the 10th depends on the last bits of the data (a 1e-15 relative change of
        # the samples moved K by +-30 %). A last step far inside every interval (under UNSETTLED standard
        # errors) is kept, said so: the unsettled digits are noise (REGBOT's other file: 2e-4 relative)
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


def fell_back(result: MethodResult, method: str, reason: str) -> MethodResult:
    """``result`` standing in for ``method``, which could not run: labelled ``method``, ``ran`` says what ran."""
    return replace(result, method=method, message=reason, ran=result.method_used)


def estimate_motion(data: MotionData, options: EstimationOptions = EstimationOptions()) -> MotionEstimate:
    """Estimate the physical parameters of one high-speed motion.

    Parameters
    ----------
    data : MotionData
        Voltage, current and speed (or position, or torque) of one motion, sampled every ``data.h``.
    options : EstimationOptions

    Returns
    -------
    MotionEstimate
        LS always; IV for methods ``iv`` and ``oe``; OE for ``oe`` (falls back to IV with a message).

    Raises
    ------
    NotEnoughExcitation
        The data cannot determine some parameters (they are named); no numbers are returned.
    EstimatorInputError
        Unusable signals or options.
    """
    p = prepare(data, options)
    ls = least_squares(p, options)
    iv = oe = None
    if options.method in ("iv", "oe"):
        try:
            iv = instrumental_variables(data, ls, options)
        except (NumericalFailure, np.linalg.LinAlgError) as exc:  # e.g. L/R far below the instruments' step
            iv = fell_back(ls, "iv", f"IV fell back to LS: {exc}")
    if options.method == "oe":
        from feeddrive.estimator.oe import output_error

        oe = output_error(p, iv, options)
    return MotionEstimate(options.method, float(data.t0), float(data.t0 + (data.n - 1) * data.h), ls, iv, oe)
