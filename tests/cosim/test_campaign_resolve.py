"""A campaign's runs that differ by their sensors' seed alone are resolved from one seedless scenario
(cosim/campaign/cosim_run.py ``_template``): the scenario each run gets must be the one its own mapping resolves to."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from feeddrive.cosim.campaign import cosim_run, expand, load_campaign
from feeddrive.cosim.campaign.schema import RunSpec
from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.scenario import scenario_from_dict

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.mark.parametrize("name", ["campaign_sensor.yaml", "campaign_pmsm.yaml"])
def test_a_run_resolved_from_its_seedless_scenario_is_the_one_its_mapping_gives(name, monkeypatch):
    campaign = load_campaign(EXAMPLES / name)
    specs = expand(campaign)[:4] + expand(campaign)[-2:]  # two grid points at least, two seeds each
    monkeypatch.setattr(cosim_run, "_RESOLVED", {})
    monkeypatch.setattr(cosim_run, "_TEMPLATES", {})
    calls = []
    real = cosim_run._from_dict
    monkeypatch.setattr(cosim_run, "_from_dict", lambda spec, data: calls.append(spec.id) or real(spec, data))
    for spec in specs:
        cosim_run.run_cosim.validate(spec)
        got = cosim_run._scenario(spec)
        direct = scenario_from_dict(spec.scenario, source="scenario", base_dir=spec.base_dir)
        assert got == direct  # the fields, the private attributes (conversions, base dir, source)
        assert got.model_dump() == direct.model_dump()
        assert got.sensors.seed == spec.seed != 0 and "seed" in got.sensors.model_fields_set
    points = {json.dumps(s.overrides, sort_keys=True) for s in specs}
    shared = "pmsm" not in name  # the servo sensors of a PMSM axis take the seed: its runs are resolved one by one
    assert len(calls) == len(points) + (0 if shared else len(specs))  # one resolution a grid point, whatever its seeds


def test_a_seed_the_sensors_would_refuse_is_resolved_as_given_and_refused():
    base = load_campaign(EXAMPLES / "campaign_noise.yaml").base_scenario()
    for bad, message in ((True, "seed"), (-3, "seed")):
        scenario = base | {"sensors": dict(base.get("sensors", {}), seed=bad)}
        spec = RunSpec("00000-bad", 0, 0, {}, scenario, str(EXAMPLES), None, {})
        assert cosim_run._template(spec) is None
        with pytest.raises(ScenarioError, match=message) as caught:
            cosim_run.run_cosim.validate(spec)
        assert str(caught.value).startswith("campaign run 00000-bad {}: ")
