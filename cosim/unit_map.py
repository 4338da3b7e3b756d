"""Units on the plant FMU's role map: each entry checked against the FMU's declared unit and converted.

Every role of the master is in SI units (``ROLE_UNITS``; the position of a rotary axis is in rad). An FMU
declares the unit of each variable in its modelDescription.xml: the variable's ``unit`` or its declared
type's ``unit`` (the value is in that unit, FMI 2.0 section 2.2.2; ``displayUnit`` only says how a tool
shows it), and a ``UnitDefinitions`` entry may give the unit's SI ``BaseUnit`` exponents, ``factor`` and
``offset``. This module turns each map entry into the linear map ``role = scale * y + offset`` (outputs) or
``x_fmu = scale * role + offset`` (inputs), with pint doing the arithmetic.

The rules of a map entry ``{var, unit, scale, offset}``:

- the unit in force is the entry's ``unit`` when stated (the scenario's word on what the variable really
  is, which replaces a wrong or missing declaration), else the FMU's declared unit;
- without ``scale``/``offset`` the conversion follows from that unit (``n_mot [rpm]`` -> ``x 0.10472``);
  a variable with no unit at all is taken as already in the role's unit, and that assumption is stated
  (``unit not declared: taken as rad/s``);
- an explicit ``scale``/``offset`` must agree with the conversion of the unit in force (relative 1e-6),
  or it is refused: a scale of 1 on an rpm output is the classic false 9.549 gain. Taken as given only
  when the unit in force is no unit, or dimensionless (``1``, ``%``, ``rad``) for a role that is not: a
  bipolar 0..100 % current output, a motor angle onto a table position;
- a unit that cannot become the role's unit (``V`` for ``speed``) is an error naming the variable and
  both units.
"""
from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

#: SI unit of each role (``position`` of a rotary axis: rad, see :func:`role_unit`)
ROLE_UNITS = {"speed_ref": "rad/s", "load": "N.m", "voltage": "V", "voltage_ref": "V", "current": "A",
              "speed": "rad/s", "position": "m"}
INPUT_ROLES = ("speed_ref", "load")
#: the role units' SI exponents (kg, m, s, A, rad): a variable declared in its role's own unit, with no
#: BaseUnit or this one (factor 1, offset 0), converts by 1 without building pint's registry (0.8 s)
SI_EXPONENTS = {"rad/s": (0, 0, -1, 0, 1), "N.m": (1, 2, -2, 0, 0), "V": (1, 2, -3, -1, 0), "A": (0, 0, 0, 1, 0),
                "m": (0, 1, 0, 0, 0), "rad": (0, 0, 0, 0, 1)}
OUTPUT_ROLES = ("voltage", "voltage_ref", "current", "speed", "position")
REQUIRED_ROLES = ("speed_ref", "voltage", "current", "speed", "position")
#: relative agreement asked of an explicit scale with the declared units (printed scales have 5+ digits)
SCALE_RTOL = 1e-6


class UnitProblem(ValueError):
    """A map entry whose units do not fit its role; ``key`` is the entry's key path below ``plant.map``."""

    def __init__(self, key: str, message: str) -> None:
        super().__init__(message)
        self.key = key


@dataclass(frozen=True)
class Conversion:
    """How one role is read from (or written to) its FMU variable.

    ``scale`` and ``offset`` are what the master applies (``role = scale * y + offset`` for an output,
    ``x = scale * role + offset`` for an input); ``unit`` is the variable's unit in force, ``source``
    where it came from (``declared``, ``stated`` in the scenario, or ``none``), ``how`` whether the numbers
    were ``converted`` by the units, ``given`` by the entry, or ``assumed`` (no unit: the role's own).
    """

    role: str
    var: str
    role_unit: str
    unit: str | None
    source: str
    how: str
    scale: float
    offset: float
    declared: str | None = None
    display_unit: str | None = None
    inverted: bool = False  # the entry's scale is the units' conversion with the opposite sign

    @property
    def note(self) -> str | None:
        """The stated assumption, when the units did not decide (printed by ``cosim info --map`` and run)."""
        if self.inverted:
            return f"{self.role} <- {self.var}: sign inverted as given, scale {self.scale:.6g} (the FMU's opposite direction)"
        if self.how == "assumed":
            return f"{self.role} <- {self.var}: unit not declared: taken as {self.role_unit}"
        if self.how == "given":
            what = "unit not declared" if self.unit is None else f"{self.unit} is dimensionless"
            return f"{self.role} <- {self.var}: {what}: scale {self.scale:.6g} offset {self.offset:.6g} as given"
        return None

    def describe(self) -> str:
        """``speed [rad/s] <- n_mot [rpm] x 0.10472`` (``->`` for an input, the FMU receives ``x``)."""
        arrow = "->" if self.role in INPUT_ROLES else "<-"
        unit = self.unit if self.unit is not None else "?"
        text = f"{self.role} [{self.role_unit}] {arrow} {self.var} [{unit}]"
        if self.how == "assumed":
            return f"{text}  unit not declared: taken as {self.role_unit}"
        text += f" x {self.scale:.5g}" + (f" {'+' if self.offset >= 0 else '-'} {abs(self.offset):.5g}"
                                          if self.offset else "")
        if self.source == "stated" and self.declared != self.unit:
            text += f"  (unit stated; the FMU declares {self.declared or 'none'})"
        if self.display_unit and self.display_unit != self.unit:
            text += f"  (displayUnit {self.display_unit})"
        if self.how == "given" or self.inverted:
            text += "  (" + self.note.split(": ", 1)[1] + ")"
        return text


