"""A plant FMU that is not there says the command that builds it (``plant.build``), runnable from anywhere.

examples/vendor_axis_10mm.yaml's FMU is not committed: ``cosim run`` said "FMU file not found" and where it looked,
and the command that builds it (with ``--pitch 0.01``: the default one builds the 20 mm FMU, which the scenario then
refuses) was only in the file's comments.
"""
from __future__ import annotations

import shlex
from pathlib import Path

import pytest
import yaml

from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.scenario import load_scenario

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
MISSING = "name: m\nstep: 1.0e-4\nplant:\n  fmu: drives/Axis.fmu\n{build}nc:\n  program:\n    - dwell: {{time: 0.1}}\n"


def error_of(path: Path) -> str:
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    return str(info.value)


def test_a_missing_fmu_with_its_build_command_says_how_to_build_it_from_the_scenario_folder(tmp_path):
    folder = tmp_path / "my scenarios"  # a space: the folder is quoted for the shell
    folder.mkdir()
    path = folder / "axis.yaml"
    path.write_text(MISSING.format(build="  build: python make_axis.py --out drives/Axis.fmu\n"))
    message = error_of(path)
    assert message.startswith(f"{path}:4: plant.fmu: FMU file not found: {folder / 'drives' / 'Axis.fmu'}; ")
    assert message.endswith(f"build it first: (cd {shlex.quote(str(folder))} && python make_axis.py --out "
                            f"drives/Axis.fmu) (plant.build)")
    path.write_text(MISSING.format(build=""))  # without it: where it looked, and the key that would say how
    assert "plant.build states the command that builds it" in error_of(path)


@pytest.mark.parametrize("name", ["vendor_axis_10mm.yaml", "vendor_fmu.yaml", "campaign_check_vendor.yaml"])
def test_every_example_whose_fmu_is_not_committed_states_its_build_command(name):
    doc = yaml.safe_load((EXAMPLES / name).read_text())
    plant = (doc.get("base") or doc)["plant"]
    script, *args = shlex.split(plant["build"])[1:]
    assert (EXAMPLES / script).is_file()
    out = args[args.index("--out") + 1] if "--out" in args else str(Path(script).with_name("VendorDrive.fmu"))
    assert out == plant["fmu"]  # the command builds the file the scenario names
    assert ("--pitch" in args) == ("pitch: 0.01" in (EXAMPLES / name).read_text())
