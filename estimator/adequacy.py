"""Model adequacy from one recording's own residue, without redundant sensors (issue 22 item 5).

The paper's model check (estimator/mismatch.py) needs a second sensor per quantity: its noise level and
its instruments come from the redundancy. Most machines have one current sensor, one voltage (often a
command) or only a torque signal. This check asks the recording alone whether the model's equations
(EQUATIONS.md eq. 4, 5) explain it, by a **lack-of-fit test against a richer nuisance model**:

* each equation's regression (filtered signals, zero-forcing derivative, as the estimator) is fitted
  with a constant, and then with nuisance terms that the DC model lacks but real drives have:

  - electrical ``u = L Di + R i + K w + c``: the squared fitted voltage (an amplifier's nonlinearity, the
    logged voltage being a command, RESET) and ``i |w|`` (a current that drifts with speed);
  - mechanical ``y = a Dw + b w + d sign(w) + c`` (``y`` the torque [N.m] or the current [A]): Legendre
    polynomials of degree 1-3 of the position over its range (a gravity torque ``m g l cos(theta)`` or
    any position-dependent load; the position is the integral of the speed when not measured, so the
    gear ratio need not be known), ``yhat |w|`` (a torque signal or current that drifts with speed at
    constant torque) and ``yhat^2``;
* the nuisance columns are orthogonalised against the model's regressors (only what the model cannot
  represent is tested; a direction with less than ``MIN_DIRECTION`` of its norm outside the model's span
  is not tested) and their coefficients get a Wald test whose covariance is a batch-means long-run
  variance over ``blocks`` consecutive blocks (the filtered equation errors are coloured), referred to
  Hotelling's small-sample F distribution ``F(q, k - q)``;
* the equations' p-values are combined by Bonferroni (``p = min(1, m min p)``).

Verdict, in this precedence:

* ``model mismatch``: ``p < alpha``; the nuisance term with the largest share is named;
* ``not enough excitation``: no mismatch found, but a model coefficient is not determined (relative
  standard error above ``max_relative_std``, as the estimator's rule), no nuisance direction can be
  told from the model's, or the record is too short for the blocks: the check has no power, so the
  absence of a mismatch says nothing;
* ``adequate``: no mismatch found with every coefficient determined.

A lack of excitation never reads as a mismatch: the test's level holds whatever the excitation (the
nuisance directions are tested only where they differ from the model's), and a mismatch always wins
because it is what makes a coefficient look undetermined (gravity on a robot axis hides Jt).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.polynomial import legendre

from feeddrive.estimator.columnwise import divide_columns
from feeddrive.estimator.derivative import FUTURE, PAST, matched_average, zero_forcing_derivative
from feeddrive.estimator.distributions import f_sf
from feeddrive.estimator.errors import EstimatorInputError
from feeddrive.estimator.filtering import FilterSpec, check_rate_factor
from feeddrive.estimator.kernels import block_iv, columns, erode, nonzero_norms, right_singular, thin_q
from feeddrive.estimator.pvalue_text import p_text

#: nuisance directions with less than this fraction of their norm outside the model's span are not tested
MIN_DIRECTION = 1e-3
#: fewest blocks more than the number of nuisance terms tested (the F test's denominator dof)
MIN_DOF = 8
#: nuisance terms are read this many filter periods (1 / cutoff) away from the residue's sample
LAG_PERIODS = 3.0
#: smallest RMS of the nuisance part, relative to the RMS of the output, that counts as a mismatch: a
#: significant but immaterial lack of fit (a weakly excited record, a tiny deterministic error) is not one
MIN_EFFECT = 0.01
#: partial correlation of a regressor with its lagged instrument below which the regressor is its own
WEAK_INSTRUMENT = 0.5
#: parameters whose regressor is a derivative (noisy)
DERIVATIVE_TERMS = ("L", "Jt")
#: level of the check when the caller gives none (``check_motion``: ``cosim estimate``)
ALPHA = 0.01
#: marks a model term whose parameter another equation estimates (the PMSM's reluctance torque in the mechanical
#: equation, the whole d-axis equation): fitted, but not required to be determined by this one
SHARED = " (shared)"
#: verdicts, in precedence (``not checked``: ``check_motion`` on signals that allow no test)
VERDICTS = ("model mismatch", "not enough excitation", "adequate", "not checked")


@dataclass(frozen=True)
class EquationCheck:
    """The lack-of-fit test of one equation.

    Attributes
    ----------
    equation : {"electrical", "mechanical"}
    output : str
        The regression's output signal (``u``, ``torque`` or ``i``).
    p_value, statistic : float or None
        Unadjusted p-value and F statistic; None when nothing could be tested (``reason`` says why).
    df : tuple of int or None
        ``(q, k - q)``: nuisance directions tested and the F test's denominator dof.
    terms : tuple of str
        The nuisance terms tested.
    strongest : str or None
        The nuisance term with the largest standardised coefficient.
    effect : float or None
        RMS of the nuisance part of the fit relative to the RMS of the output (a mismatch needs
        ``MIN_EFFECT``).
    undetermined : tuple of str
        Model coefficients whose relative standard error exceeds ``max_relative_std``.
    reason : str
        Empty, or why the check has no power.
    """

    equation: str
    output: str
    p_value: float | None
    statistic: float | None
    df: tuple[int, int] | None
    terms: tuple[str, ...]
    strongest: str | None
    undetermined: tuple[str, ...]
    effect: float | None = None
    reason: str = ""

    def to_dict(self) -> dict:
        return {"output": self.output, "p_value": self.p_value, "statistic": self.statistic,
                "df": None if self.df is None else list(self.df), "terms": list(self.terms),
                "strongest": self.strongest, "effect": self.effect, "undetermined": list(self.undetermined), "reason": self.reason or None}


@dataclass(frozen=True)
class AdequacyResult:
    """Verdict of ``check_adequacy``: one of ``VERDICTS``, the Bonferroni-adjusted p-value (None when no
    test ran), the level and each equation's test."""

    verdict: str
    p_value: float | None
    alpha: float
    reason: str
    equations: dict[str, EquationCheck] = field(default_factory=dict)

    @property
    def mismatch(self) -> bool:
        return self.verdict == "model mismatch"

    def to_dict(self) -> dict:
        """``{verdict, p_value, alpha, reason, equations: {name: {...}}}`` (report.json, ``--json``)."""
        return {"verdict": self.verdict, "p_value": self.p_value, "alpha": self.alpha, "reason": self.reason,
                "equations": {k: e.to_dict() for k, e in self.equations.items()}}

    def line(self) -> str:
        """One console line: the verdict, its p-value against alpha, and the reason."""
        p = "" if self.p_value is None else f" ({p_text(self.p_value)} {'<' if self.p_value < self.alpha else '>='} " \
                                            f"alpha = {self.alpha:g})"
        verdict = "MODEL MISMATCH" if self.mismatch else self.verdict
        return f"model check (own residue): {verdict}{p}: {self.reason}"


