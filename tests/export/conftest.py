"""Shared fixtures of the export tests: the healthy example run by ``cosim run`` and exported as an OSP system.

The reference run holds the plant's input over each step (``input_hold: zoh``), as every OSP master does
(no fmi2SetRealInputDerivatives): the exported system and the reference then describe the same
co-simulation, and what the foh hold adds is measured separately (test_libcosim.py).
"""
from __future__ import annotations

import pytest
from export_helpers import EXAMPLES, scenario

from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import scenario_from_dict
from feeddrive.cosim.yaml_source import read_yaml


@pytest.fixture(scope="session")
def healthy_zoh_run(feeddrive_fmu, tmp_path_factory):
    """``cosim run`` of examples/tool_change.yaml with the plant holding its inputs (zoh), no plots."""
    data, lines = read_yaml(EXAMPLES / "tool_change.yaml")
    data["plant"] = dict(data["plant"]) | {"input_hold": "zoh"}
    data["monitor"] = {"db": ":memory:"}
    s = scenario_from_dict(data, source="tool_change.yaml (zoh)", base_dir=EXAMPLES, lines=lines)
    return run_scenario(s, tmp_path_factory.mktemp("zoh_run"), plots=False)


@pytest.fixture(scope="session")
def healthy_system(feeddrive_fmu, tmp_path_factory):
    """examples/tool_change.yaml exported by ``export_system``, its monitor's history in the same folder."""
    from feeddrive.cosim.export.system import export_system

    out = tmp_path_factory.mktemp("healthy_system")
    s = scenario(EXAMPLES / "tool_change.yaml", db=str(out / "history.sqlite"))
    return s, export_system(s, out)
