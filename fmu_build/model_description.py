"""modelDescription.xml of the generated FMU, in FMI 2.0 or FMI 3.0.

Both versions describe the same variables with the same value references (``codegen.fmu_variables``);
FMI 3.0 adds the independent variable ``time`` after them (value reference ``NR``, read-only) because
the standard requires exactly one. Dependencies come from the structural Jacobian of the CasADi
expressions. FMI 2.0 numbers them by variable index (value reference + 1, since the variables are
listed in value-reference order); FMI 3.0 by value reference.
"""
from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import casadi as ca

from feeddrive.fmu_build.errors import FMUBuildInputError
from feeddrive.models import Model


@dataclass(frozen=True)
class FMUVariable:
    """One real variable of the FMU: value reference ``vr`` is its index in the flat array."""

    vr: int
    name: str
    kind: str  # 's' state, 'i' input, 't' tunable parameter, 'f' fixed parameter, 'c' calculated
    unit: str
    description: str
    causality: str
    variability: str
    start: float | None = None
    lower: float | None = None
    lower_strict: bool = False
    upper: float | None = None
    derivative_of: int | None = None  # value reference of the state, for der() variables



#: Replaced by the GUID (FMI 2.0) or instantiation token (FMI 3.0) once the content hash is known.
GUID_PLACEHOLDER = "@GUID@"
#: The FMI versions the builder writes.
FMI_VERSIONS = (2, 3)


def check_fmi_version(fmi_version: object) -> int:
    """``fmi_version`` as 2 or 3, or ``FMUBuildInputError`` naming the accepted values."""
    if fmi_version not in FMI_VERSIONS or isinstance(fmi_version, bool):
        raise FMUBuildInputError(f"fmi_version must be 2 or 3, got {fmi_version!r}")
    return int(fmi_version)


#: The units models may use, in SI base units: (exponents of kg, m, s, A, K, mol, cd, rad; factor).
#: A table, not pint: every scenario load generates the description (pint would add ~2.5 s to it).
_BASE_NAMES = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")
_UNITS: dict[str, tuple[tuple[int, ...], float]] = {
    "kg": ((1, 0, 0, 0, 0, 0, 0, 0), 1.0), "g": ((1, 0, 0, 0, 0, 0, 0, 0), 1e-3),
    "m": ((0, 1, 0, 0, 0, 0, 0, 0), 1.0), "mm": ((0, 1, 0, 0, 0, 0, 0, 0), 1e-3),
    "um": ((0, 1, 0, 0, 0, 0, 0, 0), 1e-6), "s": ((0, 0, 1, 0, 0, 0, 0, 0), 1.0),
    "ms": ((0, 0, 1, 0, 0, 0, 0, 0), 1e-3), "min": ((0, 0, 1, 0, 0, 0, 0, 0), 60.0),
    "A": ((0, 0, 0, 1, 0, 0, 0, 0), 1.0), "mA": ((0, 0, 0, 1, 0, 0, 0, 0), 1e-3),
    "K": ((0, 0, 0, 0, 1, 0, 0, 0), 1.0), "mol": ((0, 0, 0, 0, 0, 1, 0, 0), 1.0),
    "cd": ((0, 0, 0, 0, 0, 0, 1, 0), 1.0), "rad": ((0, 0, 0, 0, 0, 0, 0, 1), 1.0),
    "deg": ((0, 0, 0, 0, 0, 0, 0, 1), math.pi / 180), "rev": ((0, 0, 0, 0, 0, 0, 0, 1), 2 * math.pi),
    "rpm": ((0, 0, -1, 0, 0, 0, 0, 1), math.pi / 30), "Hz": ((0, 0, -1, 0, 0, 0, 0, 0), 1.0),
    "N": ((1, 1, -2, 0, 0, 0, 0, 0), 1.0), "J": ((1, 2, -2, 0, 0, 0, 0, 0), 1.0),
    "W": ((1, 2, -3, 0, 0, 0, 0, 0), 1.0), "C": ((0, 0, 1, 1, 0, 0, 0, 0), 1.0),
    "V": ((1, 2, -3, -1, 0, 0, 0, 0), 1.0), "Ohm": ((1, 2, -3, -2, 0, 0, 0, 0), 1.0),
    "H": ((1, 2, -2, -2, 0, 0, 0, 0), 1.0), "Wb": ((1, 2, -2, -1, 0, 0, 0, 0), 1.0),
    "F": ((-1, -2, 4, 2, 0, 0, 0, 0), 1.0), "Pa": ((1, -1, -2, 0, 0, 0, 0, 0), 1.0),
}


