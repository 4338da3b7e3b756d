"""A vendor's FMU as users bring it, with the mistakes they make (audit3): every one refused in one line naming the
file, the key and what was expected (exit 2, before anything is written), or converted right; never a number
taken on trust, never a traceback.

The FMUs are RefAxis (tests/plants/ref_axis.py: rpm, mm, FMI 2.0 and 3.0), built once for the test run, and
copies of it whose modelDescription.xml a test rewrites as a vendor's would read.
"""
from __future__ import annotations

import math
import sys
import zipfile
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "plants"))
from ref_axis import MAP, build  # noqa: E402

from feeddrive.cosim.cli import main  # noqa: E402
from feeddrive.cosim.errors import ScenarioError  # noqa: E402
from feeddrive.cosim.scenario import scenario_from_dict  # noqa: E402

H = 1e-3
PROGRAM = [{"dwell": {"time": 0.05}}, {"tool_change": {"position": 0.02, "v_max": 0.1, "accel": 1.0, "time": 0.05}}]


@pytest.fixture(scope="module")
def fmus(built_once) -> dict[int, Path]:
    """RefAxis as FMI 2.0 and 3.0 (tests/conftest.py built_once: shared with the other modules)."""
    return {2: built_once("RefAxis2", lambda folder: build(folder / "RefAxis2.fmu", 2)),
            3: built_once("RefAxis3", lambda folder: build(folder / "RefAxis3.fmu", 3))}


def rewritten(fmu: Path, out: Path, old: str, new: str) -> Path:
    """A copy of ``fmu`` whose modelDescription.xml has ``old`` replaced by ``new`` (exactly once)."""
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                assert text.count(old) == 1, old
                data = text.replace(old, new).encode()
            dst.writestr(item, data)
    return out


def scenario(fmu: Path, **plant) -> dict:
    return {"name": "vendor", "step": H, "plant": {"fmu": str(fmu), "map": dict(MAP)} | plant,
            "nc": {"program": PROGRAM}}


@pytest.mark.parametrize("version", [2, 3])
def test_a_unit_declared_only_as_display_unit_is_never_taken_on_trust(fmus, tmp_path, version):
    """n_act declared ``displayUnit="rpm"`` and no unit: fmpy's validator failed with KeyError(None) ("invalid
    modelDescription.xml: None"); read as no unit, the rpm would have been taken as rad/s (a false gain 9.549)."""
    bare = _bare(fmus[version], tmp_path / "Bare.fmu")
    speed = {"var": "n_act"}
    with pytest.raises(ScenarioError, match=r"plant\.map\.speed\.var: Bare\.fmu: 'n_act' declares no unit, only the "
                                            r"displayUnit 'rpm' .* expected its true unit stated with unit: '\.\.\.' "
                                            r"\(e\.g\. unit: 'rpm'") as info:
        scenario_from_dict(scenario(bare, map=MAP | {"speed": speed}))
    assert "\n" not in str(info.value)
    s = scenario_from_dict(scenario(bare, map=MAP | {"speed": {"var": "n_act", "unit": "rpm"}}))
    assert s.plant.map["speed"].linear() == (pytest.approx(math.pi / 30, rel=1e-15), 0.0)


def _bare(fmu: Path, out: Path) -> Path:
    """RefAxis with n_act's ``unit="rpm"`` as ``displayUnit="rpm"`` (FMI 3.0: its Float64 element; FMI 2.0: its
    ``<Real/>``, the first element closed after its name)."""
    text = zipfile.ZipFile(fmu).read("modelDescription.xml").decode()
    start = text.index('name="n_act"')
    element = text[start:text.index("/>", start)]
    return rewritten(fmu, out, element, element.replace('unit="rpm"', 'displayUnit="rpm"'))


def test_a_scale_copied_from_cosim_info_says_why_it_is_refused(fmus):
    """``cosim info --map`` prints ``x 0.10472``; copied into the map it was refused as "scale 0.10472 contradicts
    ... rpm -> rad/s is x 0.10472": two equal numbers. The message shows the digits that differ and the tolerance."""
    with pytest.raises(ScenarioError, match=r"plant\.map\.speed\.scale: RefAxis2\.fmu: scale 0\.10472 contradicts the "
                                            r"unit of 'n_act' \(declared rpm; rpm -> rad/s is x 0\.10471976\) "
                                            r"\(agreement to a relative 1e-06 is asked: state all the digits, or no "
                                            r"scale\)"):
        scenario_from_dict(scenario(fmus[2], map=MAP | {"speed": {"var": "n_act", "scale": 0.10472}}))
    # an offset on a current in A: the other sign's conversion is the scale -1, not the offset's "-0"
    with pytest.raises(ScenarioError, match=r"plant\.map\.current\.offset: .*offset 0\.5 contradicts .*\(scale -1: a "
                                            r"direction the FMU counts negative\)"):
        scenario_from_dict(scenario(fmus[2], map=MAP | {"current": {"var": "I", "offset": 0.5}}))


def test_info_map_names_the_display_unit_mistake_in_one_line_exit_2(fmus, tmp_path, capsys):
    import yaml

    bare = _bare(fmus[2], tmp_path / "Bare.fmu")
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(scenario(bare, map=MAP | {"speed": {"var": "n_act"}})))
    assert main(["info", str(bare), "--map", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{path}:" in err and "'n_act' declares no unit, only the displayUnit 'rpm'" in err
    assert main(["info", str(bare)]) == 0  # the FMU itself is listed: nothing wrong with it but that unit