def _rows(w: np.ndarray, h: float, cutoff_hz: float, speed_fraction: float, lag: int) -> np.ndarray:
    """Samples used: ``|w|`` above ``speed_fraction`` of its peak, away from the zero crossings (the
    filter smears sign(w) over about 1/cutoff) and from the filter's ends (and ``lag`` samples)."""
    speed = np.abs(w)
    fast = (speed >= speed_fraction * float(speed.max(initial=0.0))) & (speed > 0)
    guard = int(np.ceil(2.0 / (cutoff_hz * h)))
    keep = erode(fast, guard, border=True)
    edge = max(int(np.ceil(3.0 / (cutoff_hz * h))), lag)
    keep[:edge] = False
    keep[max(0, keep.size - edge):] = False
    return keep


def _lack_of_fit(y: np.ndarray, X: np.ndarray, Z: np.ndarray, names: list[str], N: np.ndarray, terms: list[str],
                 blocks: int, max_relative_std: float, y_scale: np.ndarray) -> tuple[float | None, float | None, tuple | None, tuple,
                                                               str | None, tuple, str]:
    """Wald test of the nuisance columns ``N`` added to ``y ~ X`` (instruments ``Z`` for ``X``); see the
    module docstring. Returns ``(p, F, df, undetermined, strongest, terms tested, reason)``."""
    n = y.size
    k = min(blocks, n // 8)
    Xs, Zs = divide_columns(X, nonzero_norms(X)), divide_columns(Z, nonzero_norms(Z))

    def iv(W: np.ndarray, V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return block_iv(y, [W], [V], k)

    # the model's coefficients and their standard errors (excitation)
    undetermined = [nm for nm in names if nm not in ("constant", "T0") and not nm.endswith(SHARED)]
    if X.shape[1] == 0:
        undetermined = []
    elif k >= X.shape[1] + 2:
        beta, cov = iv(Xs, Zs)
        se = np.sqrt(np.clip(np.diag(cov) * k / (k - X.shape[1]), 0.0, None))
        undetermined = [nm for nm, b, s in zip(names, beta, se)
                        if nm not in ("constant", "T0") and not nm.endswith(SHARED) and not abs(b) * max_relative_std > s]
    Zs = Zs.copy()
    for j in [j for j, nm in enumerate(names) if nm in undetermined]:
        # an undetermined term with a weak instrument (a derivative at constant speed, mostly noise) made
        # the IV fit and the test erratic (p < 0.01 on a third of the plateaus of a healthy motion): such
        # a regressor is its own instrument; its noise then biases little, for its term is itself small
        others = np.delete(Zs, j, axis=1)
        proj = others @ np.linalg.lstsq(others, np.column_stack([Xs[:, j], Zs[:, j]]), rcond=None)[0] \
            if others.shape[1] else 0.0
        x, z = (np.column_stack([Xs[:, j], Zs[:, j]]) - proj).T
        if not abs(float(x @ z)) >= WEAK_INSTRUMENT * float(np.sqrt((x @ x) * (z @ z))):
            Zs[:, j] = Xs[:, j]
    # nuisance: what the model's regressors cannot represent, orthonormal; orthogonal to the instruments,
    # not to the regressors, whose noise (the derivative's) would pass into the directions and bias them
    Nn = divide_columns(N, nonzero_norms(N))
    Q = thin_q(Zs) if Zs.shape[1] else np.zeros((n, 0))
    R_ = Nn - Q @ (Q.T @ Nn)
    s, Vt = right_singular(R_)  # the left singular vectors (n x q) are not needed
    keep = s > MIN_DIRECTION
    q = int(keep.sum())
    if q == 0:
        return None, None, None, tuple(undetermined), None, (), "no nuisance term differs from the model's regressors"
    if k - q < MIN_DOF:
        return (None, None, None, tuple(undetermined), None, (),
                f"{n} samples give {k} blocks; the test of {q} nuisance directions needs {q + MIN_DOF}")
    # the testable combinations of the nuisance terms themselves (not their parts orthogonal to the
    # instruments: the full model must span the model's and the nuisance's regressors, or a lack of fit
    # along a nuisance term leaves a structured residue that inflates its own variance)
    D = Vt[keep].T / s[keep]
    B = Nn @ D
    beta, cov = block_iv(y, [Xs, B], [Zs, B], k)  # [Xs B] with instruments [Zs B], never stacked (n x 10 twice)
    c, S = beta[-q:], cov[-q:, -q:]
    try:
        t2 = float(c @ np.linalg.solve(S, c))
    except np.linalg.LinAlgError:
        return None, None, None, tuple(undetermined), None, (), "the residue's block covariance is singular"
    F = (k - q) / (q * k) * t2
    p = float(f_sf(F, q, k - q))
    # the term that carries the lack of fit: each term's share of the tested directions, weighted by their z
    z = np.abs(c) / np.sqrt(np.clip(np.diag(S), np.finfo(float).tiny, None))
    strongest = terms[int(np.argmax(np.abs(Vt[keep].T) @ z))]
    # what the model cannot represent: the nuisance part of the fit outside the instruments' span
    effect = float(np.sqrt(np.mean((R_ @ D @ c) ** 2) / np.mean(y_scale ** 2)))
    return p, F, (q, k - q), tuple(undetermined), strongest, tuple(terms), effect


def _legendre(x: np.ndarray, degrees: range) -> np.ndarray:
    """Legendre polynomials of ``x`` (the rows tested) scaled to [-1, 1] over its range, shape (n, len(degrees))."""
    lo, hi = float(x.min()), float(x.max())
    t = 2 * (x - lo) / (hi - lo) - 1 if hi > lo else np.zeros_like(x)
    return np.column_stack([legendre.legval(t, np.eye(d + 1)[d]) for d in degrees])


def check_adequacy(h: float, u: np.ndarray | None = None, i: np.ndarray | None = None,
                   w: np.ndarray | None = None, torque: np.ndarray | None = None,
                   position: np.ndarray | None = None, alpha: float = 0.01, filter: FilterSpec | None = None,
                   speed_fraction: float = 0.03, blocks: int = 30, max_relative_std: float = 0.3,
                   known: Mapping[str, float] | None = None, offset: bool = False,
                   signals: Mapping[str, np.ndarray] | None = None, model_terms=None,  # noqa: ANN001
                   states: tuple[str, ...] = ("i", "w"), decimation: int | str = "auto") -> AdequacyResult:
    """Is the DC model adequate for this recording? (lack-of-fit test, see the module docstring)

    Parameters
    ----------
    h : float
        Sampling period [s].
    u, i, w, torque, position : ndarray, shape (n,), or None
        Voltage [V], current [A], speed [rad/s], torque [N.m], position [rad] of one motion (any unit
        works: the test is scale-free). The electrical equation is tested with ``u``, ``i`` and ``w``; the
        mechanical one with ``w`` and ``torque`` (else ``i``). ``w`` or ``position`` is required.
    alpha : float
        Level of the check (its false-alarm rate on a record the model explains).
    filter : FilterSpec, optional
        The identical low-pass (eq. 8); default cut-off ``min(100 Hz, 0.1 / h)``.
    speed_fraction : float
        Samples with ``|w|`` below this fraction of its peak are left out (sign(w)).
    blocks : int
        Blocks of the batch-means covariance.
    max_relative_std : float
        A model coefficient with a larger relative standard error is not determined.
    known : mapping of str to float, optional
        Parameters known in advance (``R``, ``L``, ``K``, ``Jt``, ``ft``, ``Cd``, SI): their terms are fixed,
        not fitted, so a wrong one (or a logged command instead of the terminal voltage) is a mismatch.
        ``Jt, ft, Cd`` with a current output need ``K``.
    offset : bool
        The mechanical equation has a constant torque offset ``T0`` (the estimator's ``offset``); else a
        constant is a nuisance term (an offset the model lacks).
    signals, model_terms, states
        Another drive model (:func:`check_model_motion`): its measured signals by name, the states to
        differentiate, and ``model_terms(s) -> [(equation, output, y, {parameter: regressor}, friction)]`` in
        place of the DC equations; each is tested against ``output^2`` and ``output x |speed|`` (and the
        position polynomials when ``friction``: the equation holding sign(w)).
    decimation : int or "auto"
        Every how many filtered samples are tested (``EstimationOptions.decimation``; "auto": the checks' rule
        ``filtering.check_rate_factor``, D = 5 at 10 kHz with a 100 Hz filter, where the estimator's is 3); the
        blocks, guards and lags stay the same in seconds.

    Returns
    -------
    AdequacyResult
    """
    if not (np.isfinite(h) and h > 0):
        raise EstimatorInputError(f"check_adequacy: h must be a positive sampling period [s], got {h}")
    if not 0 < alpha < 0.5:
        raise EstimatorInputError(f"check_adequacy: alpha must be in (0, 0.5), got {alpha}")
    raw = {k: v for k, v in (("u", u), ("i", i), ("w", w), ("torque", torque), ("position", position))
           if v is not None} | dict(signals or {})
    if "w" not in raw and "position" in raw:  # an encoder alone: its differentiated angle
        raw["w"] = np.gradient(np.asarray(raw["position"], dtype=float), h)
    if "w" not in raw:
        raise EstimatorInputError("check_adequacy: the speed w is required")
    n = None
    for name, x in raw.items():
        x = np.asarray(x, dtype=float)
        if x.ndim != 1 or (n is not None and x.size != n) or not np.all(np.isfinite(x)):
            raise EstimatorInputError(f"check_adequacy: {name} must be a finite 1-D array like the others")
        raw[name], n = x, x.size
    filter = filter or FilterSpec(min(100.0, 0.1 / h))
    if n < 8 * PAST + 8 * FUTURE + 64:
        return AdequacyResult("not enough excitation", None, alpha, f"{n} samples: too short to check the model")
    try:
        f = filter.apply(raw, h)
    except EstimatorInputError as exc:
        return AdequacyResult("not enough excitation", None, alpha, f"too short to filter ({exc})")
    if "position" not in f:  # the integral of the speed: a position-dependent load needs no gear ratio
        f["position"] = np.concatenate([[0.0], np.cumsum(0.5 * (f["w"][1:] + f["w"][:-1])) * h])
    # the filtered signals carry the model on every D-th sample (the checks' rule: no split halves)
    step = check_rate_factor(filter.cutoff_hz, h, n, decimation)
    if step > 1:
        f = {k: np.ascontiguousarray(v[::step]) for k, v in f.items()}
        h, n = h * step, f["w"].size
    sl = slice(PAST, n - FUTURE)
    d = {"D" + k: zero_forcing_derivative(f[k], h)[0] for k in states if k in f}
    s = {k: matched_average(v)[sl] for k, v in f.items()} | d
    # nuisance terms are read LAG samples away (the position only before): the filtered noise of a
    # signal is correlated over about 1 / cutoff, and a nuisance term carrying the noise of the residue
    # (the integrated speed noise against its derivative, the current noise against R i) is biased
    lag = int(np.ceil(LAG_PERIODS / (filter.cutoff_hz * h)))
    rows = _rows(s["w"], h, filter.cutoff_hz, speed_fraction, lag)
    if np.count_nonzero(rows) < 64:
        return AdequacyResult("not enough excitation", None, alpha,
                              f"{np.count_nonzero(rows)} samples with |speed| above {speed_fraction:g} of its peak")
    sgn, aw = np.sign(s["w"]), np.abs(s["w"])

    # everything tested is read on the rows only: a term read LAG samples away is taken there (the rows keep
    # LAG samples from both ends, so the indices stay inside; the values of np.roll(x, +-LAG)[rows], bit for bit)
    take = np.flatnonzero(rows)  # take() of the row indices: the same rows as [rows], in half the time

    def fitted(X: np.ndarray, Xr: np.ndarray, Zr: np.ndarray, y: np.ndarray) -> np.ndarray:
        return X @ np.linalg.lstsq(Zr.T @ Xr, Zr.T @ y.take(take), rcond=None)[0]

    earlier, later = take - lag, take + lag  # the indices LAG samples either side, formed once

    def before(x: np.ndarray) -> np.ndarray:
        return x.take(earlier)  # x LAG samples earlier, on the rows

    def around(x: np.ndarray) -> np.ndarray:
        return 0.5 * (before(x) + x.take(later))

    def instruments(X: np.ndarray) -> np.ndarray:  # noqa: N803
        # the regressors read LAG samples either side: their noise (the derivative's above all) is not
        # the residue's, so the fit is not attenuated (errors in variables), whose smooth error the
        # nuisance terms would otherwise take for a mismatch
        return np.column_stack([around(x) for x in X.T])

    known = dict(known or {})
    checks, ignored = {}, []

    def equation(name: str, output: str, y: np.ndarray, terms: dict[str, np.ndarray], nuisance: list,
                 labels: list[str]) -> None:
        """Register one equation: known terms moved to the output side, the offset a nuisance term."""
        fixed = {}
        for p in [p for p in terms if p in known]:
            fixed[p] = terms.pop(p)
            y = y - known[p] * fixed[p]
        X = np.column_stack(list(terms.values())) if terms else np.zeros((y.size, 0))
        # once: the fit and the test use the same instruments. X's rows gathered a column at a time (take() of a
        # 2-D array copies each row of a few values alone): the same C-ordered rows
        Xr = columns([x.take(take) for x in terms.values()]) if terms else X.take(take, axis=0)
        Zr = instruments(X)
        yhat = fitted(X, Xr, Zr, y) if terms else np.zeros_like(y)
        # a known parameter's own term is a nuisance too: a wrong value, or a logged command taken for the
        # voltage, leaves a lack of fit along it. A derivative is read LAG away (its noise is the residue's);
        # the others as they are (read away, their curvature between t - LAG and t + LAG was itself a
        # lack of fit that hid a K 10 % off)
        constant = [] if "T0" in terms else [np.ones(take.size)]  # the offset: a nuisance unless modelled
        N = np.column_stack(constant + [around(x) if p in DERIVATIVE_TERMS else x.take(take) for p, x in fixed.items()]
                            + [f(yhat) for f in nuisance])
        checks[name] = (output, y.take(take), Xr, Zr, list(terms), N,
                        ["offset (constant)"] * len(constant) + [f"known {p} off" for p in fixed] + labels)

    scale = {"electrical": s.get("u"), "mechanical": s.get("torque", s.get("i"))}
    for name, output, y, terms, friction in (model_terms(s | {"sgn_w": sgn}) if model_terms else []):
        position = before(s["position"])
        legendre_terms = [lambda yhat, d=d: _legendre(position, range(d, d + 1))[:, 0] for d in (1, 2, 3)]
        equation(name, output, y, terms, (legendre_terms if friction else [])
                 + [lambda yhat: around(yhat * aw), lambda yhat: around(yhat ** 2)],
                 [f"position-dependent torque (gravity) P{d}" for d in (1, 2, 3) if friction]
                 + [f"{output} x |speed|", "output^2"])
        scale[name] = y
    if "u" in s and "i" in s and not model_terms:
        equation("electrical", "u", s["u"], {"L": s["Di"], "R": s["i"], "K": s["w"]},
                 [lambda yhat: around(yhat ** 2), lambda yhat: around(s["i"] * aw)],
                 ["amplifier nonlinearity (u^2)", "current x |speed|"])
    out = "torque" if "torque" in s else "i" if "i" in s else None
    if out is not None and not model_terms:
        y = s[out]
        if out == "i":  # i = (Jt Dw + ft w + Cd sign w) / K: the mechanical parameters need K
            if "K" in known:
                y, out = known["K"] * y, "K i"
            else:
                ignored += [p for p in ("Jt", "ft", "Cd") if p in known]
        position = before(s["position"])
        # one direction only: sign(w) is the constant (Cd and an offset confounded, the offset not tested)
        terms = {"Jt": s["Dw"], "ft": s["w"], "Cd": sgn} | ({"T0": np.ones_like(sgn)} if offset else {})
        equation("mechanical", out, y, terms,
                 [lambda yhat, d=d: _legendre(position, range(d, d + 1))[:, 0] for d in (1, 2, 3)]
                 + [lambda yhat: around(yhat * aw), lambda yhat: around(yhat ** 2)],
                 ["position-dependent torque (gravity) P1", "position-dependent torque (gravity) P2",
                  "position-dependent torque (gravity) P3", f"{'current' if out == 'i' else 'torque'} x |speed|",
                  "output^2"])
    checks = {k: (o, y, X, Z, nm, N, t, scale[k].take(take) * (known.get("K", 1.0) if o == "K i" else 1))
              for k, (o, y, X, Z, nm, N, t) in checks.items()}
    if not checks:
        raise EstimatorInputError("check_adequacy: neither the electrical (u, i, w) nor the mechanical "
                                  "(w and torque or i) equation can be tested")
    results = {}
    for eq, (output, y, X, Z, names, N, terms, y_scale) in checks.items():
        try:
            with np.errstate(all="ignore"):
                p, F, df, undetermined, strongest, tested, last = _lack_of_fit(y, X, Z, names, N, terms, blocks,
                                                                               max_relative_std, y_scale)
            if p is not None and not (np.isfinite(p) and np.isfinite(F) and np.isfinite(last)):
                raise FloatingPointError("a non-finite statistic")
        except (np.linalg.LinAlgError, FloatingPointError, ValueError) as exc:  # degenerate data: no power
            p, F, df, undetermined, strongest, tested = None, None, None, (), None, ()
            last = f"the test failed numerically on this record ({exc})"
        effect, reason = (last, "") if p is not None else (None, last)
        results[eq] = EquationCheck(eq, output, p, F, df, tested, strongest, undetermined, effect, reason)
    result = _verdict(results, alpha)
    if ignored:
        result = replace(result, reason=f"{result.reason}; known {', '.join(ignored)} not used (no K)")
    return result


def _verdict(results: dict[str, EquationCheck], alpha: float) -> AdequacyResult:
    """The verdict from each equation's test (precedence: mismatch, not enough excitation, adequate)."""
    tested = {k: e for k, e in results.items() if e.p_value is not None}
    m = len(tested)
    p = min(1.0, m * min(e.p_value for e in tested.values())) if tested else None
    material = [e for e in tested.values() if m * e.p_value < alpha and e.effect >= MIN_EFFECT]
    if material:
        worst = min(material, key=lambda e: e.p_value)
        return AdequacyResult("model mismatch", p, alpha, f"the {worst.equation} equation lacks a term the "
                              f"recording needs ({100 * worst.effect:.2g} % of the {worst.output} signal; largest "
                              f"share: {worst.strongest})", results)
    small = [e for e in tested.values() if m * e.p_value < alpha]
    note = "; ".join(f"{e.equation}: a significant lack of fit of only {100 * e.effect:.2g} % of the {e.output} "
                     f"signal (immaterial below {100 * MIN_EFFECT:g} %)" for e in small)
    weak = [f"{e.equation}: {e.reason}" if e.reason else f"{e.equation}: {', '.join(e.undetermined)} not determined"
            for e in results.values() if e.reason or e.undetermined]
    if weak:
        return AdequacyResult("not enough excitation", p, alpha, "no mismatch found, but the check has little "
                              "power (" + "; ".join(weak + ([note] if note else [])) + ")", results)
    return AdequacyResult("adequate", p, alpha, "no mismatch found (" + ", ".join(
        f"{e.equation} {p_text(e.p_value)}" for e in tested.values()) + "; Bonferroni over the equations"
        + (f"; {note}" if note else "") + ")", results)


def check_motion(data, options) -> AdequacyResult:  # noqa: ANN001 - estimator.MotionData, EstimationOptions
    """``check_adequacy`` on one motion as the estimator sees it (``MotionData`` and ``EstimationOptions``:
    its signals, filter, speed fraction and known parameters), at level ``ALPHA``. Signals that allow no
    test give the verdict ``not checked`` with the reason (never an exception: the estimate stands)."""
    from feeddrive.estimator.simulation import MODEL

    if options.model is not MODEL:
        return check_model_motion(data, options)
    if data.w is None and data.position is None or data.torque is None and data.i is None:
        return AdequacyResult("not checked", None, ALPHA, "needs a speed (or position) and a current or torque")
    return check_adequacy(data.h, u=data.u, i=data.i, w=data.w, torque=data.torque, position=data.position,
                          alpha=ALPHA, filter=options.filter, speed_fraction=options.speed_fraction,
                          known=options.known, offset=options.offset, decimation=options.decimation)


def check_model_motion(data, options) -> AdequacyResult:  # noqa: ANN001 - estimator.MotionData, EstimationOptions
    """``check_motion`` for a model other than the DC drive (``options.model``, e.g. the PMSM): each equation's
    regression derived from the model with all its parameters free (collinear columns, the PMSM's reluctance
    term through L_d and L_q, kept once), tested for a lack of fit as the DC equations are."""
    from feeddrive.estimator.kernels import equation_parameters_of
    from feeddrive.estimator.model_terms import owners
    from feeddrive.estimator.regression import derive_regression
    from feeddrive.models.drives import differentiated

    model = options.model
    owner = owners(model)
    regressions, ignored = [], []
    for eq in model.equations.values():
        free = [n for n in equation_parameters_of(model, eq.name)
                if n not in options.known and (options.offset or not model.variables[n].optional)]
        try:
            reg = derive_regression(model, eq.name, free, dict(options.known))
        except EstimatorInputError:  # known terms of an equation scaled by a free psi_f: as the DC check's "no K"
            mine = [n for n in equation_parameters_of(model, eq.name) if n in options.known]
            ignored += [f"{n} (the {eq.name} equation is scaled by {eq.normaliser}, not known)" for n in mine]
            reg = derive_regression(model, eq.name, free + mine,
                                    {n: v for n, v in options.known.items() if n not in mine})
        regressions.append((reg, eq.output))

    def terms(s: dict) -> list:
        found = []
        for reg, out in regressions:
            if not reg.names or any(s.get(x) is None for x in reg.signals):
                continue
            y, Phi = reg.evaluate(s)
            keep: list[int] = []
            for j in range(Phi.shape[1]):  # a column in the span of the kept ones adds nothing to the model
                A = Phi[:, keep + [j]]
                if np.linalg.matrix_rank(A / np.linalg.norm(A, axis=0).clip(1e-300), tol=1e-9) == len(keep) + 1:
                    keep.append(j)
            names = [n if owner.get(n) == reg.equation else n + SHARED for n in reg.names]
            found.append((reg.equation, out, y, {names[j]: Phi[:, j] for j in keep}, "sgn_w" in reg.signals))
        return found

    if data.w is None and data.position is None:
        return AdequacyResult("not checked", None, ALPHA, "needs a speed (or position)")
    try:
        result = check_adequacy(data.h, w=data.w, position=data.position, signals=data.signals, alpha=ALPHA,
                                filter=options.filter, speed_fraction=options.speed_fraction, offset=options.offset,
                                model_terms=terms, states=differentiated(model), decimation=options.decimation)
    except EstimatorInputError as exc:
        return AdequacyResult("not checked", None, ALPHA, str(exc))
    return replace(result, reason=f"{result.reason}; known {', '.join(ignored)} not used") if ignored else result