def base_unit(unit: str) -> dict[str, str]:
    """The ``BaseUnit`` attributes of a model unit: non-zero SI exponents (``kg m s A K mol cd rad``)
    and ``factor`` when not 1. Units are products (``.``) and quotients (``/``, left to right) of the
    names in ``_UNITS`` with optional integer powers (``m2``, ``s-1``) and parentheses: ``N.m.s/rad``,
    ``V/(A.s)``, ``kg.m2``, ``rad/s/s``; ``1`` is dimensionless.

    Raises
    ------
    FMUBuildInputError
        The unit has a name outside the table or does not parse.
    """
    tokens = re.findall(r"[A-Za-z]+-?\d*|[./()]|\S", unit)
    pos = 0

    def fail() -> FMUBuildInputError:
        return FMUBuildInputError(f"unit {unit!r}: expected products and quotients of {', '.join(_UNITS)} "
                                  "with integer powers (e.g. 'N.m', 'rad/s', 'kg.m2', 'V/(A.s)') or '1'")

    def factor() -> tuple[list[int], float]:
        nonlocal pos
        if pos < len(tokens) and tokens[pos] == "(":
            pos += 1
            value = product()
            if pos >= len(tokens) or tokens[pos] != ")":
                raise fail()
            pos += 1
            return value
        if pos < len(tokens) and tokens[pos] == "1":  # 1/s
            pos += 1
            return [0] * len(_BASE_NAMES), 1.0
        m = re.fullmatch(r"([A-Za-z]+)(-?\d*)", tokens[pos]) if pos < len(tokens) else None
        if not m or m.group(1) not in _UNITS:
            raise fail()
        pos += 1
        power = int(m.group(2) or 1)
        exponents, scale = _UNITS[m.group(1)]
        return [power * e for e in exponents], scale ** power

    def product() -> tuple[list[int], float]:
        nonlocal pos
        exponents, scale = factor()
        while pos < len(tokens) and tokens[pos] in "./":
            sign = 1 if tokens[pos] == "." else -1
            pos += 1
            more, more_scale = factor()
            exponents = [a + sign * b for a, b in zip(exponents, more)]
            scale *= more_scale ** sign
        return exponents, scale

    if unit in ("", "1"):
        return {}
    exponents, scale = product()
    if pos != len(tokens):
        raise fail()
    attrs = {name: str(e) for name, e in zip(_BASE_NAMES, exponents) if e}
    if not math.isclose(scale, 1.0, rel_tol=1e-12):
        attrs["factor"] = repr(scale)
    return attrs


def _dependencies(expr: ca.SX, known: ca.SX) -> list[list[int]]:
    """Per row of ``expr``: the 0-based positions in ``known`` it structurally depends on."""
    sp = ca.jacobian(expr, known).sparsity()
    rows, cols = sp.get_triplet()
    deps: list[list[int]] = [[] for _ in range(expr.numel())]
    for r, c in zip(rows, cols):
        deps[r].append(c)
    return [sorted(d) for d in deps]


def _structure(model: Model, variables: list[FMUVariable]):
    """``(outputs, derivatives, initial)``: (vr, dependency vrs) of the outputs and of the der()
    variables, and the vrs of the initial unknowns (calculated outputs and derivatives). States and
    inputs come first in the flat array, so a position in ``[x; u]`` is its value reference."""
    x, u, _ = model.vectors()
    known = ca.vertcat(x, u)
    state_names = [s.name for s in model.states]
    out_deps = dict(zip([o.name for o in model.outputs], _dependencies(model.output_expressions(), known)))
    der_deps = _dependencies(model.state_derivatives(), known)
    outputs = [(v.vr, [state_names.index(v.name)] if v.kind == "s" else out_deps[v.name])
               for v in variables if v.causality == "output"]
    derivatives = [(v.vr, der_deps[v.derivative_of]) for v in variables if v.derivative_of is not None]
    initial = [v.vr for v in variables if v.kind == "c"]
    return outputs, derivatives, initial


def _root(version: str, model: Model, token_key: str, extra: dict[str, str]) -> ET.Element:
    return ET.Element("fmiModelDescription", {
        "fmiVersion": version, "modelName": model.name, token_key: GUID_PLACEHOLDER,
        "description": model.description, "generationTool": f"feeddrive-monitor fmu_build, CasADi {ca.__version__}",
        "variableNamingConvention": "structured", **extra})


def _common(root: ET.Element, variables: list[FMUVariable]) -> None:
    """UnitDefinitions (each unit with its SI base-unit exponents where ``base_unit`` knows it), LogCategories and DefaultExperiment:
    the same elements in both versions."""
    units = ET.SubElement(root, "UnitDefinitions")
    for unit in sorted({v.unit for v in variables}):
        element = ET.SubElement(units, "Unit", {"name": unit})
        try:
            ET.SubElement(element, "BaseUnit", base_unit(unit))
        except FMUBuildInputError:
            pass  # a unit outside the table keeps its name only (valid FMI; the importer reads the name)
    cats = ET.SubElement(root, "LogCategories")
    ET.SubElement(cats, "Category", {"name": "logStatusError",
                                     "description": "rejected input (unknown variable, bad value) and failed steps"})
    ET.SubElement(root, "DefaultExperiment", {"startTime": "0", "stopTime": "1", "stepSize": "0.0001"})


