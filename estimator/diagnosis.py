"""Diagnosis of plant faults from parameter drifts (paper Table I; EQUATIONS.md section 2).

Each VALIDATED parameter set theta_j is compared with

* a healthy baseline (the mean of the first N validated motions that had no diagnosis, or nominal
  values; while fewer than N exist, the mean of those so far, so a worn axis is diagnosed, and kept out
  of the baseline, from the second validated motion on), and
* the last validated set theta_{j-1} (a sudden change),

in standard errors that combine both uncertainties: ``z = (theta_j - theta_ref) / sqrt(s_j^2 + s_ref^2)``.
A parameter has drifted when ``|z| > z_crit`` (two-sided level ``alpha``, default 1e-3: 3.29) AND the
relative change exceeds ``min_relative`` (default 5 %): a significant but tiny change is not a fault.
Drifted parameters are mapped to the faults of Table I whose sensitive parameters and direction of
change explain them; a fault explaining a strict subset of what another explains is dropped (R up and
K down -> motor heating, not also brush wear), and so is a fault with more contradictions (a
precisely measured sensitive parameter that stayed put or moved the wrong way) than another fault
explaining the same drifts (R up with K and L steady -> brush wear, not also motor heating). Drifts
that no fault explains are reported as ``unexplained drift``. Directions (Table I gives none; physics does): wear and lack of oil raise the
friction Cd, ft; a missing work-piece lowers Jt; brush wear and heating raise R; heating and
demagnetisation lower K; L may move either way.

A sensor fault is not a plant fault: parameters estimated from invalid measurements (or from a model
that failed validation) must never be passed here; the monitor enforces it.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from feeddrive.estimator.distributions import norm_isf
from feeddrive.estimator.errors import EstimatorInputError

#: Table I: fault -> {sensitive parameter: direction of change (+1 up, -1 down, 0 either)}
TABLE_I: dict[str, dict[str, int]] = {
    "bearing or slide-way wear": {"Cd": +1, "ft": +1},
    "lack or ageing of lubricating oil": {"Cd": +1, "ft": +1},
    "missing work-piece or work-piece holder": {"Jt": -1},
    "brush wear": {"R": +1},
    "motor heating": {"R": +1, "L": 0, "K": -1},
    "demagnetisation": {"L": 0, "K": -1},
}
#: Table I extended to a PMSM servo axis (issue 25 item 4): the magnet flux psi_f takes K's place (a
#: demagnetised magnet lowers it; a hot magnet too, by about -0.1 %/K for NdFeB, while the copper's R rises by
#: +0.39 %/K); the mechanical faults are the DC drive's
TABLE_I_PMSM: dict[str, dict[str, int]] = {
    "bearing or slide-way wear": {"Cd": +1, "ft": +1},
    "lack or ageing of lubricating oil": {"Cd": +1, "ft": +1},
    "missing work-piece or work-piece holder": {"Jt": -1},
    "winding heating": {"R": +1, "psi_f": -1},
    "demagnetisation": {"psi_f": -1},
}
#: the table of each drive kind (``models.drives.DRIVES``)
TABLES: dict[str, dict[str, dict[str, int]]] = {"dc": TABLE_I, "pmsm": TABLE_I_PMSM, "pmsm-spm": TABLE_I_PMSM}
UNEXPLAINED = "unexplained drift"


@dataclass(frozen=True)
class DiagnosisOptions:
    """Thresholds of the drift test.

    Attributes
    ----------
    alpha : float
        Two-sided level of the drift test in combined standard errors.
    min_relative : float or mapping of str to float
        Smallest relative change that counts (one value for all parameters or per parameter).
    trend_motions : int
        Validated motions (current included) over which the trend is fitted.
    """

    alpha: float = 1e-3
    min_relative: float | Mapping[str, float] = 0.05
    trend_motions: int = 5

    def __post_init__(self) -> None:
        if not 0 < self.alpha < 0.5:
            raise EstimatorInputError(f"DiagnosisOptions.alpha: must be in (0, 0.5), got {self.alpha!r}")
        if self.trend_motions < 2:
            raise EstimatorInputError(f"DiagnosisOptions.trend_motions: must be >= 2, got {self.trend_motions!r}")

    @property
    def z_crit(self) -> float:
        return float(norm_isf(self.alpha / 2))

    def min_rel(self, name: str) -> float:
        m = self.min_relative
        return float(m.get(name, 0.05) if isinstance(m, Mapping) else m)


@dataclass(frozen=True)
class Drift:
    """Evidence for one parameter: value, reference values and the size of the change."""

    parameter: str
    value: float
    baseline: float
    relative_change: float
    z_baseline: float
    z_last: float | None
    trend_per_motion: float | None
    significant: bool
    std: float = float("nan")  # combined standard error of value - baseline

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(frozen=True)
class Diagnosis:
    """One diagnosed fault with the parameters that point at it and their evidence."""

    fault: str
    parameters: tuple[str, ...]
    evidence: tuple[Drift, ...]

    def to_dict(self) -> dict:
        return {"fault": self.fault, "parameters": list(self.parameters),
                "evidence": [d.to_dict() for d in self.evidence]}


def _value_std(p: Any, name: str) -> tuple[float, float]:
    if isinstance(p, Mapping):
        value, std = p.get("value"), p.get("std")
    elif isinstance(p, tuple):
        value, std = p
    else:
        value, std = getattr(p, "value", None), getattr(p, "std", None)
    if value is None or std is None or not (np.isfinite(value) and np.isfinite(std) and std >= 0):
        raise EstimatorInputError(f"parameter {name!r}: expected a finite value and std >= 0, got {p!r}")
    return float(value), float(std)


def make_baseline(sets: Sequence[Mapping[str, Any]]) -> dict[str, tuple[float, float]]:
    """Healthy baseline from the first validated parameter sets.

    Parameters
    ----------
    sets : sequence of mapping name -> {value, std} (or ``(value, std)`` or an object with them)
        A parameter missing from some sets (refused there) is averaged over the sets that hold it.

    Returns
    -------
    dict name -> (value, std)
        Mean value; std of the mean, the larger of the propagated standard errors and the scatter
        between the sets (so a baseline from disagreeing motions is not over-confident).
    """
    if not sets:
        raise EstimatorInputError("make_baseline: no parameter sets given")
    # each parameter from the sets that give it: a motion that refused L (one parameter at a time) still
    # counts for R and K, and does not erase L from the baseline
    names = set.union(*(set(s) for s in sets))
    out = {}
    for name in sorted(names):
        v, s = np.array([_value_std(p[name], name) for p in sets if name in p]).T
        n = v.size
        spread = float(np.std(v, ddof=1) / np.sqrt(n)) if n > 1 else 0.0
        out[name] = (float(v.mean()), max(float(np.sqrt(np.sum(s**2)) / n), spread))
    return out


def drifts(current: Mapping[str, Any], baseline: Mapping[str, Any], last: Mapping[str, Any] | None = None,
           recent: Sequence[Mapping[str, Any]] = (), options: DiagnosisOptions = DiagnosisOptions()) -> list[Drift]:
    """Drift of each parameter of ``current`` present in ``baseline``.

    Parameters
    ----------
    current, baseline, last : mapping name -> {value, std}
        The validated set theta_j, the healthy baseline, theta_{j-1} (or None).
    recent : sequence of mapping name -> {value, std}
        Earlier validated sets, oldest first, for the trend (relative change per motion of a
        straight line through the last ``trend_motions`` values, current included).
    options : DiagnosisOptions

    Returns
    -------
    list of Drift
    """
    out = []
    for name in current:
        if name not in baseline:
            continue
        v, s = _value_std(current[name], name)
        b, sb = _value_std(baseline[name], name)
        std = max(float(np.hypot(s, sb)), np.finfo(float).tiny)
        z = (v - b) / std
        rel = (v - b) / abs(b) if b != 0 else float("inf") * np.sign(v - b)
        z_last = None
        if last is not None and name in last:
            vl, sl = _value_std(last[name], name)
            z_last = float((v - vl) / max(np.hypot(s, sl), np.finfo(float).tiny))
        series = [_value_std(r[name], name)[0] for r in recent if name in r][-(options.trend_motions - 1):] + [v]
        trend = None
        if len(series) >= 3 and b != 0:
            trend = float(np.polyfit(np.arange(len(series)), series, 1)[0] / abs(b))
        significant = abs(z) > options.z_crit and abs(rel) > options.min_rel(name)
        out.append(Drift(name, v, b, float(rel), float(z), z_last, trend, bool(significant), std))
    return out


def _contradicts(d: Drift | None, direction: int, options: DiagnosisOptions) -> bool:
    """The parameter moved significantly against ``direction``, or stayed put although a change of
    ``min_relative`` would have been significant (its resolution is good enough to tell)."""
    if d is None:
        return False
    if d.significant:
        return direction != 0 and np.sign(d.relative_change) != direction
    z_at_min = options.min_rel(d.parameter) * abs(d.baseline) / d.std
    return z_at_min > options.z_crit and abs(d.relative_change) < options.min_rel(d.parameter) / 2


def diagnose(current: Mapping[str, Any], baseline: Mapping[str, Any], last: Mapping[str, Any] | None = None,
             recent: Sequence[Mapping[str, Any]] = (), options: DiagnosisOptions = DiagnosisOptions(),
             table: Mapping[str, Mapping[str, int]] | None = None) -> list[Diagnosis]:
    """Map the significant drifts of a validated parameter set to the faults of Table I.

    Parameters are those of ``drifts``, and ``table`` (fault -> {parameter: direction}; None: the DC drive's
    ``TABLE_I``; a PMSM's is ``TABLE_I_PMSM``, see ``TABLES``). Returns one ``Diagnosis`` per candidate fault (several when
    Table I cannot tell them apart, e.g. wear and lubrication), plus ``unexplained drift`` for the
    drifted parameters no fault explains; an empty list when nothing drifted.
    """
    all_drifts = {d.parameter: d for d in drifts(current, baseline, last, recent, options)}
    evidence = {p: d for p, d in all_drifts.items() if d.significant}
    if not evidence:
        return []
    table = TABLE_I if table is None else table
    explains = {}
    for fault, sens in table.items():
        hit = frozenset(p for p, d in evidence.items()
                        if p in sens and (sens[p] == 0 or np.sign(d.relative_change) == sens[p]))
        if hit:
            explains[fault] = hit
    kept = [f for f, hit in explains.items() if not any(hit < other for other in explains.values())]
    # Sensitive parameters that were measured precisely and did not move (or moved the wrong way) speak
    # against a fault: of the faults explaining the same drifts keep those with the fewest such
    # contradictions (R up with K and L steady is brush wear, not motor heating).
    against = {f: sum(_contradicts(all_drifts.get(p), want, options)
                      for p, want in table[f].items() if p not in explains[f]) for f in kept}
    kept = [f for f in kept if not any(explains[g] >= explains[f] and against[g] < against[f] for g in kept)]
    out = [Diagnosis(f, tuple(sorted(explains[f])), tuple(evidence[p] for p in sorted(explains[f]))) for f in kept]
    rest = sorted(set(evidence) - set().union(*explains.values()))
    if rest:
        out.append(Diagnosis(UNEXPLAINED, tuple(rest), tuple(evidence[p] for p in rest)))
    return out
