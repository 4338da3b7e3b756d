"""Which recorded quantity's sign convention differs from the model's, when the estimate is impossible.

A current sensor wired the other way round, a drive that logs the speed positive the other way, or a vendor
FMU whose torque is positive as a load turns every estimate of some equations negative: with ``i -> -i`` the
DC drive's fit gives ``-R, -L, K, -Jt, -ft, -Cd``; with ``w -> -w`` only ``K < 0``; with ``u -> -u`` all six.
Each pattern is what one quantity's reversal does to the regressions, so rather than tabulate them per motor
the least squares fit is made again with each measured quantity negated in turn (model-generic: a PMSM's
``u_d, u_q`` or ``i_d, i_q`` are negated together, as a current or voltage chain counting the other way
does; a reversed phase sequence is not this and gets no hint). When exactly
the negations of one quantity (or of either of two: only their relative sign is seen) make every given
parameter physically possible, that is said, with the values it gives. Nothing is changed in the estimate:
it stays flagged and is never validated; the hint only says where to look.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace

import numpy as np

from feeddrive.estimator.motion import FIELDS, EstimationOptions, MotionData
from feeddrive.estimator.physical import physical_flags

#: a signal name's quantity, as a user maps it (PMSM: ``u_d`` -> ``u``)
QUANTITY = {"u": "voltage", "i": "current", "w": "speed", "position": "speed", "torque": "torque"}


def _groups(data: MotionData) -> dict[str, list[str]]:
    """quantity -> the present signals that carry it (a speed and a position are one quantity)."""
    out: dict[str, list[str]] = {}
    for name in data.raw():
        q = QUANTITY.get(name) or QUANTITY.get(name.split("_")[0], name)
        out.setdefault(q, []).append(name)
    return out


def _negated(data: MotionData, names: list[str]) -> MotionData:
    fields = {n: -getattr(data, n) for n in names if n in FIELDS}
    signals = {n: (-x if n in names else x) for n, x in data.signals.items()}
    return replace(data, **fields, signals=signals)


def sign_hint(data: MotionData, options: EstimationOptions, flags: Mapping[str, str],
              fit_ls: Callable) -> str | None:
    """One sentence naming the quantity whose sign reversal makes the estimate physically possible, or None.

    Parameters
    ----------
    data : MotionData
        The motion as estimated.
    options : EstimationOptions
        The options it was estimated with.
    flags : mapping of str to str
        The estimate's physical-range flags (``physical.physical_flags`` without the user's bounds); no hint
        is looked for without one.
    fit_ls : callable
        ``partial._fit_ls``: (data, options) -> (Prepared, MethodResult or None, fixed, refused, lumped).

    Returns
    -------
    str or None
        E.g. ``"the current's sign is the opposite of the model's convention: with it negated every parameter
        is physically possible (R 0.6, L 0.004, ...); map it times -1 (COLUMN*-1) or check the sensor's
        direction"``; None when no single quantity explains the flags (a model mismatch, a missing term).
    """
    if not flags:
        return None
    groups = _groups(data)
    if len(groups) < 2:  # one quantity alone has no relative sign
        return None
    found: dict[str, dict[str, float]] = {}
    ls_options = replace(options, method="ls")
    for quantity, names in groups.items():
        try:
            _, res, _, refused, lumped = fit_ls(_negated(data, names), ls_options)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):  # a refusal: this negation explains nothing
            continue
        if res is None:
            continue
        given = [n for n in res.names if n not in refused and n not in lumped]
        if not given or set(physical_flags(res, {})) & set(given):
            continue
        found[quantity] = {n: float(res.values[res.names.index(n)]) for n in given}
    if not found or len(found) > 2:
        return None
    values = next(iter(found.values()))
    shown = ", ".join(f"{n} {v:.4g}" for n, v in values.items())
    if len(found) == 1:
        q = next(iter(found))
        return (f"the {q}'s sign is the opposite of the model's convention: with it negated every parameter is "
                f"physically possible ({shown}); map it times -1 (COLUMN*-1) or check the sensor's direction")
    a, b = found
    # a term of neither quantity (a torque offset T0) changes sign with the one negated: both values are said
    same = {n: v for n, v in found[a].items() if n in found[b] and np.isclose(v, found[b][n], rtol=1e-6, atol=0.0)}
    shown = ", ".join(f"{n} {v:.4g}" for n, v in same.items())
    both = [f"{n} {v:.4g} with the {a} negated, {found[b][n]:.4g} with the {b}" for n, v in found[a].items()
            if n not in same and n in found[b]]
    shown += "".join(f"; {x}" for x in both)
    return (f"the {a} and the {b} have opposite sign conventions (only their relative sign is seen): with either "
            f"negated every parameter is physically possible ({shown}); map one of them times -1 (COLUMN*-1)")