def _attributes(v: FMUVariable) -> dict[str, str]:
    attrs = {"name": v.name, "valueReference": str(v.vr), "description": v.description,
             "causality": v.causality, "variability": v.variability}
    if v.kind != "i":  # inputs take no 'initial'
        attrs["initial"] = "calculated" if v.start is None else "exact"
    return attrs


def _values(v: FMUVariable) -> dict[str, str]:
    real = {"unit": v.unit}
    if v.lower is not None:
        # FMI's min is inclusive: a strict bound (R > 0) is declared as the next double above it (5e-324 for 0), so
        # that the declared range is the one fmu_core's check_value enforces (R = 0 was declared valid, then refused
        # by fmi2SetReal at t = 0: a run failure for a scenario value the reader could have refused)
        real["min"] = repr(math.nextafter(float(v.lower), math.inf) if v.lower_strict else float(v.lower))
    if v.upper is not None:
        real["max"] = repr(float(v.upper))
    if v.start is not None:
        real["start"] = repr(float(v.start))
    return real


def _text(root: ET.Element) -> str:
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _joined(numbers: list[int], offset: int) -> str:
    return " ".join(str(n + offset) for n in numbers)


def xml2(model: Model, variables: list[FMUVariable]) -> str:
    """FMI 2.0 modelDescription.xml (Co-Simulation with input interpolation, and Model Exchange)."""
    root = _root("2.0", model, "guid", {"numberOfEventIndicators": "0"})
    state_ability = {"modelIdentifier": model.name, "canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true"}
    ET.SubElement(root, "ModelExchange", {**state_ability, "completedIntegratorStepNotNeeded": "true"})
    ET.SubElement(root, "CoSimulation", {**state_ability, "canHandleVariableCommunicationStepSize": "true",
                                         "canInterpolateInputs": "true"})
    _common(root, variables)
    mv = ET.SubElement(root, "ModelVariables")
    for v in variables:
        sv = ET.SubElement(mv, "ScalarVariable", _attributes(v))
        real = _values(v)
        if v.derivative_of is not None:
            real = {"unit": v.unit, "derivative": str(v.derivative_of + 1), **real}
        ET.SubElement(sv, "Real", real)
    outputs, derivatives, initial = _structure(model, variables)
    structure = ET.SubElement(root, "ModelStructure")
    for tag, unknowns in (("Outputs", outputs), ("Derivatives", derivatives)):
        block = ET.SubElement(structure, tag)
        for vr, deps in unknowns:
            ET.SubElement(block, "Unknown", {"index": str(vr + 1), "dependencies": _joined(deps, 1)})
    block = ET.SubElement(structure, "InitialUnknowns")
    for vr in initial:
        ET.SubElement(block, "Unknown", {"index": str(vr + 1)})
    return _text(root)


def xml3(model: Model, variables: list[FMUVariable]) -> str:
    """FMI 3.0 modelDescription.xml: Co-Simulation (no event mode, no intermediate update, variable
    step size) and Model Exchange (no event indicators, no completed-step call needed), Float64
    variables with the same value references as FMI 2.0, plus ``time`` (independent)."""
    root = _root("3.0", model, "instantiationToken", {})
    state_ability = {"modelIdentifier": model.name, "canGetAndSetFMUState": "true", "canSerializeFMUState": "true"}
    ET.SubElement(root, "ModelExchange", {**state_ability, "needsCompletedIntegratorStep": "false"})
    ET.SubElement(root, "CoSimulation", {**state_ability, "canHandleVariableCommunicationStepSize": "true",
                                         "hasEventMode": "false", "providesIntermediateUpdate": "false"})
    _common(root, variables)
    mv = ET.SubElement(root, "ModelVariables")
    ET.SubElement(mv, "Float64", {"name": "time", "valueReference": str(len(variables)),
                                  "description": "simulation time", "causality": "independent",
                                  "variability": "continuous", "unit": "s"})
    for v in variables:
        attrs = {**_attributes(v), **_values(v)}
        attrs["description"] = attrs["description"].replace("fmi2DoStep", "fmi3DoStep")
        if v.derivative_of is not None:
            attrs["derivative"] = str(v.derivative_of)
        ET.SubElement(mv, "Float64", attrs)
    outputs, derivatives, initial = _structure(model, variables)
    structure = ET.SubElement(root, "ModelStructure")
    for tag, unknowns in (("Output", outputs), ("ContinuousStateDerivative", derivatives)):
        for vr, deps in unknowns:
            ET.SubElement(structure, tag, {"valueReference": str(vr), "dependencies": _joined(deps, 0)})
    for vr in initial:
        ET.SubElement(structure, "InitialUnknown", {"valueReference": str(vr)})
    return _text(root)
