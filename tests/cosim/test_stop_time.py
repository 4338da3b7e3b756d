"""A stated stop time the master cannot reach in whole steps is refused, naming it (time is an integer count
of steps): 1.0 s at a 0.03 s step ran 1.02 s without a word."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.scenario import load_scenario

EXAMPLE = Path(__file__).parents[2] / "examples" / "tool_change.yaml"


def scenario(tmp_path: Path, **keys) -> Path:
    data = yaml.safe_load(EXAMPLE.read_text()) | keys
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_a_stop_time_between_steps_is_refused_with_the_two_nearest(tmp_path):
    with pytest.raises(ScenarioError, match=r"s.yaml:\d+: stop_time: 4 s is not a whole number of steps of 0.003 s; "
                                            r"expected e.g. 3.999 or 4.002$"):
        load_scenario(scenario(tmp_path, stop_time=4.0, step=0.003))


def test_a_whole_number_of_steps_loads_despite_rounding(tmp_path):
    s = load_scenario(scenario(tmp_path, stop_time=4.2, step=1e-4))  # 4.2 / 1e-4 = 41999.999999999996
    assert s.stop_time == 4.2
