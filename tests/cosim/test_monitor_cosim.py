"""The monitor inside whole co-simulations (plant FMU + NC + sensors + monitor), ~4 s each."""
from __future__ import annotations

import json

import pytest

from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import scenario_from_dict
from feeddrive.estimator.history import History

pytestmark = pytest.mark.slow


def scenario(name, db, program, events=(), monitor=None, stop_time=None, sensors=None):
    data = {"name": name, "axis": "X", "step": 1e-4, "plant": {"fmu": "builtin"},
            "sensors": {"seed": 4, **(sensors or {})},
            "nc": {"program": program, "identification": {"distance": 0.2}},
            "monitor": {**({"db": str(db)} if db else {}), **(monitor or {})}, "events": list(events)}
    if stop_time:
        data["stop_time"] = stop_time
    return scenario_from_dict(data)


TOOL_CHANGE = [{"dwell": {"time": 0.1}}, {"tool_change": {"position": 0.27, "v_max": 0.22, "accel": 0.6, "time": 0.3}}]


def test_two_runs_on_the_same_database_continue(tmp_path, feeddrive_fmu):
    """Run 1 healthy; run 2 with a current-sensor fault isolates it with run 1's validated R, L, K.

    Neither scenario names a history file: ``default_history`` (what ``cosim run`` passes) is used."""
    db = tmp_path / "history.sqlite"
    first = run_scenario(scenario("healthy", None, TOOL_CHANGE), tmp_path / "run1", plots=False,
                         default_history=db)
    (m1,) = first.report["motions"]
    assert m1["validated"] and m1["reference"] == "nominal" and m1["sensor_faults"] == []
    for name, truth in (("K", 1.05), ("Jt", 0.1), ("Cd", 1.2)):
        assert m1["parameters"][name]["value"] == pytest.approx(truth, rel=0.02), name
    faulty = scenario("im1-fault", None, TOOL_CHANGE,
                      sensors={"current": [{"gain": 1.03, "offset": 0.2}, {}]})
    second = run_scenario(faulty, tmp_path / "run2", plots=False, default_history=db)
    (m2,) = second.report["motions"]
    assert m2["reference"] == "last validated" and m2["validated"]
    (fault,) = m2["sensor_faults"]
    assert fault["sensor"] == "Im1" and fault["kind"] == "gain+offset"
    assert fault["gain"] == pytest.approx(1.03, abs=0.005) and fault["offset"] == pytest.approx(0.2, abs=0.04)
    assert m2["residues"]["current"]["trusted"] == "Im2"
    assert m2["gain_ratio"] == pytest.approx(1.03, abs=0.003)  # eq. 12 on the filtered currents
    with History(db) as h:
        assert [(m["scenario"], m["motion"]) for m in h.motions("X")] == [("healthy", 1), ("im1-fault", 1)]
    report = json.loads((tmp_path / "run2" / "report.json").read_text())
    assert report["components"]["monitor"]["motions"][0]["sensor_faults"][0]["sensor"] == "Im1"


def test_identification_request_makes_the_nc_insert_a_motion(tmp_path, feeddrive_fmu):
    """A short rapid (too short to identify) -> request -> the NC's identification motion is validated."""
    program = [{"dwell": {"time": 0.1}}, {"rapid": {"to": 0.03, "v_max": 0.22, "accel": 0.6}}]
    run = run_scenario(scenario("request", tmp_path / "h.sqlite", program, monitor={"max_motions": 0},
                                stop_time=3.6), tmp_path / "run", plots=False)
    first, second = run.report["motions"]
    assert not first["validated"] and "shorter than min_motion_s" in first["error"]
    assert second["validated"] and second["end"] - second["start"] > 2.0
    request = run.signals["monitor.request"]
    state = run.signals["nc.state"]
    rise = int((request > 0.5).argmax())
    assert state[rise - 1] == 1 and state[rise] == 0  # raised as soon as the short motion ended
    assert request[-1] == 0.0  # the identification is fresh again