@lru_cache(maxsize=1)
def _registry():  # noqa: ANN202 - pint.UnitRegistry, built once (slow)
    import pint

    return pint.UnitRegistry()


def _pint_text(unit: str) -> str:
    """FMI/SI spelling to pint's: ``N.m`` -> ``N*m``, ``kg.m2`` -> ``kg*m**2``, ``Ohm`` -> ``ohm``."""
    text = re.sub(r"(?<=[A-Za-z])\.(?=[A-Za-z(])", "*", unit.strip())
    text = re.sub(r"(?<=[A-Za-z])(\d+)", r"**\1", text)
    return text.replace("Ohm", "ohm")


def quantity(unit: str, base: Any = None) -> Any:
    """One ``unit`` as a pint quantity; ``base``: its FMI ``BaseUnit`` (SI exponents, factor, offset),
    which wins over the name. Raises ValueError for a unit pint does not know."""
    import pint

    ureg = _registry()
    if base is not None:  # the FMU's own definition: factor * kg^a m^b s^c A^d K^e mol^f cd^g rad^h
        q = ureg.Quantity(float(base.factor), "dimensionless")
        for name, pint_name in (("kg", "kg"), ("m", "m"), ("s", "s"), ("A", "A"), ("K", "K"), ("mol", "mol"),
                                ("cd", "cd"), ("rad", "rad")):
            exponent = int(getattr(base, name, 0) or 0)
            if exponent:
                q = q * ureg.Quantity(1.0, pint_name) ** exponent
        return q
    if unit.strip() in ("", "1", "-"):
        return ureg.Quantity(1.0, "dimensionless")
    try:
        return ureg.Quantity(1.0, _pint_text(unit))
    except (pint.errors.PintError, ValueError, TypeError, AttributeError, SyntaxError, AssertionError):
        raise ValueError(f"unit {unit!r} is not a unit pint knows") from None


def angle_exponent(q: Any) -> int:
    """The power of radian in a pint quantity's root units (``rpm``: 1, ``Hz`` and ``1/min``: 0)."""
    return int(dict(q.to_root_units().unit_items()).get("radian", 0))


def angle_mismatch(unit: str, target: str, base: Any = None) -> str | None:
    """Why ``unit`` cannot be read as ``target`` although pint converts it, or None.

    pint holds the radian dimensionless, so it converts ``Hz``, ``1/s`` and ``1/min`` into ``rad/s`` by 1 and
    1/60: a rate that does not say whether it counts revolutions or radians (``1/min`` on a German data sheet
    is rpm, 2 pi times more) would be taken on trust. The powers of the angle in both units must agree."""
    have, want = angle_exponent(quantity(unit, base)), angle_exponent(quantity(target))
    if have == want:
        return None
    if have == 0:
        return f"{unit} counts no angle where {target} counts radians (revolutions or radians?)"
    return f"{unit} holds the angle to the power {have}, {target} to the power {want}"


def _affine(unit: str, base: Any, target: str) -> tuple[float, float]:
    """``(a, b)`` with ``value_in_target = a * value_in_unit + b``; DimensionalityError when impossible.

    With a ``BaseUnit``, FMI defines ``value_SI = factor * value + offset`` in the product of its exponents."""
    ureg = _registry()
    if base is not None:
        factor, offset = float(base.factor or 1.0), float(base.offset or 0.0)
        k = float((quantity(unit, base) / factor).to(_pint_text(target)).magnitude)
        return k * factor, k * offset
    text = "dimensionless" if unit.strip() in ("", "1", "-") else _pint_text(unit)
    zero = float(ureg.Quantity(0.0, text).to(_pint_text(target)).magnitude)
    one = float(ureg.Quantity(1.0, text).to(_pint_text(target)).magnitude)
    return one - zero, zero


