"""``monitor.bounds`` in a scenario: checked with the line it is on (issue 22)."""
from __future__ import annotations

import pytest
from test_scenario import BASE, write

from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.scenario import load_scenario
from feeddrive.estimator.physical import bounds_mapping


def test_bounds_mapping_reads_strings_and_pairs():
    assert bounds_mapping({"Jt": "4e-6:", "ft": [0, None]}) == {"Jt": (4e-6, None), "ft": (0.0, None)}


def test_monitor_bounds_are_read_and_bad_ones_located(tmp_path, feeddrive_fmu):
    s = load_scenario(write(tmp_path, BASE + "monitor: {bounds: {Jt: '4e-6:', ft: [0, null]}}\n"))
    assert s.monitor is not None and s.monitor.config.bounds == {"Jt": (4e-6, None), "ft": (0.0, None)}
    with pytest.raises(ScenarioError, match=r"monitor\.bounds") as exc:
        load_scenario(write(tmp_path, BASE + "monitor: {bounds: {Q: '0:1'}}\n"))
    assert "\n" not in str(exc.value) and ".yaml:" in str(exc.value)
