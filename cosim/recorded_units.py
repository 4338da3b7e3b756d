"""Units of recorded data: the SI unit of each role, a header's or a map's unit converted with pint, and the
role map's ``COLUMN*SCALE [UNIT]`` entries (``cosim estimate`` and ``cosim monitor``, :mod:`feeddrive.cosim.recorded`).

A scale that changes a column's unit (a gear, a pitch, a wheel radius, a percentage of a rated value) states
the unit of the scaled values; a unit is never taken on trust where the header or the map says another.
"""
from __future__ import annotations

import math
import re
from functools import lru_cache

from feeddrive.cosim.errors import DataError, InputError

#: SI unit each role is converted to, in order of preference; a unit that converts to a later entry of
#: position / speed / torque puts the data on the table side of a linear axis.
SI_UNITS = {"time": ("s",), "voltage": ("V",), "voltage_ref": ("V",), "current": ("A",), "current1": ("A",),
            "current2": ("A",), "speed": ("rad/s", "m/s"), "position": ("rad", "m"), "torque": ("N*m", "N"),
            "torque_ref": ("N*m", "N"), "state": (), "i_d": ("A",), "i_q": ("A",), "u_d": ("V",), "u_q": ("V",),  # PMSM dq (cosim estimate --drive)
            # a PMSM drive's trace (cosim monitor --drive pmsm, cosim/recorded_servo.py): phase currents, a second
            # sensor on one phase, voltage references, electrical angle, linear-scale position
            "I_U": ("A",), "I_V": ("A",), "I_W": ("A",), "I_U2": ("A",), "I_V2": ("A",), "I_W2": ("A",),
            "u_d_ref": ("V",), "u_q_ref": ("V",), "phi_el": ("rad",), "x_lin": ("m",)}
#: roles whose unit says which side of the drive chain the data are on (``Recording.side``, ``to_motor_side``)
MECHANICAL = ("position", "speed", "torque", "torque_ref")
#: roles whose values may be rms values (``[A rms]``): a PMSM's dq currents, whose amplitude-invariant value is
#: the phase peak, sqrt(2) x the rms value of the sinusoidal phase current (a phase current's sample is never rms)
RMS_ROLES = ("i_d", "i_q")
SI_SIDE = {"rad/s": "motor", "rad": "motor", "N*m": "motor", "m/s": "table", "m": "table", "N": "table"}
#: Largest magnitude accepted: the estimator squares and sums the samples, 1e300 would overflow
MAX_ABS = 1e100


@lru_cache(maxsize=1)
def _registry():  # noqa: ANN202 - pint.UnitRegistry, built once (slow)
    import pint

    return pint.UnitRegistry()


def si_factor(unit: str, role: str, where: str) -> tuple[float, str]:
    """``(factor, si_unit)``: a value in ``unit`` times ``factor`` is in ``si_unit`` (pint does the work).

    ``N.m``, ``kg.m2`` and ``Ohm`` are read as ``N*m``, ``kg*m**2`` and ``ohm``. ``where`` names the file
    and column in the error.
    """
    import pint

    targets = SI_UNITS.get(role, ())
    if not targets or unit in ("", "1", "-"):
        return 1.0, ""
    base, rms = re.subn(r"(?i)[\s_]*rms$", "", unit.strip())
    if rms:  # an rms value is no unit pint converts: stated in the header, converted here, and said so
        if role not in RMS_ROLES or not base:
            raise DataError(f"{where}: unit {unit!r}: an rms value is not a sample of role {role}; expected "
                            f"{' or '.join(targets)} (rms only for the dq currents {', '.join(RMS_ROLES)})")
        factor, si = si_factor(base, role, where)
        return factor * math.sqrt(2.0), f"{si} (rms x sqrt 2)"
    text = re.sub(r"(?<=[A-Za-z])\.(?=[A-Za-z])", "*", unit)  # N.m -> N*m
    text = re.sub(r"(?<=[A-Za-z])(\d+)", r"**\1", text).replace("Ohm", "ohm")  # m2 -> m**2
    ureg = _registry()
    try:
        q = ureg.Quantity(1.0, text)
    except (pint.errors.PintError, ValueError, TypeError, AttributeError, SyntaxError):
        raise DataError(f"{where}: unknown unit {unit!r}; expected a unit such as {', '.join(targets)}") from None
    for target in targets:
        try:
            factor = float(q.to(target).magnitude)
        except pint.errors.DimensionalityError:
            continue
        from feeddrive.cosim.unit_map import angle_mismatch

        angle = angle_mismatch(unit, target)  # pint holds the radian dimensionless: [1/min] was rad/s x 1/60
        if angle is not None:
            raise DataError(f"{where}: {angle}; expected the unit that says it, e.g. [rpm] for revolutions per minute")
        return factor, target
    # a percentage or per-unit value (of a rated torque, current, speed): its scale is the machine's, not pint's
    rated = (f"; a fraction of a rated value needs its scale: --map '{role}=COLUMN*SCALE [{targets[0].replace('*', '.')}]'"
             " (SCALE = rated value / 100 for %)") if q.dimensionless else ""
    raise DataError(f"{where}: unit {unit!r} is not a unit of role {role} (expected one convertible to "
                    f"{' or '.join(targets)}){rated}")


