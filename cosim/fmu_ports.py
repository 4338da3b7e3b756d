"""An FMU's ports as the master sees them: which variables, in which order, how many values, which unit.

Both FMI versions: the Real variables of FMI 2.0 and the Float64 variables of FMI 3.0 are the fast path
(one get / set of a value-reference array per step). Other numeric outputs (Integer, Boolean, Enumeration
in FMI 2.0; Float32, IntN, UIntN, Boolean, Enumeration in FMI 3.0) are read as floats through fmpy's
typed getters (slower, for FMUs that have them, e.g. a counter). String, Binary and Clock variables
are not ports: the master's signals are floats. FMI 3.0 arrays become one port per element,
``name[k]`` (k from 1, row-major as FMI 3.0 stores them); their size is fixed by the dimensions' start
values or the structural parameters they name.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

#: the types read and written through the fast path (fmi2GetReal / fmi3GetFloat64)
REAL_TYPES = ("Real", "Float64")
#: other types whose values are numbers the master can carry as floats
OTHER_NUMERIC = ("Integer", "Enumeration", "Boolean", "Float32", "Int8", "UInt8", "Int16", "UInt16", "Int32",
                 "UInt32", "Int64", "UInt64")


@dataclass(frozen=True)
class Var:
    """One FMU variable behind one or more ports."""

    name: str
    vr: int
    type: str
    size: int
    unit: str
    variability: str

    def ports(self) -> list[str]:
        """Port names: the variable's name, or ``name[k]`` for each element of an array."""
        if self.size == 1 and not self.is_array:
            return [self.name]
        return [f"{self.name}[{k}]" for k in range(1, self.size + 1)]

    @property
    def is_array(self) -> bool:
        return self.size != 1 or self._array

    _array: bool = False


def unit_of(v: Any) -> str:
    """A variable's unit: its own ``unit`` or its declared type's (fmpy keeps them apart)."""
    return v.unit or (getattr(v.declaredType, "unit", None) if v.declaredType is not None else None) or ""


def size_of(v: Any, variables: dict[str, Any]) -> int:
    """Number of values of a variable (1 for a scalar); raises ValueError for an array of unknown size."""
    dims = getattr(v, "dimensions", None) or []
    n = 1
    for d in dims:
        start = d.start
        if start in (None, "") and d.variable is not None:
            start = variables[d.variable.name].start
        try:
            n *= int(start)
        except (TypeError, ValueError):
            raise ValueError(f"the size of array {v.name!r} is not known before the run") from None
    return n


def var(v: Any, variables: dict[str, Any]) -> Var:
    return Var(v.name, v.valueReference, v.type, size_of(v, variables), unit_of(v), v.variability or "",
               bool(getattr(v, "dimensions", None)))


def own_inputs(md: Any, exclude: set[str], interface: str = "cs") -> list[Var]:
    """The FMU's Real / Float64 inputs not in ``exclude`` (those mapped to roles), in declaration order.

    In Model Exchange only the continuous ones: a discrete input may change only in event mode, which the
    master does not enter for an input (a discrete input keeps its start value there)."""
    variables = {v.name: v for v in md.modelVariables}
    return [var(v, variables) for v in md.modelVariables
            if v.causality == "input" and v.type in REAL_TYPES and v.name not in exclude
            and (interface == "cs" or v.variability == "continuous")]


def extra_outputs(md: Any, exclude: set[str]) -> tuple[list[Var], list[Var]]:
    """The FMU's outputs not in ``exclude``: (Real / Float64 ones, other numeric ones)."""
    variables = {v.name: v for v in md.modelVariables}
    outs = [v for v in md.modelVariables if v.causality == "output" and v.name not in exclude]
    return ([var(v, variables) for v in outs if v.type in REAL_TYPES],
            [var(v, variables) for v in outs if v.type in OTHER_NUMERIC])


def other_getter(fmu: Any, fmi3: bool, variables: list[Var]) -> Any:
    """``() -> list of float``: the values of ``variables`` (non-Real numeric outputs), through fmpy's getters."""
    calls = []
    for v in variables:
        if fmi3:
            name = {"Enumeration": "getInt64"}.get(v.type, f"get{v.type}")
            get = getattr(fmu, name)
            calls.append((lambda g=get, vr=v.vr, n=v.size: g([vr], n)))
        else:
            get = fmu.getBoolean if v.type == "Boolean" else fmu.getInteger
            calls.append((lambda g=get, vr=v.vr: g([vr])))

    def read() -> list[float]:
        return [float(x) for call in calls for x in call()]
    return read


def total(variables: list[Var]) -> int:
    return sum(v.size for v in variables)

