"""A time column that states no unit, checked against the data: the position's derivative must be the speed.

A recording whose time column gives no unit is taken in seconds (:func:`feeddrive.cosim.recorded.assumed_units`
says so). Taken for seconds, a time in ms makes every derivative 1000 times too small: Jt came out 1e6 times
too large with exit 0. When the recording maps a position and a speed, the data tell the time unit: over the
samples where the axis moves, ``d(position)/dt = g x speed`` with ``g = 1`` when the units hold. A gain that one
unit explains (``g = 1e-3``: the time in ms; ``2 pi / 60``: a bare speed in rpm) refuses the recording, naming the
column, the measured gain and the fix; ``g ~ 1`` confirms the seconds and the note says so; any other gain is
added to the note. A stated time unit is never second-guessed here (a real gain fault is the monitor's business).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from feeddrive.cosim.errors import DataError

#: a :class:`feeddrive.cosim.recorded.Recording` (not imported: recorded imports this module)
Recording = Any

#: relative distance of the measured gain to an explanation's within which the explanation is taken (3 %: 180 / pi
#: (a position in deg) and 60 (a time in min) are 4.5 % apart, as are rpm's 2 pi / 60 and the 0.1 of a row index
#: mapped as the time of 10 Hz data; a gain near both is refused naming both)
UNIT_TOLERANCE = 0.03
#: the filtered d(position)/dt and speed must correlate this well for their gain to mean anything
MIN_CORRELATION = 0.95
#: cut-off of the identical low-pass filter [fraction of the sample rate]: relative, so that the wrong time unit
#: itself changes nothing (the gain of two identically filtered proportional signals is the filter's)
CUTOFF = 0.01
#: fewest samples of a record the gain is measured on (shorter pieces of a split recording are skipped)
MIN_PIECE = 50


def _explanations(rec: Recording, time: bool = True) -> list[tuple[float, str, str]]:
    """``(gain, what explains it, the fix)``: each unit a bare time (with ``time``), speed or position may be in
    instead of s, rad/s (m/s) or rad (m), with the gain d(position)/dt / speed it gives when taken as the SI one."""
    out = []
    if time:
        time_col = rec.timing["source"].split(" ", 1)[1].strip("'")
        out = [(1e-3, "the time is in ms", f"--map 'time={time_col} [ms]'"),
               (1e-6, "the time is in us", f"--map 'time={time_col} [us]'"),
               (60.0, "the time is in min", f"--map 'time={time_col} [min]'")]
    table = rec.side == "table"
    speed, position = rec.columns["speed"], rec.columns["position"]
    if not rec.units.get("speed"):  # a bare speed: taken as rad/s (m/s); its values are the SI ones x 1/gain
        out += ([(1e-3, "the speed is in mm/s", f"--map 'speed={speed} [mm/s]'")] if table else
                [(2 * math.pi / 60, "the speed is in rpm", f"--map 'speed={speed} [rpm]'"),
                 (math.pi / 180, "the speed is in deg/s", f"--map 'speed={speed} [deg/s]'")])
    if not rec.units.get("position"):
        out += ([(1e3, "the position is in mm", f"--map 'position={position} [mm]'")] if table else
                [(180 / math.pi, "the position is in deg", f"--map 'position={position} [deg]'"),
                 (1 / (2 * math.pi), "the position is in revolutions", f"--map 'position={position} [rev]'")])
        if not rec.units.get("speed") and not table:
            out.append((1 / 60, "the position is in revolutions and the speed in rpm",
                        f"--map 'position={position} [rev]' 'speed={speed} [rpm]'"))
    return out


def position_speed_gain(rec: Recording) -> tuple[float, float] | None:
    """``(g, correlation)``: d(position)/dt = g x speed, both low-passed identically (``CUTOFF``), over the samples
    where the axis moves (``validation.gain_ratio``: |speed - its mean| above 20 % of its largest value), the time
    taken in s; None when the axis does not move (``segmentation.at_rest``) or no record is long enough."""
    from feeddrive.estimator.errors import EstimatorInputError
    from feeddrive.estimator.filtering import lowpass
    from feeddrive.estimator.segmentation import at_rest
    from feeddrive.estimator.validation import gain_ratio

    speed = rec.signals["speed"]
    if at_rest(speed) is not None:
        return None
    slope = rec.gradient(rec.signals["position"])  # within each record: never across a gap
    parts = [lowpass({"d": slope[a:b], "w": speed[a:b]}, rec.h, CUTOFF / rec.h) for a, b in rec.bounds()
             if b - a >= MIN_PIECE]
    if not parts:
        return None
    d = np.concatenate([p["d"] for p in parts])
    w = np.concatenate([p["w"] for p in parts])
    try:
        gain = gain_ratio(d, w)
    except EstimatorInputError:  # the filtered speed is constant
        return None
    with np.errstate(invalid="ignore", divide="ignore"):
        r = float(np.corrcoef(d, w)[0, 1])
    return (gain, r) if math.isfinite(gain) else None


def _judged(rec: Recording, time: bool) -> tuple[float, float, list[tuple[str, str]]] | None:
    """``(gain, correlation, the units that explain the gain)`` of d(position)/dt against the speed
    (``position_speed_gain``; ``_explanations`` within ``UNIT_TOLERANCE``, the time's with ``time``; none when
    the two do not follow each other or the gain is ~1), or None when a position and a speed are not both mapped
    or the axis does not move."""
    if not {"position", "speed"} <= set(rec.signals):
        return None
    measured = position_speed_gain(rec)
    if measured is None:
        return None
    gain, r = measured
    if not r >= MIN_CORRELATION or abs(gain - 1.0) <= UNIT_TOLERANCE:
        return gain, r, []
    return gain, r, [(what, fix) for g, what, fix in _explanations(rec, time) if abs(gain / g - 1.0) <= UNIT_TOLERANCE]


def _within(gain: float) -> str:
    return f"the position's derivative matches the speed within {100 * abs(gain - 1.0):.2g} %"


def time_note(rec: Recording, note: str) -> str:
    """The note on a time column that states no unit (``note``: taken as s, how to state it), checked against the
    data when a position and a speed are mapped.

    Returns
    -------
    str
        ``note`` with ``taken as s: the position's derivative matches the speed within X %`` when the gain is ~1,
        or the measured gain added when no unit explains it (or the two do not follow each other).

    Raises
    ------
    cosim.errors.DataError
        The gain is one a unit explains (``_explanations``, within ``UNIT_TOLERANCE``): the line names the time
        column, the gain and each fix.
    """
    judged = _judged(rec, time=True)
    if judged is None:
        return note
    gain, r, fits = judged
    if not r >= MIN_CORRELATION:
        return f"{note}; the position's derivative does not follow the speed (correlation {r:.2f}): not checked"
    if abs(gain - 1.0) <= UNIT_TOLERANCE:
        return note.replace("taken as s", f"taken as s: {_within(gain)}", 1).replace("[UNIT]' (e.g. ms)", "[s]'")
    source = rec.timing["source"]
    if fits:
        why = " or ".join(f"{what} ({fix})" for what, fix in fits)
        time_col = source.split(" ", 1)[1].strip("'")
        # a gear of 60 (or 1000) between the position and the speed reads as a time unit: the seconds, stated, pass
        keep = (f"; if the seconds are right (a gear between the position and the speed), state them: "
                f"--map 'time={time_col} [s]'") if any(what.startswith("the time") for what, _ in fits) else ""
        raise DataError(f"{rec.path}: {source} states no unit and is taken as s, but then the position's derivative "
                        f"is {gain:.4g} x the speed: {why}{keep}")
    return (f"{note}; the position's derivative is {gain:.4g} x the speed (no time unit explains it: a gear between "
            f"the two, or a sensor's gain?)")


def motion_units_note(rec: Recording) -> str | None:
    """With the time's unit known (stated, or ``--rate``/``--dt``), a bare speed or position checked the same way:
    ``d(position)/dt = speed`` (``_judged``). A gain that the speed's or the position's unit explains (rpm:
    2 pi / 60, deg/s, deg, rev, mm) is refused naming the fix; ~1 confirms the units taken (the line returned);
    another gain is said. None when a position and a speed are not both mapped, both state their unit, or the
    axis does not move.

    Raises
    ------
    cosim.errors.DataError
        The gain is one a unit of the speed or the position explains (within ``UNIT_TOLERANCE``).
    """
    if rec.units.get("speed") and rec.units.get("position"):
        return None
    judged = _judged(rec, time=False)
    if judged is None:
        return None
    gain, r, fits = judged
    bare = " and ".join(f"{role} {rec.columns[role]!r}" for role in ("position", "speed") if not rec.units.get(role))
    if not r >= MIN_CORRELATION:
        return f"{bare}: the position's derivative does not follow the speed (correlation {r:.2f}): units not checked"
    if abs(gain - 1.0) <= UNIT_TOLERANCE:
        return f"{bare}: the units taken agree: {_within(gain)}"
    if fits:
        why = " or ".join(f"{what} ({fix})" for what, fix in fits)
        verb = "state" if " and " in bare else "states"
        raise DataError(f"{rec.path}: {bare} {verb} no unit, and the position's derivative is {gain:.4g} x the "
                        f"speed: {why}")
    return f"{bare}: the position's derivative is {gain:.4g} x the speed (no unit explains it: a gear between the " \
           "two, or a sensor's gain?)"
