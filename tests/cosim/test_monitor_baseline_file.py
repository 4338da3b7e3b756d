"""``monitor.baseline: FILE``: a stated healthy baseline, a JSON/YAML of parameter values or a history
database (and ``baseline_axis``) to learn it from, besides ``motions`` and ``nominal``.

examples/worn_axis.yaml (Cd +50 %, ft +75 %) is diagnosed against both: the healthy values in a JSON file
given by a path relative to the scenario, and the first healthy motion of axis X of the history that
examples/tool_change.yaml wrote. Bad files give one line naming ``monitor.baseline``.
"""
from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from feeddrive.cosim.cli.run import history_line
from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import scenario_from_dict

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
HEALTHY = {"R": 0.6, "L": 0.004, "K": 1.05, "Jt": 0.1, "ft": 0.02, "Cd": 1.2}
WEAR = {"bearing or slide-way wear", "lack or ageing of lubricating oil"}


def scenario(name: str, **monitor) -> dict:
    data = yaml.safe_load((EXAMPLES / name).read_text())
    data["monitor"] = {k: v for k, v in (data.get("monitor") or {}).items() if k != "baseline"} | monitor
    return data


def assert_worn(report: dict, baseline: dict[str, float]) -> None:
    (m,) = report["motions"]
    assert m["validated"] and m["verdict"] == "diagnosed" and {d["fault"] for d in m["diagnosis"]} == WEAR
    for d in m["diagnosis"]:
        assert d["parameters"] == ["Cd", "ft"]
        for ev, truth in zip(d["evidence"], (1.8 / 1.2 - 1, 0.035 / 0.02 - 1)):
            assert ev["baseline"] == pytest.approx(baseline[ev["parameter"]], rel=0.02)
            assert ev["relative_change"] == pytest.approx(truth, abs=0.05), ev


def test_worn_axis_is_diagnosed_against_a_stated_file_and_a_learnt_history(tmp_path):
    (tmp_path / "healthy.json").write_text(json.dumps({"parameters": HEALTHY | {"Cd": {"value": 1.2, "std": 0.0}}}))
    data = scenario("worn_axis.yaml", baseline="healthy.json", db=":memory:")
    run = run_scenario(scenario_from_dict(data, base_dir=tmp_path), tmp_path / "json", plots=False)
    assert_worn(run.report, HEALTHY)
    monitor = run.report["components"]["monitor"]
    assert history_line(monitor).endswith(f"healthy baseline: stated in {tmp_path / 'healthy.json'} (monitor.baseline)")

    db = tmp_path / "h.sqlite"
    healthy = run_scenario(scenario_from_dict(scenario("tool_change.yaml", db=str(db)), base_dir=EXAMPLES),
                           tmp_path / "healthy", plots=False)
    (first,) = healthy.report["motions"]
    assert first["validated"] and first["diagnosis"] == []
    learnt = {k: p["value"] for k, p in first["parameters"].items()}
    data = scenario("worn_axis.yaml", baseline=str(db), baseline_axis="X", db=":memory:")
    run = run_scenario(scenario_from_dict(data, base_dir=tmp_path), tmp_path / "db", plots=False)
    assert_worn(run.report, learnt)


@pytest.mark.parametrize("content, expected", [
    (None, "no such file"),
    ('{"Cd": 1.2, "mu": 3}', "unknown parameter 'mu'"),
    ('{"Cd": "high"}', "Cd: expected a finite number or {value, std >= 0}"),
    ("[1, 2", "not a readable JSON/YAML parameter file"),
])
def test_a_bad_baseline_file_is_one_line_naming_the_key(tmp_path, content, expected):
    if content is not None:
        (tmp_path / "b.json").write_text(content)
    with pytest.raises(ScenarioError) as exc:
        scenario_from_dict(scenario("worn_axis.yaml", baseline="b.json"), base_dir=tmp_path)
    msg = str(exc.value)
    assert "monitor.baseline" in msg and expected in msg and "\n" not in msg, msg