def _own_unit(unit: str, base: Any, target: str) -> bool:
    """``unit`` is the role's unit ``target`` by name and, when the FMU defines it, by its BaseUnit."""
    if unit.strip() != target or target not in SI_EXPONENTS:
        return False
    if base is None:
        return True
    exponents = tuple(int(getattr(base, n, 0) or 0) for n in ("kg", "m", "s", "A", "rad"))
    others = any(int(getattr(base, n, 0) or 0) for n in ("K", "mol", "cd"))
    return (exponents == SI_EXPONENTS[target] and not others and float(base.factor or 1.0) == 1.0
            and float(base.offset or 0.0) == 0.0)


def declared_unit(variable: Any) -> tuple[str | None, str | None]:
    """``(unit, displayUnit)`` an FMU declares for ``variable``: its own, else its declared type's."""
    t = getattr(variable, "declaredType", None)
    unit = getattr(variable, "unit", None) or (getattr(t, "unit", None) if t is not None else None)
    display = getattr(variable, "displayUnit", None) or (getattr(t, "displayUnit", None) if t is not None else None)
    return unit or None, display or None


def role_unit(role: str, kind: str = "linear") -> str:
    """The SI unit of ``role``; the position of a rotary axis is its angle in rad."""
    return "rad" if role == "position" and kind == "rotary" else ROLE_UNITS[role]


def convert(role: str, entry: Any, variable: Any, unit_definitions: list, kind: str = "linear") -> Conversion:
    """The conversion of one map entry (``entry.var``, ``.unit``, ``.scale``, ``.offset``) for ``role``.

    Raises
    ------
    UnitProblem
        Incompatible units, an unknown unit, or an explicit scale/offset contradicting the units in force;
        ``key`` says which key of the entry, the message names the variable and both units.
    """
    target = role_unit(role, kind)
    declared, display = declared_unit(variable)
    unit, source = (entry.unit, "stated") if entry.unit is not None else (declared, "declared" if declared else "none")
    given = entry.scale is not None or entry.offset is not None
    scale = 1.0 if entry.scale is None else float(entry.scale)
    offset = 0.0 if entry.offset is None else float(entry.offset)
    common = {"role": role, "var": entry.var, "role_unit": target, "unit": unit, "source": source,
              "declared": declared, "display_unit": display}
    if unit is None and display is not None:  # how a tool shows it, not the unit of its values
        raise UnitProblem("var", f"{entry.var!r} declares no unit, only the displayUnit {display!r} (the unit a tool "
                                 "shows it in; FMI defines it relative to the unit, which is missing), so the unit "
                                 f"of its values is unknown; expected its true unit stated with unit: '...' (e.g. "
                                 f"unit: '{display}' if its values are in {display}, unit: '{target}' if in {target})")
    if unit is None:
        return Conversion(**common, how="given" if given else "assumed", scale=scale, offset=offset)
    defs = {u.name: u for u in unit_definitions or ()}
    base = getattr(defs.get(unit), "baseUnit", None)
    key = "unit" if source == "stated" else "var"
    whose = f"{entry.var!r} is {'stated' if source == 'stated' else 'declared'} in {unit}"
    try:
        own, angle = _own_unit(unit, base, target), None
        if own:
            a, b = 1.0, 0.0
        else:
            import pint

            quantity(unit, base)
            a, b = _affine(unit, base, target)  # role = a * y + b
            angle = angle_mismatch(unit, target, base)
    except ValueError as exc:
        raise UnitProblem(key, f"{whose}, a unit pint does not know ({exc}); expected a unit convertible to {target} "
                               f"(state the variable's true unit with unit: '...')") from None
    except pint.errors.DimensionalityError:
        if given and quantity(unit, base).dimensionless:
            return Conversion(**common, how="given", scale=scale, offset=offset)
        raise UnitProblem(key, f"{whose}, role {role!r} needs {target}: incompatible units; expected a "
                               f"variable in a unit convertible to {target}, or its true unit stated with "
                               "unit: '...'") from None
    if angle is not None:
        if given and quantity(unit, base).dimensionless:  # e.g. a rotary table's angle in turns, scale given
            return Conversion(**common, how="given", scale=scale, offset=offset)
        raise UnitProblem(key, f"{whose}, role {role!r} needs {target}: {angle}; expected its true unit stated "
                               "with unit: '...', e.g. unit: 'rpm' for revolutions per minute")
    if role in INPUT_ROLES:  # the FMU receives x = (role - b) / a
        a, b = 1.0 / a, -b / a
    # a vendor whose positive direction is the master's negative one (a motor mounted mirrored, an encoder
    # counting down): the units' conversion with the opposite sign, stated by the scale, offset-free
    inverted = (entry.scale is not None and math.isclose(scale, -a, rel_tol=SCALE_RTOL) and b == 0.0
                and offset == 0.0)
    if given and not inverted:
        bad_scale = entry.scale is not None and not math.isclose(scale, a, rel_tol=SCALE_RTOL)
        bad_offset = not math.isclose(offset, b, rel_tol=SCALE_RTOL, abs_tol=SCALE_RTOL * max(1.0, abs(b)))
        if bad_scale or bad_offset:
            what, have, want = ("scale", scale, a) if bad_scale else ("offset", offset, b)
            # as many digits as tell the two apart: a scale copied from `cosim info --map` (x 0.10472) is 2e-6 off
            digits = next(d for d in (6, 8, 10, 12, 17) if f"{have:.{d}g}" != f"{want:.{d}g}")
            close = (f" (agreement to a relative {SCALE_RTOL:g} is asked: state all the digits, or no {what})"
                     if math.isclose(have, want, rel_tol=1e-3) else "")
            raise UnitProblem(what, f"{what} {have:.{digits}g} contradicts the unit of {entry.var!r} ({source} {unit}; "
                                    f"{unit} -> {target} is {'x' if what == 'scale' else '+'} {want:.{digits}g})"
                                    f"{close}; expected no {what} (the units convert), the conversion with the "
                                    f"opposite sign (scale {-a:.{max(digits, 6)}g}: a direction the FMU "
                                    "counts negative), or the variable's true unit stated with unit: '...'")
    return Conversion(**common, how="converted", scale=-a if inverted else a, offset=b, inverted=inverted)


