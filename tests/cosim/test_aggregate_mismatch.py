"""A campaign's detection table counts what the report shows in red: a model mismatch is an alarm on a healthy
run and a detection of a plant fault the model lacks (backlash, which only the model check sees)."""
from __future__ import annotations

from pathlib import Path

from feeddrive.cosim.campaign import load_campaign
from feeddrive.cosim.campaign.aggregate import aggregate
from feeddrive.cosim.campaign.cosim_run import _injected
from feeddrive.cosim.campaign.schema import expand
from feeddrive.cosim.scenario import scenario_from_dict
from feeddrive.models.feed_drive import feed_drive

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def record(index: int, injected: dict, verdicts: list[str]) -> dict:
    motions = [{"validated": v == "healthy", "verdict": v, "sensor_faults": [], "diagnosis": [], "parameters": {},
                "mismatch": {"passed": v != "model mismatch"}} for v in verdicts]
    return {"status": "ok", "index": index, "result": {"truth": {}, "injected": injected, "motions": motions}}


def test_a_model_mismatch_is_a_false_alarm_when_healthy_and_a_detection_of_backlash():
    records = [record(0, {"plant": {}, "sensors": {}}, ["healthy"]),
               record(1, {"plant": {}, "sensors": {}}, ["model mismatch"]),
               record(2, {"plant": {}, "sensors": {}}, ["healthy", "healthy"]),
               record(3, {"plant": {}, "sensors": {}}, ["healthy", "healthy"]),
               record(4, {"plant": {"backlash": 0.02}, "sensors": {}}, ["model mismatch"]),
               record(5, {"plant": {"backlash": 0.02}, "sensors": {}}, ["healthy"])]
    rows = {r["fault_class"]: r for r in aggregate(records).detection}
    assert rows["healthy"]["runs"] == 4 and rows["healthy"]["false_alarm_rate"] == 0.25
    backlash = rows["plant:backlash"]
    # detected by its mismatch, never isolated: no Table I fault names backlash
    assert (backlash["runs"], backlash["detection_rate"], backlash["isolation_rate"]) == (2, 0.5, 0.0)


def test_backlash_is_recorded_as_an_injected_plant_fault():
    """examples/campaign_check_backlash.yaml sweeps plant.parameters.backlash, which the model lacks: it was
    recorded as no fault at all, so its 60 rejected motions were scored as healthy ones."""
    campaign = load_campaign(EXAMPLES / "campaign_check_backlash.yaml")
    model = feed_drive()
    nominal = {k: v for k, v in model.nominal(("physical",)).items() if k in ("R", "L", "K", "Jt", "ft", "Cd")}
    seen = []
    specs = expand(campaign)
    for spec in (specs[0], specs[-1]):  # the sweep is the outer loop: 0.02 rad first, 0.06 rad last
        scenario = scenario_from_dict(spec.scenario, base_dir=spec.base_dir)
        truth = nominal | {k: v for k, v in scenario.plant.parameters.items() if k in nominal}
        seen.append(_injected(scenario, truth, nominal, model.variables))
    # the drive chain's pitch and belt ratio are the model's own (design) parameters: not faults
    assert sorted(s["plant"]["backlash"] for s in seen) == [0.02, 0.06] and all(len(s["plant"]) == 1 for s in seen)
    assert all(s["sensors"] == {} for s in seen)
    healthy = load_campaign(EXAMPLES / "campaign_check_healthy.yaml")
    spec = expand(healthy)[0]
    assert _injected(scenario_from_dict(spec.scenario, base_dir=spec.base_dir), nominal, nominal,
                     model.variables) == {"plant": {}, "sensors": {}}


def test_a_run_whose_axis_did_not_follow_its_nc_is_set_apart():
    """A vendor plant whose position counts the other way ran the table away (report.json ``following``); its
    red motions judge the set-up, not the drive: its own row, out of the false-alarm rate."""
    runaway = record(1, {"plant": {}, "sensors": {}}, ["model mismatch"])
    runaway["result"]["following"] = "the axis did not follow its NC: final position 1.58 m from the target"
    records = [record(0, {"plant": {}, "sensors": {}}, ["healthy"]), runaway,
               record(2, {"plant": {}, "sensors": {}}, ["healthy"])]
    rows = {r["fault_class"]: r for r in aggregate(records).detection}
    assert rows["healthy"]["runs"] == 2 and rows["healthy"]["false_alarm_rate"] == 0.0
    assert rows["(did not follow its NC)"]["runs"] == 1 and rows["(did not follow its NC)"]["false_alarm_rate"] is None


def test_a_held_input_plant_sampled_per_step_is_set_apart():
    """Its model checks reject because of the sampling (report.json ``held_inputs``, cosim/held_inputs.py): its own
    row, out of the false-alarm rate, as a run that did not follow its NC."""
    held = record(1, {"plant": {}, "sensors": {}}, ["model mismatch"])
    held["result"]["held_inputs"] = "motion 1: the model check rejects a plant that holds its inputs over each step"
    records = [record(0, {"plant": {}, "sensors": {}}, ["healthy"]), held]
    rows = {r["fault_class"]: r for r in aggregate(records).detection}
    assert rows["healthy"]["runs"] == 1 and rows["healthy"]["false_alarm_rate"] == 0.0
    assert rows["(held inputs sampled per step)"]["runs"] == 1
    assert rows["(held inputs sampled per step)"]["false_alarm_rate"] is None
