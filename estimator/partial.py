"""One parameter at a time: each physical parameter is given or refused on its own reason (issue 22).

``estimate_motion`` gives all the parameters of a motion or raises ``NotEnoughExcitation`` (the monitor
needs the whole set to validate it). ``estimate_parameters`` gives every parameter the data determine
and names the others with the rule that refuses them and its numbers:

* ``one direction``: every usable sample of the mechanical equation has the same sign of speed, so
  ``Cd sign(w)`` is a constant torque, the same as an offset or a load torque: Cd (and T0) refused;
* ``speed range``: ``|w|`` spans too narrow a range (``MIN_SPEED_SPREAD`` of its largest value between the 5th
  and 95th percentiles) for ``ft w`` to be told from ``Cd sign(w)``: ft and Cd refused;
* ``sample period``: an equation's time constant, its derivative parameter over its resistance read from the
  model (``time_constants``: L/R; the PMSM's L_q/R and L_d/R), has a 95 % upper bound shorter than
  ``identifiability.MIN_TAU_SAMPLES`` sample periods: that parameter refused and fixed at 0, the others from the quasi-static
  equation (DC: ``u = R i + K w``). And at an NC's rate (``nc_rate.MAX_HALF_PHASE``) a parameter on which IV (its
  halves sampled every 2 h alias the signals) and LS disagree beyond what LS's noise bias explains
  (``nc_rate.rate_rule``); below that, every interval there holds the method's systematic error
  (``nc_rate.systematic``: IV - LS, or LS's noise bias, LS asked for or standing in for IV);
* ``second lag``: the current follows the voltage through two time constants of comparable size (a sensor's
  low-pass on the current): L/R is one of them and the data cannot tell which (identifiability.py): L refused,
  kept in the fit as a lumped term, R and K given. The lag biases the rest too: each equation in that current
  is fitted again with the lag's terms (the electrical one with d2i/dt2, the others with the current's
  derivative), and a given parameter whose lag-free value falls outside its printed interval is refused
  (``lag bias``: ft 2.2 times its value at a 20 ms current filter, with an interval excluding the truth);
* ``excitation``: the estimator's rules, per parameter: too few (fast) samples in its equation, a weak
  direction of the column-scaled regressor (condition number above ``max_condition``), and, for every
  parameter, a 95 % interval wider than ``+-1.96 max_relative_std`` of its value (the printed interval
  itself, so a t quantile with few degrees of freedom counts), or fewer covariance blocks than parameters;
  a friction parameter tied to the other, refused, beyond ``MAX_INFLATION`` (its interval given the refused
  one's estimate would hold only if that estimate were the truth).

One rule decides what is given: a parameter is printed only if no rule refuses it, so no printed
interval is wider than the one that refuses another file's parameter. A parameter refused because it is
collinear with others is fixed in the re-fit of the others (``fixed``: L, Jt, ft or T0 at 0), or kept as
a lumped term (Cd carries ``Cd + T0`` or the friction at the motion's speed) and not given.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from feeddrive.estimator.distributions import norm_ppf, t_ppf
from feeddrive.estimator.errors import EstimatorInputError, NotEnoughExcitation
from feeddrive.estimator.estimate import (
    _column_reference,
    _combine,
    _signals_for,
    _solve,
    constant_sensitivities,
    derived_estimates,
    ls_parts,
    prepare,
    update_constants,
)
from feeddrive.estimator.identifiability import lag_reason, lag_terms, second_lag, tau_rule, time_constants
from feeddrive.estimator.lagged_iv import iv_with_fallbacks
from feeddrive.estimator.linear_fit import conditional_covariance
from feeddrive.estimator.medians import percentiles_in_place
from feeddrive.estimator.motion import EstimationOptions, MethodResult, MotionData, MotionEstimate
from feeddrive.estimator.nc_rate import rate_rule, systematic
from feeddrive.estimator.physical import Bounds, bounded_fit, impossible, physical_flags
from feeddrive.estimator.pvalue_text import p_text
from feeddrive.estimator.sign_convention import sign_hint
from feeddrive.models.drives import differentiated

#: Smallest spread of |w| (5th to 95th percentile, relative to the 95th) that separates ft from Cd.
MIN_SPEED_SPREAD = 0.2
#: Largest variance inflation of a friction parameter by the other, refused (its variance over its variance given
#: that estimate; 10 is the usual collinearity threshold): above it, it is refused too (``_rule``).
MAX_INFLATION = 10.0
#: Variance inflation by the refused parameters beyond which a parameter's conditional interval is no interval.
DEGENERATE = 1e12
#: What a refusal at a physically impossible estimate says: the others are not given conditional on it (``_rule``).
NOT_ASSUMED = "the others' intervals do not assume it"
#: The friction pair that one motion tells apart only through its speed range.
FRICTION = {"ft": "Cd", "Cd": "ft"}
#: Fewest usable samples of the minority direction for Cd to be told from an offset.
MIN_REVERSED = 20
#: Parameters that may be fixed (at 0) in the re-fit of the others when the data cannot determine them.
#: (the PMSM's L_d when the d axis is not excited: its term p w L_d i_d is then zero whatever its value)
FIXABLE = ("L", "L_d", "L_q", "Jt", "ft", "T0")


def _apriori(p, options: EstimationOptions, fixed: dict, refused: dict, lumped: set) -> bool:
    """The rules decided from the data alone (one direction, speed range). True if something was fixed."""
    mech = next((r for r in p.regressions if r.equation == "mechanical"), None)
    if mech is None:
        return False
    w, changed = p.signals["w"][p.rows["mechanical"]], False
    if "Cd" in mech.names and "T0" in mech.names and "Cd" not in refused:
        pos, neg = np.count_nonzero(w > 0), np.count_nonzero(w < 0)  # the boolean sums' integers
        if min(pos, neg) < MIN_REVERSED:
            why = (f"one direction only: {pos} usable samples at w > 0, {neg} at w < 0 (need {MIN_REVERSED} of "
                   f"each): Cd and the torque offset T0 are confounded (only Cd + T0 is determined)")
            refused.update({"Cd": why, "T0": why})
            lumped.add("Cd")
            fixed["T0"], changed = 0.0, True
    if "ft" in mech.names and "Cd" in mech.names and "ft" not in refused:
        a = np.abs(w)  # ours: its percentiles selected in place (np.percentile's values), numpy's if not finite
        lo, hi = (percentiles_in_place(a, (5, 95)) if a.size >= 2 and np.isfinite(a).all() else
                  np.percentile(a, [5, 95]) if a.size else (0.0, 0.0))
        spread = (hi - lo) / hi if hi > 0 else 0.0
        if spread < MIN_SPEED_SPREAD:
            why = (f"too narrow a speed range: |w| within [{lo:.4g}, {hi:.4g}] {options.speed_unit} on 90 % of the "
                   f"usable samples (spread {spread:.0%} < {MIN_SPEED_SPREAD:.0%}): viscous ft and dry Cd friction "
                   f"cannot be told apart")
            refused.update({"ft": why, "Cd": refused.get("Cd", why)})
            lumped.add("Cd")
            fixed["ft"], changed = 0.0, True
    return changed


def _weak(exc: NotEnoughExcitation, reg, fixed: dict, refused: dict, lumped: set) -> bool:
    """A weak direction in ``reg``: fix what can be fixed (True), or refuse the whole equation (False)."""
    weak = [n for n in exc.unidentifiable if n in reg.names]
    if weak and "condition number" in exc.reason:
        if set(weak) <= set(FIXABLE) | {"Cd"}:
            if "Cd" in weak and ({"ft", "T0"} & set(weak)):
                weak.remove("Cd")
                lumped.add("Cd")
                refused.setdefault("Cd", exc.reason)
            for n in weak:
                fixed[n] = 0.0
                refused.setdefault(n, exc.reason)
            return True
    for n in reg.names:  # the whole equation (not its normaliser: K may come from the other equation)
        refused.setdefault(n, exc.reason)
    return False


def _lag_bias(p, fits: dict, lagging: set, model, lagfree: dict) -> None:
    """The other equations in a current whose measurement lags (``_lag_rule`` found it) fitted again with the lag's
    terms (``identifiability.lag_terms``); where the Wald test rejects them (5 %), the lag's effect on their
    parameters goes into ``lagfree`` (name -> (lag-free minus first-order LS value, relative to the equation's
    normaliser; Wald p; current)), which ``_lag_check`` holds the given intervals against."""
    for state in lagging:
        for reg in p.regressions:
            fit = fits.get(reg.equation)
            if fit is None or state not in reg.signals or any(eq == reg.equation and s == state
                                                              for eq, s, _, _ in time_constants(model)):
                continue
            sig = _signals_for(p, reg)
            if "D" + state not in sig:
                continue
            rows = p.rows[reg.equation]
            y, Phi = reg.evaluate(sig)
            y_d, Phi_d = reg.evaluate({**sig, state: sig["D" + state]})
            cols = ([y_d] if not np.array_equal(y_d, y) else []) + [
                Phi_d[:, j] for j in range(Phi.shape[1]) if not np.array_equal(Phi_d[:, j], Phi[:, j])]
            if not cols:
                continue
            try:
                test = lag_terms(y[rows], Phi[rows], np.column_stack(cols)[rows], p.block)
            except (np.linalg.LinAlgError, ValueError):
                continue
            if test is not None and test["p_value"] < 0.05:
                for j, n in enumerate(reg.names):  # the lag's effect: both LS, so LS's own noise bias cancels
                    lagfree[n] = (float(test["theta"][j] - fit.theta[j]), reg.normaliser, test["p_value"], state)


def _lag_check(result: MethodResult, lagfree: dict, refused: dict, lumped: set) -> None:
    """A given parameter whose lag-free value (``_lag_bias``) lies outside its printed 95 % interval is refused:
    the interval holds the measurement's lag, not the motor (a current low-passed by 20 ms gave ft 2.2 times its
    value with an interval of [1.5, 2.9] times it; the lag-free fit 1.08 times)."""
    names = list(result.names)
    values = np.asarray(result.values, dtype=float)
    cov = np.asarray(result.covariance, dtype=float)
    dof = np.full(len(names), float(result.dof)) if result.parameter_dof is None else np.asarray(result.parameter_dof)
    for n, (delta, normaliser, p_value, state) in lagfree.items():
        if n not in names or n in refused or n in lumped:
            continue
        scale = 1.0
        if normaliser is not None:
            if normaliser not in names:
                continue
            scale = float(values[names.index(normaliser)])
        j = names.index(n)
        half = float(t_ppf(0.975, max(float(dof[j]), 1.0))) * float(np.sqrt(max(cov[j, j], 0.0)))
        value = float(values[j])
        free = value + delta * scale  # the given value without the lag's effect measured on LS
        if abs(free - value) > half:
            test = "with the d2i/dt2 term" if p_value != p_value else f"with the lag's terms (Wald {p_text(p_value)})"
            refused[n] = (f"biased by the lag of the {state} measurement (the second lag test): fitted {test} it is "
                          f"{free:.4g}, outside its 95 % interval [{value - half:.4g}, {value + half:.4g}] "
                          f"({result.method_used.upper()}: {value:.4g})")


def _lag_rule(p, reg, y: np.ndarray, Phi: np.ndarray, fit, refused: dict, lumped: set, model,
              lagfree: dict | None = None) -> str | None:
    """An inductance refused (and kept in the fit as a lumped term) when its current shows a second lag
    (identifiability.py): the equation of ``reg`` whose state is a current [A], with its time constant slope /
    resistance read from the model (``time_constants``: L/R; the PMSM's L_q/R in the q-axis regression).
    Returns the lagging current's name when the rule fired (``_lag_bias`` then checks the other equations)."""
    mask = p.rows[reg.equation]
    start, stop = int(np.argmax(mask)), len(mask) - int(np.argmax(mask[::-1]))
    if not mask.any() or not mask[start:stop].all():
        return None  # the d2i/dt2 column needs contiguous samples
    rows = slice(start, stop)  # the mask's samples read as views, not gathered (the same values)
    fired = None
    for eq, state, a, r in time_constants(model):
        if eq != reg.equation or model.variables[state].unit != "A" or a in refused or not {a, r} <= set(reg.names):
            continue
        sig = _signals_for(p, reg)
        Di = sig.get("D" + state)
        if Di is None:
            continue
        # a lag of the measurement lags the equation's other currents too: under field weakening (i_d ~ -17 A)
        # the q axis's p w L_d i_d gains p w L_d tau_f Di_d, which the d2i_q/dt2 column cannot take; unmodelled, it
        # biased R so that the smaller time constant fell below MIN_LAG_RATIO of the larger and the rule did not
        # fire. Each column in another current, with that current replaced by its derivative, is a nuisance.
        others = [x for x in differentiated(model) if x != state and model.variables[x].unit == "A"
                  and "D" + x in sig and x in reg.signals]
        extra = None
        if others:
            Phi_d = reg.regressors({**sig, **{x: sig["D" + x] for x in others}})
            moved = [j for j in range(Phi.shape[1]) if not np.array_equal(Phi_d[:, j], Phi[:, j])]
            extra = Phi_d[rows][:, moved] if moved else None
        try:
            test = second_lag(y[rows], Phi[rows], tuple(reg.names), Di[rows], p.h, p.block, a, r, extra)
        except (np.linalg.LinAlgError, ValueError):  # a test that cannot run refuses nothing, never a traceback
            continue
        R1 = float(fit.theta[reg.names.index(r)])
        # with the other currents' lag terms the augmented fit's R is the one consistent with the lag (the DC
        # drive's first-order R is, too: its lag moves into L only)
        why = lag_reason(test, R1 if extra is None or test is None else test["R"], a, state)
        if why:
            fired = state
            refused[a] = why
            lumped.add(a)
            if lagfree is not None:  # the first-order fit's others against the fit with d2i/dt2 (_lag_check)
                for j, n in enumerate(reg.names):
                    if n != a:
                        lagfree[n] = (float(test["theta"][j] - fit.theta[j]), reg.normaliser, float("nan"), state)
            jr = reg.names.index(r)
            sr = float(np.sqrt(max(fit.cov[jr, jr], 0.0)))
            if extra is not None and abs(test["R"] - R1) > 1.96 * sr and r not in refused:
                refused[r] = (f"the first-order fit's {r} = {R1:.4g} (+-{1.96 * sr:.2g}) is biased by the measurement "
                              f"lag of the other currents ({', '.join(others)}): {test['R']:.4g} with the lag's terms")
    return fired


def _fit_ls(data: MotionData, options: EstimationOptions, lagfree: dict | None = None):
    """LS with the refusals and the re-fits; returns (Prepared, MethodResult or None, fixed, refused, lumped).
    ``lagfree`` (a dict) receives the lag-free values of ``_lag_bias``."""
    fixed: dict[str, float] = {}
    refused: dict[str, str] = {}
    lumped: set[str] = set()
    lagging: set[str] = set()  # currents whose measurement lags (_lag_rule), kept across the re-fits
    for _ in range(8):  # each round fixes at least one more parameter (at most 4 can be)
        opts = replace(options, known={**options.known, **fixed})
        if lagfree is not None:
            lagfree.clear()  # this round's fits only
        p = prepare(data, opts, strict=False)
        for n, why in p.refused.items():
            refused.setdefault(n, why)
        if _apriori(p, opts, fixed, refused, lumped):
            continue
        fits, again = {}, False
        for reg in p.regressions:
            parts = ls_parts(p, reg)  # with its partner equation's samples (the PMSM's d axis)
            y, Phi = parts[0][:2]
            try:
                fit = _solve(reg, parts, p.block, opts,
                             _column_reference(reg, _signals_for(p, reg), p.h), p.notes.get(reg.equation, ""))
            except NotEnoughExcitation as exc:
                again |= _weak(exc, reg, fixed, refused, lumped)
                continue
            except (np.linalg.LinAlgError, FloatingPointError) as exc:  # e.g. eigh not converging on extreme values
                refused.update({n: f"the {reg.equation} fit failed numerically ({exc})" for n in reg.names})
                continue
            if not np.all(np.isfinite(fit.theta)) or not np.all(np.isfinite(fit.cov)):
                refused.update({n: f"non-finite {reg.equation} fit" for n in reg.names})
                continue
            if fit.dof + len(reg.names) < len(reg.names):  # fewer blocks than parameters: a singular covariance
                nb = fit.dof + len(reg.names)
                why = (f"the motion holds {nb} block(s) of {p.block * p.h:.3g} s for the uncertainty of the "
                       f"{reg.equation} equation; its {len(reg.names)} parameters need at least {len(reg.names)}")
                refused.update({n: why for n in reg.names})
                continue
            if tau_rule(fit, reg, data.h, fixed, refused, opts.model):  # the record's period, decimated or not
                again = True
                continue
            lagging.add(_lag_rule(p, reg, y, Phi, fit, refused, lumped, opts.model, lagfree) or "")
            fits[reg.equation] = fit
            update_constants(p, reg, fit.theta)
        if again:
            continue
        if lagfree is not None:
            _lag_bias(p, fits, lagging - {""}, opts.model, lagfree)
        # an equation scaled by a parameter that is refused cannot give its parameters
        usable = [r for r in p.regressions if r.equation in fits]
        names = {n for r in usable for n in r.names}
        for r in list(usable):
            if r.normaliser and (r.normaliser not in names or r.normaliser in refused):
                why = (f"{r.equation} equation is scaled by {r.normaliser}, which is refused ("
                       + refused.get(r.normaliser, f"no voltage signal: map the voltage or state {r.normaliser} "
                                                   f"(--known {r.normaliser}=VALUE, monitor.known)") + ")")
                for n in r.names:
                    refused.setdefault(n, why)
                usable.remove(r)
                fits.pop(r.equation)
        if not usable:
            return p, None, fixed, refused, lumped
        p = replace(p, regressions=usable)
        return p, _combine("ls", p, fits, sensitivities=constant_sensitivities(usable, [p], fits)), fixed, refused, lumped
    raise EstimatorInputError("the re-fits without the refused parameters did not settle")  # pragma: no cover


def _rule(result: MethodResult, options: EstimationOptions, refused: dict, fixed: dict) -> MethodResult:
    """The relative standard error rule, for every parameter of ``result``; refusals added to ``refused``.

    A parameter refused by it is fixed at its own estimate (stated in ``fixed``) for the others: their
    covariance becomes the one given that value (the Schur complement, what a re-fit with it known gives
    for least squares), so its uncertainty and collinearity do not spoil them. Repeated until no more is
    refused. Not given a physically impossible estimate (R < 0), marginalised over instead: the others' intervals
    hold whatever its value. A friction parameter (ft, Cd) whose variance that conditioning on the other, refused, cuts by more
    than ``MAX_INFLATION`` is refused too, with that ratio and the correlation.
    Returns ``result`` with that covariance.
    """
    names, values = list(result.names), np.asarray(result.values, dtype=float)
    cov = np.array(result.covariance, dtype=float)
    dof = np.full(len(names), float(result.dof)) if result.parameter_dof is None else np.asarray(result.parameter_dof)
    # judged on the printed interval: its half-width against that of a standard error of max_relative_std
    # with many degrees of freedom (a t quantile with few dof widens both alike)
    widen = t_ppf(0.975, np.maximum(dof, 1.0)) / norm_ppf(0.975)
    out: list[int] = []
    bad: list[int] = []  # refused at a physically impossible estimate: marginalised over, never conditioned on
    full = cov  # given every refused one, impossible or not: named when that is all that passed the rule
    while True:
        with np.errstate(divide="ignore", invalid="ignore"):
            rel, rel_full = (np.where(values != 0, np.sqrt(np.clip(np.diag(c), 0, None)) * widen / np.abs(values),
                                      np.inf) for c in (cov, full))
        over = [j for j, n in enumerate(names) if j not in out and n not in refused
                and not rel[j] <= options.max_relative_std]
        if not over:
            break
        new = [max(over, key=lambda j: rel[j])]  # the worst first: fixing it may bring the others within the rule
        for j in new:
            why = impossible(names[j], values[j], values[j] + rel[j] * norm_ppf(0.975) * abs(values[j]))
            at = ", ".join(f"{names[k]} = {values[k]:.4g}" for k in bad)
            given = (f"; +-{rel_full[j] * norm_ppf(0.975):.0%} given the physically impossible {at}" if bad and
                     rel_full[j] <= options.max_relative_std else
                     f"; {why}: physically impossible, {NOT_ASSUMED}" if why else "")
            refused[names[j]] = (f"95 % interval +-{rel[j] * norm_ppf(0.975):.0%} of the value, more than "
                                 f"+-{options.max_relative_std * norm_ppf(0.975):.0%} (a relative standard error "
                                 f"above {options.max_relative_std:.0%}; {result.method_used.upper()}: {values[j]:.4g}"
                                 f"{given})")
            fixed[names[j]] = float(values[j])
            bad += [j] if why else []
        out += new
        keep = [j for j in range(len(names)) if j not in out]
        # the others' covariance given the refused ones' estimates (the Schur complement), except an impossible one:
        # UMich's K was given as 718 [481, 954] N/A given R = -0.618 Ohm, an interval that held only if R were that
        cov, full = conditional_covariance(cov, keep, [j for j in out if j not in bad]), conditional_covariance(
            full, keep, out)
        # viscous and dry friction are told apart only by the motion's speed range (``speed range``): when one is
        # refused, the other's interval given the refused one's estimate holds only if that estimate were the
        # truth (at an NC's 2 ms, 40 dB: ft refused at +-132 %, Cd then +26 % with an interval of +-12 %
        # excluding the truth; ft and Cd -0.98 correlated). Refused too when that conditioning cuts its variance
        # by more than MAX_INFLATION. (Only this pair: on REGBOT's record the same holds for K given R, refused,
        # and K's conditional interval is kept, as the DC drive's tests state.)
        with np.errstate(divide="ignore", invalid="ignore"):
            vif = np.diag(result.covariance) / np.diag(cov)
        tied = [(j, names.index(FRICTION[n])) for j, n in enumerate(names) if j in keep and n not in refused
                and FRICTION.get(n) in names and names.index(FRICTION[n]) in out and vif[j] > MAX_INFLATION]
        for j, r in tied:
            rho = result.covariance[r, j] / np.sqrt(result.covariance[r, r] * result.covariance[j, j])
            refused[names[j]] = (f"determined only together with {names[r]} (refused; correlation {rho:.3f}): its "
                                 f"variance is {vif[j]:.3g} times its variance given {names[r]} (more than "
                                 f"{MAX_INFLATION:g}), an interval that holds only if {names[r]} were known "
                                 f"({result.method_used.upper()}: {values[j]:.4g})")
            fixed[names[j]] = float(values[j])
        out += [j for j, _ in tied]
        # an interval of no width given the refused ones: the parameter is all theirs (a record at rest gave ft
        # 0.2003 N.m.s/rad with [0.2003, 0.2003] given K = -0.158, R, L, Jt at their refused estimates)
        void = [j for j in keep if names[j] not in refused and j not in out
                and not cov[j, j] * DEGENERATE > result.covariance[j, j]]  # (a rounding may leave it negative)
        for j in void:
            refused[names[j]] = (f"determined only by the refused {', '.join(names[k] for k in out)}: its interval "
                                 f"given them has no width (its variance {cov[j, j]:.3g}, {result.covariance[j, j]:.3g} "
                                 f"without them) ({result.method_used.upper()}: {values[j]:.4g})")
            fixed[names[j]] = float(values[j])
        out += void
    return replace(result, covariance=cov) if out else result


def _subset(result: MethodResult, names: list[str]) -> MethodResult:
    idx = [result.names.index(n) for n in names]
    dof = None if result.parameter_dof is None else np.asarray(result.parameter_dof)[idx]
    return replace(result, names=tuple(names), values=np.asarray(result.values)[idx],
                   covariance=np.asarray(result.covariance)[np.ix_(idx, idx)], parameter_dof=dof)


def estimate_parameters(data: MotionData, options: EstimationOptions = EstimationOptions(),
                        bounds: Bounds | None = None) -> MotionEstimate:
    """Every parameter the motion determines, the others refused with their reason (module docstring).

    Parameters
    ----------
    data : MotionData
    options : EstimationOptions
    bounds : mapping of str to (lower or None, upper or None), optional
        The user's bounds (e.g. ``{"Jt": (4e-6, None)}``: a rotor inertia) on top of the physical ranges.

    Returns
    -------
    MotionEstimate
        ``parameters`` holds the given ones only; ``refused`` the others with the reason; ``fixed`` what
        was fixed in the re-fit; ``flags`` the given ones outside their physical range or bounds (never
        to be validated), and ``bounded`` the bounded least squares estimate offered then.

    Raises
    ------
    NotEnoughExcitation
        Nothing at all can be estimated (every parameter refused; the reasons are joined).
    EstimatorInputError
        Unusable signals or options.
    """
    with np.errstate(all="ignore"):  # non-finite values are tested for: they become refusals, never warnings
        lagfree: dict = {}
        p, ls, fixed, refused, lumped = _fit_ls(data, options, lagfree)
        if ls is None:
            reasons = {}
            for n, why in refused.items():
                reasons.setdefault(why, []).append(n)
            missing = all(" equation is scaled by " in why for why in reasons)  # (K, no voltage): not excitation
            raise NotEnoughExcitation(list(refused), next(iter(reasons)) if len(reasons) == 1 else
                                      "; ".join(f"{', '.join(ns)}: {why}" for why, ns in reasons.items()),
                                      lead="cannot identify" if missing else "not enough excitation to identify")
        final = ls
        iv = oe = None
        if options.method == "ls":  # LS asked for: its noise bias in its intervals at an NC's rate, as when it stands in
            final = systematic(data, ls, ls, options, fixed, _fit_ls)
        if options.method in ("iv", "oe"):
            iv = iv_with_fallbacks(data, ls, replace(options, known={**options.known, **fixed}), fixed,
                                   {r.equation for r in p.regressions})
            # at an NC's rate, IV's aliasing or LS's noise bias in the interval; for oe too, whose fall-back is this
            # IV (without it, oe on Quanser's 2 ms record gave Jt +-6 % where iv refused it at +-415 %)
            iv = final = systematic(data, ls, iv, options, fixed, _fit_ls)
        if options.method == "oe":
            oe = _oe(p, iv, options, fixed)
            final = oe
        unconditional = final
        final = _rule(final, options, refused, fixed)
        _lag_check(final, lagfree, refused, lumped)
        if options.method == "ls":
            ls = final
        elif options.method == "iv":
            iv = final
            rate_rule(data, ls, iv, options, fixed, refused, _fit_ls)
        else:
            oe = final
            rate_rule(data, ls, oe, options, fixed, refused, _fit_ls)  # only where OE fell back to IV (ran iv)
        given = [n for n in final.names if n not in refused and n not in lumped]
        subsets = {m: None if r is None else _subset(r, [n for n in given if n in r.names])
                   for m, r in (("ls", ls), ("iv", iv), ("oe", oe))}
        shown = subsets[options.method]
        flags = physical_flags(shown, bounds or {})
        hint = sign_hint(data, options, physical_flags(shown, {}), _fit_ls)
        # a bounded fit of sign-reversed data sits on its bounds (Jt 5e-18): offered only when no sign explains it
        bounded = bounded_fit(p, {**options.known, **fixed}, bounds or {}, given) if flags and not hint else {}
    start, end = float(data.t0), float(data.t0 + (data.n - 1) * data.h)
    order = [v.name for v in options.physical]
    refused = {n: refused[n] for n in sorted(refused, key=order.index) if n not in options.known}
    return MotionEstimate(options.method, start, end, subsets["ls"], subsets["iv"], subsets["oe"], refused=refused,
                          flags=flags, bounded=bounded, hint=hint, fixed={n: v for n, v in fixed.items() if n in refused},
                          lumped={n: float(final.values[final.names.index(n)]) for n in lumped if n in final.names},
                          joint=_subset(unconditional, list(shown.names)),
                          derived=derived_estimates(shown, options.model), rate_hz=1.0 / p.h)


def _oe(p, iv: MethodResult, options: EstimationOptions, fixed: Mapping[str, float]) -> MethodResult:
    from feeddrive.estimator.oe import _fallback, output_error

    if fixed:
        return _fallback(iv, "parameters fixed in the re-fit (" + ", ".join(f"{n} = {v:g}" for n, v in fixed.items())
                         + ")" + (f"; {iv.message}" if iv.message else ""))
    return output_error(p, iv, options)