#: a scale within this relative distance of the header unit's own factor to SI agrees with it (rounded constants)
SCALE_AGREES = 1e-3
_STATED = re.compile(r"^(?P<column>.*\S)\s+\[(?P<unit>[^\[\]]*)\]\s*$")
_SCALED = re.compile(r"^(?P<column>.*\S)\s*\*\s*(?P<scale>[^\s*\[\]]+)\s*(?:\[(?P<unit>[^\[\]]*)\])?\s*$")


def split_map(column: str) -> tuple[str, float | None, str | None]:
    """A role map's entry: ``COLUMN``, ``COLUMN [UNIT]``, ``COLUMN*SCALE`` or ``COLUMN*SCALE [UNIT]``.

    Returns ``(column, scale or None, stated unit or None)``: the column's values times the scale are in
    the stated unit (``"Wheel velocity*325.9 [rad/s]"``: a wheel speed in m/s times gear/radius is the
    motor's speed in rad/s; a gear or a pitch changes the unit, so the header's unit no longer says it).
    """
    m = _SCALED.match(column)
    if m is None:
        m = _STATED.match(column)  # a unit stated without a scale: after a space (data[:,3] is an index)
        if m is None:
            return column, None, None
        unit = m["unit"].strip()
        if not unit:
            raise InputError(f"--map {column!r}: empty unit in [ ]; expected e.g. [rad/s]")
        return m["column"].strip(), None, unit
    try:
        value = float(m["scale"])
    except ValueError:
        return column, None, None
    if not math.isfinite(value) or value == 0:
        raise InputError(f"--map {column!r}: the scale must be a finite non-zero number")
    unit = m["unit"].strip() if m["unit"] is not None else None
    if unit == "":
        raise InputError(f"--map {column!r}: empty unit in [ ]; expected e.g. [rad/s]")
    return m["column"].strip(), value, unit


def _stated_factor(stated: str, header: str, role: str, where: str) -> tuple[float, str]:
    """``(factor to SI, SI unit)`` of ``COLUMN [UNIT]``: the unit a column's header lacks, or its own again; one that
    contradicts the header's is refused (a scale converts: ``COLUMN*SCALE [UNIT]``)."""
    factor, si = si_factor(stated, role, f"{where}: stated unit [{stated}]")
    if header:
        head_factor, head_si = si_factor(header, role, where)
        if head_si != si or abs(factor / head_factor - 1.0) > 1e-12:
            raise DataError(f"{where}: the header says [{header}], the map states [{stated}]; expected one unit (a "
                            f"scale converts between them: --map '{role}=COLUMN*SCALE [{stated}]')")
    return factor, si


def _scaled_factor(spec: str, scale: float, stated: str | None, header: str, role: str, where: str
                   ) -> tuple[float, str]:
    """``(factor to SI, SI unit or "")`` of ``COLUMN*SCALE [UNIT]`` (``stated``) on a column whose header states
    ``header``.

    A stated unit decides (the values times the scale are in it). Without one, a scale that agrees with the
    header's own factor to SI (within :data:`SCALE_AGREES`) keeps the header's unit; one that contradicts it is
    refused (it changes the unit: a gear, a pitch, a wheel radius), naming the fix. With no unit anywhere the
    unit stays unknown (``""``): :func:`read_recording` says what it is taken as.
    """
    if stated is not None:
        factor, si = si_factor(stated, role, f"{where}: stated unit [{stated}]")
        return scale * factor, si
    head_factor, head_si = 1.0, ""
    if header:
        try:
            head_factor, head_si = si_factor(header, role, where)
        except DataError:  # not the role's unit (%, counts): the scale makes it one, which the map must state
            raise DataError(f"{where}: the header says [{header}], not a unit of {role}, and the map's scale "
                            f"{scale:.6g} gives no unit; state the unit of the scaled values: --map "
                            f"'{role}={spec} [UNIT]', e.g. [{SI_UNITS[role][0].replace('*', '.')}]") from None
    if not head_si:
        return scale, ""
    if abs(scale / head_factor - 1.0) <= SCALE_AGREES:
        return scale, head_si
    why = " (a gear, a pitch or a radius changes it)" if role in MECHANICAL else ""
    raise DataError(f"{where}: the header says [{header}] ({head_factor:.6g} x to {head_si}) but the map's scale is "
                    f"{scale:.6g}, so the scaled values are in another unit{why}; state it: --map "
                    f"'{role}={spec} [UNIT]', e.g. [{SI_UNITS[role][0]}]")


def column_factor(spec: str, header: str, role: str, where: str) -> tuple[float, str]:
    """``(factor to SI, SI unit or "")`` of a role map's entry ``spec`` (:func:`split_map`) on a column whose
    header states ``header`` (``""``: none); ``where`` names the file and column in an error."""
    _, scale, stated = split_map(spec)
    if scale is None and stated is not None:
        return _stated_factor(stated, header, role, where)
    if scale is None:
        return si_factor(header, role, where)
    return _scaled_factor(spec.strip(), scale, stated, header, role, where)
