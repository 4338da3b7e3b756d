"""RefAxis: an ideal speed-controlled axis with a vendor's units (rpm, mm), as FMI 2.0 and FMI 3.0 FMUs
(Co-Simulation and Model Exchange) from one C source (ref_axis/model.c), compiled with the system C
compiler against the framework of the Modelica Reference-FMUs (../shared/third_party/Reference-FMUs,
read in place, never copied).

n_act [rpm] = n_set; pos_mm [mm]' = n_set / 60 * pitch_mm; U [V] = 0.11 V/rpm * n_act; I [A] = T_load / 1.05.
"""
from __future__ import annotations

import subprocess
import tempfile
import zipfile
from pathlib import Path

import fmpy
import pytest

from feeddrive.fmu_build.build import compiler

HERE = Path(__file__).parent / "ref_axis"
FRAMEWORK = Path(__file__).resolve().parents[2] / ".." / "shared" / "third_party" / "Reference-FMUs"
TOKEN = "{5b1c9a52-3f4e-4d1a-9a43-0c2d7e8f6a11}"
#: name, value reference, causality, variability, unit, start
VARIABLES = [("n_set", 1, "input", "continuous", "rpm", "0"), ("T_load", 2, "input", "continuous", "N.m", "0"),
             ("n_act", 3, "output", "continuous", "rpm", None), ("pos_mm", 4, "output", "continuous", "mm", "0"),
             ("der(pos_mm)", 5, "local", "continuous", "mm/s", None), ("U", 6, "output", "continuous", "V", None),
             ("I", 7, "output", "continuous", "A", None), ("pitch_mm", 8, "parameter", "tunable", "mm", "20")]
#: the scenario's plant.map: rpm and mm to the roles' rad/s and m
MAP = {"speed_ref": {"var": "n_set", "scale": 30 / 3.141592653589793}, "load": {"var": "T_load"},
       "voltage": {"var": "U"}, "current": {"var": "I"},
       "speed": {"var": "n_act", "scale": 3.141592653589793 / 30}, "position": {"var": "pos_mm", "scale": 1e-3}}


def _initial(causality: str, start: str | None, name: str) -> str:
    if causality == "output":
        return ' initial="exact"' if start is not None else ' initial="calculated"'
    if name.startswith("der("):
        return ' initial="calculated"'
    return ' initial="exact"' if causality == "parameter" else ""


def model_description(version: int) -> str:
    units = "".join(f'<Unit name="{u}"/>' for u in sorted({v[4] for v in VARIABLES}))
    head = (f'<?xml version="1.0" encoding="UTF-8"?>\n<fmiModelDescription fmiVersion="{version}.0" '
            f'modelName="RefAxis" ')
    if version == 3:
        rows = ['<Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>']
        for name, vr, caus, var, unit, start in VARIABLES:
            extra = ' derivative="4"' if name.startswith("der(") else ""
            s = f' start="{start}"' if start is not None else ""
            rows.append(f'<Float64 name="{name}" valueReference="{vr}" causality="{caus}" variability="{var}"'
                        f'{_initial(caus, start, name)} unit="{unit}"{s}{extra}/>')
        outputs = "".join(f'<Output valueReference="{v[1]}"/>' for v in VARIABLES if v[2] == "output")
        return (head + f'instantiationToken="{TOKEN}">\n<ModelExchange modelIdentifier="RefAxis"/>\n'
                '<CoSimulation modelIdentifier="RefAxis" canHandleVariableCommunicationStepSize="true" '
                'fixedInternalStepSize="5e-5"/>\n'
                f'<UnitDefinitions>{units}</UnitDefinitions>\n<ModelVariables>\n' + "\n".join(rows) +
                f'\n</ModelVariables>\n<ModelStructure>{outputs}<ContinuousStateDerivative valueReference="5"/>'
                + "".join(f'<InitialUnknown valueReference="{vr}"/>' for vr in (3, 5, 6, 7)) +
                '</ModelStructure>\n</fmiModelDescription>\n')
    rows = ['<ScalarVariable name="time" valueReference="0" causality="independent" variability="continuous">'
            '<Real/></ScalarVariable>']
    for name, vr, caus, var, unit, start in VARIABLES:
        extra = ' derivative="5"' if name.startswith("der(") else ""
        s = f' start="{start}"' if start is not None else ""
        rows.append(f'<ScalarVariable name="{name}" valueReference="{vr}" causality="{caus}" variability="{var}"'
                    f'{_initial(caus, start, name)}><Real unit="{unit}"{s}{extra}/></ScalarVariable>')
    outputs = "".join(f'<Unknown index="{k + 2}"/>' for k, v in enumerate(VARIABLES) if v[2] == "output")
    return (head + f'guid="{TOKEN}" numberOfEventIndicators="0">\n<ModelExchange modelIdentifier="RefAxis"/>\n'
            '<CoSimulation modelIdentifier="RefAxis" canHandleVariableCommunicationStepSize="true"/>\n'
            f'<UnitDefinitions>{units}</UnitDefinitions>\n<ModelVariables>\n' + "\n".join(rows) +
            f'\n</ModelVariables>\n<ModelStructure><Outputs>{outputs}</Outputs><Derivatives><Unknown index="6"/>'
            '</Derivatives><InitialUnknowns>' + "".join(f'<Unknown index="{i}"/>' for i in (4, 6, 7, 8)) +
            '</InitialUnknowns></ModelStructure>\n</fmiModelDescription>\n')


def build(out: Path, version: int) -> Path:
    """Compile and pack RefAxis as an FMI ``version`` (2 or 3) FMU at ``out``; skips without the framework."""
    return pack(out, version, HERE, "RefAxis", model_description(version))


def pack(out: Path, version: int, source: Path, identifier: str, description: str) -> Path:
    """Compile ``source``/model.c (with its config.h) against the Reference-FMUs framework as an FMI ``version``
    FMU ``identifier`` with ``description`` as modelDescription.xml, at ``out``; skips without the framework."""
    if not (FRAMEWORK / "src" / "cosimulation.c").is_file():
        pytest.skip(f"Reference-FMUs source not found: {FRAMEWORK.resolve()}")
    platform = fmpy.platform_tuple if version == 3 else fmpy.platform
    with tempfile.TemporaryDirectory() as tmp:
        lib = Path(tmp) / f"{identifier}{fmpy.sharedLibraryExtension}"
        subprocess.run([*compiler(), "-O2", "-fPIC", "-shared", f"-DFMI_VERSION={version}", "-DDISABLE_PREFIX",
                        f"-I{FRAMEWORK / 'include'}", f"-I{source}", "-o", str(lib), str(source / "model.c"),
                        str(FRAMEWORK / "src" / f"fmi{version}Functions.c"), str(FRAMEWORK / "src" / "cosimulation.c"),
                        "-lm"], check=True, capture_output=True)
        with zipfile.ZipFile(out, "w") as z:
            z.writestr("modelDescription.xml", description)
            z.write(lib, f"binaries/{platform}/{lib.name}")
    return out
