"""A map entry in its role's own unit converts by 1 without pint's registry (0.8 s of ``cosim run``'s
start-up); a unit of the same name whose FMU BaseUnit says otherwise still goes through pint."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from fmpy.model_description import BaseUnit, ModelVariable, Unit

from feeddrive.cosim import unit_map
from feeddrive.cosim.scenario import MapEntry

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def variable(unit: str) -> ModelVariable:
    v = ModelVariable("w", 1)
    v.unit = unit
    return v


def test_own_unit_is_one_and_a_redefined_unit_is_converted():
    si = Unit("rad/s")
    si.baseUnit = BaseUnit(s=-1, rad=1)
    conv = unit_map.convert("speed", MapEntry(var="w"), variable("rad/s"), [si])
    assert (conv.scale, conv.offset, conv.how) == (1.0, 0.0, "converted")
    # an FMU whose "rad/s" is in fact rpm (factor 2 pi / 60): its BaseUnit wins, pint converts
    rpm = Unit("rad/s")
    rpm.baseUnit = BaseUnit(s=-1, rad=1, factor=0.10471975511965977)
    conv = unit_map.convert("speed", MapEntry(var="w"), variable("rad/s"), [rpm])
    assert abs(conv.scale - 0.10471975511965977) < 1e-15 and conv.offset == 0.0
    assert not unit_map._own_unit("N.m", BaseUnit(kg=1, m=2, s=-2, rad=1), "N.m")


def test_loading_the_readme_scenario_builds_no_unit_registry():
    code = ("import sys; from feeddrive.cosim.scenario import load_scenario; "
            f"load_scenario({str(EXAMPLES / 'tool_change.yaml')!r}); print('pint' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
