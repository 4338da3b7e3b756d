"""Units on connections: a source's output unit against the input unit its destination declares (pint).

FMU components declare their inputs' units (the FMU's, or the role's SI unit); the master checks every
connection between an output and an input that both declare one. Units that differ only in spelling
(``N.m`` and ``N*m``) pass; a different scale (``mm`` into ``m``) or dimension (``V`` into ``rad/s``) is a
ScenarioError naming the connection: the master carries numbers, it never converts them silently.
"""
from __future__ import annotations

import re
from functools import lru_cache
from typing import Any


@lru_cache(maxsize=1)
def _registry() -> Any:
    import pint

    return pint.UnitRegistry()


def _quantity(unit: str) -> Any:
    text = re.sub(r"(?<=[A-Za-z])\.(?=[A-Za-z])", "*", unit)  # N.m -> N*m
    text = re.sub(r"(?<=[A-Za-z])(\d+)", r"**\1", text).replace("Ohm", "ohm")  # m2 -> m**2
    return _registry().Quantity(1.0, "dimensionless" if text in ("1", "-") else text)


def mismatch(source_unit: str, input_unit: str) -> str | None:
    """Why a value in ``source_unit`` cannot feed an input in ``input_unit`` unchanged, or None.

    Either unit empty (not declared): None, nothing to check.
    """
    if not source_unit or not input_unit or source_unit == input_unit:
        return None
    import pint

    try:
        a, b = _quantity(source_unit), _quantity(input_unit)
    except (pint.errors.PintError, ValueError, TypeError, AttributeError, SyntaxError):
        return f"cannot compare units {source_unit!r} and {input_unit!r} (unknown to pint)"
    try:
        factor = float(a.to(b.units).magnitude)
    except pint.errors.DimensionalityError:
        return f"unit {source_unit!r} does not convert to {input_unit!r} (another dimension)"
    from feeddrive.cosim.unit_map import angle_exponent

    if angle_exponent(a) != angle_exponent(b):  # pint holds the radian dimensionless: Hz = rad/s for it
        return (f"unit {source_unit!r} into {input_unit!r}: one counts an angle, the other not (revolutions or "
                "radians?); expected the same unit on both sides")
    if abs(factor - 1.0) > 1e-12:
        return (f"1 {source_unit} = {factor:g} {input_unit}: the value would be taken in the wrong scale; "
                "expected the same unit on both sides (convert in the FMU or with a map entry's scale)")
    return None
