"""Physical ranges of the parameters, the user's bounds, and the bounded estimate offered when one is left.

R, L, K and Jt must be positive; ft and Cd must not be negative (an interval wholly below zero is
impossible: a driving torque the model lacks, gravity, a sensor's sign). The user may add bounds, e.g.
``Jt >= 4e-6`` (the rotor's own inertia). An estimate outside is flagged with the reason and never
validated; the bounded least squares estimate (``scipy.optimize.lsq_linear`` on the same rows) is then
offered, marked as bounded (it has no confidence interval: the bound, not the data, decides it).
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from feeddrive.estimator.errors import EstimatorInputError
from feeddrive.estimator.motion import ORDER, MethodResult
from feeddrive.models.drives import DRIVES, drive_model

#: parameter -> (lower or None, upper or None)
Bounds = Mapping[str, tuple[float | None, float | None]]
#: every drive kind's physical parameters (a name means the same quantity in every model: R, Jt, ft, Cd)
_VARIABLES = {v.name: v for kind in DRIVES for v in drive_model(kind).of_kind("physical")}
STRICT = tuple(n for n, v in _VARIABLES.items() if v.lower_strict)  # R, L, K, Jt (L_d, L_q, psi_f): > 0
NON_NEGATIVE = tuple(n for n, v in _VARIABLES.items() if v.lower is not None and not v.lower_strict)  # ft, Cd


def parse_bounds(items: list[str], where: str = "--bounds") -> dict[str, tuple[float | None, float | None]]:
    """``["Jt=1e-5:1", "ft=0:"]`` -> ``{"Jt": (1e-5, 1.0), "ft": (0.0, None)}`` (one clear error otherwise)."""
    names = list(ORDER)
    out = {}
    for item in items:
        name, sep, rng = item.partition("=")
        lo, colon, hi = rng.partition(":")
        name = name.strip()
        if not sep or not colon or name not in names:
            raise EstimatorInputError(f"{where} {item!r}: expected NAME=LOW:HIGH (either may be empty) with NAME one "
                                      f"of {', '.join(names)}")
        try:
            b = tuple(float(x) if x.strip() else None for x in (lo, hi))
        except ValueError:
            raise EstimatorInputError(f"{where} {item!r}: LOW and HIGH must be numbers") from None
        if any(x is not None and not np.isfinite(x) for x in b) or (None not in b and b[0] > b[1]):
            raise EstimatorInputError(f"{where} {item!r}: expected finite LOW <= HIGH")
        out[name] = b
    return out


def bounds_mapping(raw: object, where: str = "monitor.bounds") -> dict[str, tuple[float | None, float | None]]:
    """A scenario's ``bounds:`` mapping, ``{Jt: "4e-6:", ft: [0, null]}``, as ``parse_bounds`` gives it."""
    if not isinstance(raw, Mapping):
        raise EstimatorInputError(f"{where}: expected a mapping NAME: 'LOW:HIGH' or [LOW, HIGH], got {raw!r}")
    items = []
    for name, rng in raw.items():
        if isinstance(rng, (list, tuple)) and len(rng) == 2:
            rng = ":".join("" if x is None else str(x) for x in rng)
        if not isinstance(rng, str):
            raise EstimatorInputError(f"{where}: {name}: expected 'LOW:HIGH' or [LOW, HIGH], got {rng!r}")
        items.append(f"{name}={rng}")
    return parse_bounds(items, where)


def impossible_values(values: Mapping[str, float], where: str) -> None:
    """Raise ``EstimatorInputError`` naming the first stated value outside its physical range (``--known K=0``,
    ``monitor.nominal: {R: -1}``): a known value is fixed in the fit and the checks, so an impossible one gave a
    'model mismatch' or a sign hint about the data instead of a word about the input."""
    for name, v in values.items():
        if name in STRICT and not v > 0:
            raise EstimatorInputError(f"{where} {name}={v:g}: expected a positive value ({name} > 0)".strip())
        if name in NON_NEGATIVE and not v >= 0:
            raise EstimatorInputError(f"{where} {name}={v:g}: expected a value >= 0 (a friction)".strip())


def impossible(name: str, value: float, upper: float | None = None) -> str | None:
    """Why an estimate cannot be ``name``'s, as ``physical_flags`` judges it, or None: R, L, K, Jt not positive; ft,
    Cd with the upper end of its 95 % interval ``upper`` below 0 (a friction's estimate near 0 may fall below it)."""
    if name in STRICT and not value > 0:
        return "not positive"
    if name in NON_NEGATIVE and upper is not None and upper < 0:
        return "its 95 % interval wholly below 0"
    return None


def physical_flags(result: MethodResult | None, bounds: Bounds) -> dict[str, str]:
    """Given parameters outside their physical range or the user's bounds -> the reason, with the numbers."""
    flags: dict[str, str] = {}
    if result is None:
        return flags
    for name, p in result.parameters.items():
        lo, hi = bounds.get(name, (None, None))
        if name in STRICT and not p.value > 0:
            flags[name] = f"{name} = {p.value:.4g} is not positive: physically impossible"
        elif name in NON_NEGATIVE and p.ci95[1] < 0:
            flags[name] = (f"{name} = {p.value:.4g}, 95 % CI [{p.ci95[0]:.4g}, {p.ci95[1]:.4g}] wholly below 0: a "
                           f"negative friction is impossible (a driving torque the model lacks?)")
        elif lo is not None and p.value < lo:
            flags[name] = f"{name} = {p.value:.4g} below the stated lower bound {lo:g}"
        elif hi is not None and p.value > hi:
            flags[name] = f"{name} = {p.value:.4g} above the stated upper bound {hi:g}"
    return flags


def _limits(name: str, bounds: Bounds) -> tuple[float, float]:
    lo, hi = bounds.get(name, (None, None))
    phys = 0.0 if name in STRICT or name in NON_NEGATIVE else -np.inf
    return max(phys, -np.inf if lo is None else lo), np.inf if hi is None else hi


def bounded_fit(p, known: Mapping[str, float], bounds: Bounds, names: list[str]) -> dict[str, float]:
    """Bounded least squares of every regression of ``p`` (``Prepared``) within the physical ranges and ``bounds``.

    A normalised equation (``theta = p / K``) takes its bounds divided by the bounded K. Returns the given
    ``names`` only; {} when a bounded fit cannot be made (then nothing is offered).
    """
    from feeddrive.estimator.estimate import _signals_for

    values: dict[str, float] = dict(known)
    regs = sorted(p.regressions, key=lambda r: r.normaliser is not None)  # the one giving K first
    for reg in regs:
        scale_by = 1.0
        if reg.normaliser:
            scale_by = values.get(reg.normaliser, np.nan)
            if not scale_by > 0:
                return {}
        y, Phi = reg.evaluate(_signals_for(p, reg))
        rows = p.rows[reg.equation]
        X, y = Phi[rows], y[rows]
        col = np.sqrt(np.einsum("ij,ij->j", X, X))
        col[col == 0] = 1.0
        lim = np.array([_limits(n, bounds) for n in reg.names]).T / scale_by * col
        if np.any(lim[0] > lim[1]):
            return {}
        from scipy.optimize import lsq_linear  # here: scipy.optimize takes ~0.25 s to import

        fit = lsq_linear(X / col, y, bounds=(lim[0], lim[1]))
        if not fit.success or not np.all(np.isfinite(fit.x)):
            return {}
        values.update({n: float(v) * scale_by for n, v in zip(reg.names, fit.x / col)})
    return {n: values[n] for n in names if n in values}
