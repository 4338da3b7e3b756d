"""``cosim info RECORDING``: what a recording holds (variables, shapes, dtypes, units) and its time base."""
from __future__ import annotations

import re

import numpy as np

from feeddrive.cosim.errors import DataError
from feeddrive.cosim.readers.source import Source, Variable
from feeddrive.cosim.readers.timebase import measure

_TIME_NAME = re.compile(r"(^|[._ \s])(t|time\w*|timestamp\w*|\w*_time|zeit)$", re.IGNORECASE)


def find_time(source: Source, variables: list[Variable]) -> tuple[str, np.ndarray, bool] | None:
    """The first time-like signal: a vector named like time (``t``, ``time``, ``rec.time_cont``) or a
    matrix whose first column increases in non-integer steps (``data[:,0]``); None when there is none."""
    candidates = [v.name for v in variables if len(v.shape) == 1 and v.dtype not in ("text", "struct", "-")
                  and (_TIME_NAME.search(re.sub(r"\s*\[[^\]]*\]$", "", v.name)) or v.dtype == "datetime")]
    candidates += [f"{v.name}[:,0]" for v in variables if len(v.shape) == 2 and v.shape[0] > 2
                   and v.dtype not in ("text", "struct", "-", "cells", "struct array")]
    for name in candidates:
        try:
            sig = source.resolve(name, "time")
        except DataError:
            continue
        t = sig.values
        if len(t) > 2 and np.all(np.isfinite(t)) and np.all(np.diff(t) > 0) and (
                not name.endswith("[:,0]") or np.any(t != np.round(t))):
            return name, t, sig.absolute
    return None


def describe(source: Source, time: str | None = None, rate: float | None = None) -> list[str]:
    """The lines ``cosim info`` prints for a recording (``time``: the time variable to use; ``rate`` [Hz])."""
    variables = source.variables()
    lines = [str(source.path), f"  {source.kind}"]
    found = None
    if time is not None:
        sig = source.resolve(time, "time")
        found = (sig.label, sig.values, sig.absolute)
    elif rate is None:
        found = find_time(source, variables)
    if found is not None:
        name, t, absolute = found
        dt = np.diff(t)
        if np.any(dt <= 0):
            lines.append(f"  time: {name}: not strictly increasing at sample {int(np.flatnonzero(dt <= 0)[0]) + 1}")
        else:
            timing = measure(t - t[0])
            lines.append(f"  time: {name}{' (calendar time stamps)' if absolute else ''}: {timing.describe()}, "
                         f"{t[-1] - t[0]:.6g} s")
            if not timing.uniform:
                lines.append("  not uniformly sampled: cosim estimate/monitor need --resample MAXGAP or --split-gaps")
    elif rate is not None:
        lines.append(f"  time: --rate {rate:g} Hz (no time column used)")
    else:
        lines.append("  time: no time column found; map one (--map time=NAME) or give --rate HZ or --dt SECONDS "
                     "to cosim estimate and monitor (cosim info DATA --time NAME shows its sampling)")
    rows = [("name", "shape", "dtype", "unit", "note")]
    rows += [(v.name, " x ".join(map(str, v.shape)) or "scalar", v.dtype, v.unit, v.note) for v in variables]
    widths = [max(len(r[k]) for r in rows) for k in range(len(rows[0]))]
    lines += ["  " + "  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
    return lines
