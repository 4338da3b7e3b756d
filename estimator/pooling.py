"""Several estimates of one machine (repeated recordings, or the motions of one recording): do they agree,
and what is their pooled estimate?

Pooled estimate: inverse-covariance weighted, ``theta = (sum C_f^-1)^-1 sum C_f^-1 theta_f`` over the
estimates ``f`` that give every pooled parameter (a parameter given by only some of them is pooled
alone, with its variances). Agreement: ``chi2 = sum_f (theta_f - theta)^T C_f^-1 (theta_f - theta)`` on
``(m - 1) p`` degrees of freedom (m estimates of p parameters) with its p-value (``joint``), and the
same per parameter with its variances on ``m - 1``. The question a user asks is whether each parameter
agrees within the intervals: the verdict is ``consistent`` when the smallest per-parameter p-value times
the number of parameters tested (Bonferroni, the reported ``p_value``) is above ``alpha``, else
``differ: <params>`` naming those whose own p-value is below ``alpha / p``. The joint test is reported
beside it: it also weighs the correlations within a file, which a model mismatch can make too optimistic.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from feeddrive.estimator.distributions import chi2_sf, t_ppf
from feeddrive.estimator.motion import ORDER, MethodResult, ParameterEstimate


@dataclass(frozen=True)
class Pooled:
    """Pooled estimate and agreement test of several estimates.

    Attributes
    ----------
    parameters : dict of str to ParameterEstimate
        Pooled value, standard error and 95 % interval (t with the summed degrees of freedom).
    count : dict of str to int
        How many estimates gave each parameter.
    chi2, dof, joint_p : float, int, float
        Joint test over the parameters every estimate gives (dof 0 and p 1 when there is nothing to test).
    p_value : float or None
        The smallest per-parameter p-value times the number of parameters tested (at most 1): the verdict's;
        None when no parameter is given by two estimates or more (verdict ``not tested: ...``).
    per_parameter : dict of str to (chi2, dof, p_value)
    differ : list of str
    verdict : str
        ``consistent``, ``differ: Jt, ...`` or ``not tested: ...``.
    """

    parameters: dict[str, ParameterEstimate]
    count: dict[str, int]
    chi2: float
    dof: int
    joint_p: float
    p_value: float | None
    per_parameter: dict[str, tuple[float, int, float]] = field(default_factory=dict)
    differ: list[str] = field(default_factory=list)
    verdict: str = "consistent"
    parameter_dof: dict[str, float] = field(default_factory=dict)

    def as_result(self) -> MethodResult:
        """The pooled estimate as a ``MethodResult`` (diagonal covariance), e.g. to pool it again."""
        names = tuple(self.parameters)
        std = np.array([p.std for p in self.parameters.values()])
        return MethodResult("pooled", names, np.array([p.value for p in self.parameters.values()]),
                            np.diag(std ** 2), 1, 0.0, 0.0,
                            parameter_dof=np.array([self.parameter_dof[n] for n in names]))

    def to_dict(self) -> dict:
        return {"p_value": self.p_value, "verdict": self.verdict,
                "joint": {"chi2": self.chi2, "dof": self.dof, "p_value": self.joint_p},
                "differ": list(self.differ),
                "per_parameter": {n: {"chi2": c, "dof": d, "p_value": p} for n, (c, d, p) in self.per_parameter.items()},
                "pooled": {n: {"value": p.value, "ci95": list(p.ci95), "count": self.count[n]}
                           for n, p in self.parameters.items()}}


def _pinv(C: np.ndarray) -> np.ndarray:
    return np.linalg.pinv(C, rcond=1e-12, hermitian=True)


def _dof(r: MethodResult, n: str) -> float:
    j = r.names.index(n)
    return float(r.dof if r.parameter_dof is None else r.parameter_dof[j])


def pool(results: list[MethodResult], alpha: float = 0.01) -> Pooled:
    """Pool ``results`` (each with its own given parameters) and test their agreement (module docstring)."""
    order = list(ORDER)
    names = sorted({n for r in results for n in r.names}, key=order.index)
    params, count, per, dofs = {}, {}, {}, {}
    for n in names:
        have = [r for r in results if n in r.names]
        x = np.array([r.values[r.names.index(n)] for r in have])
        v = np.array([r.covariance[r.names.index(n), r.names.index(n)] for r in have])
        ok = v > 0
        if not ok.any():
            continue
        wgt = 1.0 / v[ok]
        mean = float(np.sum(wgt * x[ok]) / np.sum(wgt))
        std = float(np.sqrt(1.0 / np.sum(wgt)))
        dof = sum(_dof(r, n) for r, k in zip(have, ok) if k)
        q = float(t_ppf(0.975, max(dof, 1.0)))
        params[n] = ParameterEstimate(mean, std, (mean - q * std, mean + q * std))
        count[n] = int(ok.sum())
        dofs[n] = max(dof, 1.0)
        if ok.sum() > 1:
            c = float(np.sum(wgt * (x[ok] - mean) ** 2))
            per[n] = (c, int(ok.sum()) - 1, float(chi2_sf(c, int(ok.sum()) - 1)))
    common = [n for n in names if n in params and all(n in r.names for r in results)]
    chi2, dof = 0.0, 0
    if len(results) > 1 and common:
        sub = []
        for r in results:
            idx = [r.names.index(n) for n in common]
            sub.append((np.asarray(r.values)[idx], np.asarray(r.covariance)[np.ix_(idx, idx)]))
        W = [_pinv(C) for _, C in sub]
        theta = np.linalg.lstsq(sum(W), sum(w @ x for w, (x, _) in zip(W, sub)), rcond=None)[0]
        chi2 = float(sum((x - theta) @ w @ (x - theta) for w, (x, _) in zip(W, sub)))
        dof = (len(results) - 1) * len(common)
    joint_p = float(chi2_sf(chi2, dof)) if dof else 1.0
    p_value = min(1.0, min((p for *_, p in per.values()), default=1.0) * max(len(per), 1))
    differ = [n for n, (_, _, p) in per.items() if p * len(per) <= alpha]
    verdict = f"differ: {', '.join(differ)}" if differ else "consistent"
    if len(results) > 1 and not per:  # nothing to compare: "consistent" would be a verdict without a test
        verdict, p_value = "not tested: no parameter is given by more than one estimate", None
    return Pooled(params, count, chi2, dof, joint_p, p_value, per, differ, verdict, dofs)
