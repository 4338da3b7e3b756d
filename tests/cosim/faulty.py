"""A misbehaving test FMU compiled from tests/cosim/data/faulty.c with the system C compiler, and
variants of its archive that are not valid FMUs (for the bad-input battery)."""
from __future__ import annotations

import subprocess
import tempfile
import zipfile
from pathlib import Path

import fmpy

from feeddrive.fmu_build.build import CFLAGS, FMI_HEADERS, compiler

SOURCE = Path(__file__).parent / "data" / "faulty.c"
#: the FMU's `mode` parameter
MODES = {"none": 0, "segfault": 1, "abort": 2, "loop": 3, "error": 4, "discard": 5, "fatal": 6, "nan": 7}
GUID = "{8c4e810f-3df3-4a00-8276-176fa3c9f710}"

_VARIABLES = [("w_ref", "input", "continuous", "rad/s", "0"), ("Tl", "input", "continuous", "N.m", "0"),
              ("u", "output", "continuous", "V", None), ("i", "output", "continuous", "A", None),
              ("w", "output", "continuous", "rad/s", None), ("x", "output", "continuous", "m", None),
              ("mode", "parameter", "fixed", "", "0"), ("fail_time", "parameter", "fixed", "s", "0.5")]

#: the scenario's plant.map for this FMU
MAP = {"speed_ref": {"var": "w_ref"}, "load": {"var": "Tl"}, "voltage": {"var": "u"}, "current": {"var": "i"},
       "speed": {"var": "w"}, "position": {"var": "x"}}


def model_description(fmi_version: str = "2.0") -> str:
    rows = []
    for vr, (name, causality, variability, unit, start) in enumerate(_VARIABLES):
        initial = ' initial="exact"' if causality == "output" else ""
        start_attr = f' start="{start if start is not None else 0}"'
        unit_attr = f' unit="{unit}"' if unit else ""
        rows.append(f'    <ScalarVariable name="{name}" valueReference="{vr}" causality="{causality}" '
                    f'variability="{variability}"{initial}><Real{unit_attr}{start_attr}/></ScalarVariable>')
    outputs = "".join(f'<Unknown index="{k + 1}"/>' for k, v in enumerate(_VARIABLES) if v[1] == "output")
    units = "".join(f'<Unit name="{u}"/>' for u in sorted({v[3] for v in _VARIABLES if v[3]}))
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<fmiModelDescription fmiVersion="{fmi_version}" '
            f'modelName="Faulty" guid="{GUID}" numberOfEventIndicators="0">\n'
            '  <CoSimulation modelIdentifier="faulty" canHandleVariableCommunicationStepSize="true"/>\n'
            f"  <UnitDefinitions>{units}</UnitDefinitions>\n  <ModelVariables>\n" + "\n".join(rows) +
            f"\n  </ModelVariables>\n  <ModelStructure><Outputs>{outputs}</Outputs></ModelStructure>\n"
            "</fmiModelDescription>\n")


def compile_library(workdir: Path) -> Path:
    library = workdir / f"faulty{fmpy.sharedLibraryExtension}"
    subprocess.run([*compiler(), *CFLAGS, "-fvisibility=default", f"-I{FMI_HEADERS}", "-o", str(library),
                    str(SOURCE), "-lm"], check=True, capture_output=True)
    return library


def build(out: Path, *, fmi_version: str = "2.0", platform: str | None = None, description: bool = True,
          extra: dict[str, bytes] | None = None, library: Path | None = None) -> Path:
    """Pack the FMU (or a broken variant of it) into ``out``; compiles the library unless given."""
    with tempfile.TemporaryDirectory() as tmp:
        library = library or compile_library(Path(tmp))
        with zipfile.ZipFile(out, "w") as z:
            if description:
                z.writestr("modelDescription.xml", model_description(fmi_version))
            z.write(library, f"binaries/{platform or fmpy.platform}/{library.name}")
            for name, data in (extra or {}).items():
                z.writestr(name, data)
    return out