def check_map(md: Any, role_map: Mapping[str, Any], fmu_name: str, kind: str = "linear",
              conversions: dict[str, Conversion] | None = None, elsewhere: Any = (),
              interface: str = "cs") -> list[tuple[tuple, str]]:
    """Problems of a role map against an FMU's model description, as ``(key path, message)`` pairs; the
    units of each entry are checked (``cosim.unit_map.convert``) and, given ``conversions``, filled in.
    ``elsewhere``: roles that FMU components map (a plant split into several FMUs); ``interface``: ``cs`` or
    ``me`` (in Model Exchange an input role needs a continuous input)."""
    from feeddrive.cosim.fmu_inspect import REAL_TYPES

    variables = {v.name: v for v in md.modelVariables}
    problems: list[tuple[tuple, str]] = []
    missing = [r for r in REQUIRED_ROLES if r not in role_map and r not in elsewhere]
    if missing:
        problems.append((("plant", "map"), f"roles {', '.join(missing)} are not mapped; expected entries "
                         f"{{role: {{var: <FMU variable>}}}} for {', '.join(REQUIRED_ROLES)}"))
    for role, entry in role_map.items():
        v = variables.get(entry.var)
        path = ("plant", "map", role, "var")
        want = "input" if role in INPUT_ROLES else "output"
        candidates = [n for n, x in variables.items() if x.causality == want and x.type in REAL_TYPES]
        if v is None:
            problems.append((path, f"FMU {fmu_name!r} has no variable {entry.var!r}; its Real {want}s are: "
                             f"{', '.join(candidates) or 'none'}"))
        elif v.type not in REAL_TYPES:
            problems.append((path, f"{entry.var!r} is a {v.type} variable; expected a Real (FMI 3.0: Float64)"))
        elif getattr(v, "dimensions", None):  # the run failed setting it: "could not convert string to float: '1 2 3'"
            problems.append((path, f"{entry.var!r} is an array variable (FMI 3.0 Dimension); role {role!r} needs a "
                                   f"scalar: expected a scalar Float64 {want} (or the array in an FMU component, "
                                   "whose ports are its elements)"))
        elif role in INPUT_ROLES and v.causality != "input":
            problems.append((path, f"{entry.var!r} has causality {v.causality!r}; role {role!r} needs an input"))
        elif role in INPUT_ROLES and interface == "me" and v.variability == "discrete":
            # the FMU refused it at the first step (fmi3SetFloat64: only in initialization or event mode)
            problems.append((path, f"{entry.var!r} is a discrete input: in Model Exchange it may change only in "
                                   "event mode, which the master does not enter for an input; expected a continuous "
                                   "input, or interface: cs"))
        elif role not in INPUT_ROLES and v.causality not in ("output", "local"):
            problems.append((path, f"{entry.var!r} has causality {v.causality!r}; role {role!r} needs an output"))
        else:
            try:
                conv = convert(role, entry, v, md.unitDefinitions, kind)
            except UnitProblem as exc:
                problems.append((("plant", "map", role, exc.key), f"{fmu_name}: {exc}"))
                continue
            if conversions is not None:
                conversions[role] = conv
    return problems
