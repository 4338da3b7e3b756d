"""The Monitor component driven through the Component call order with plant data.

Plant data: the closed-loop CasADi model with redundant sensors of tests/estimator/test_validation.py
(loaded by path: test folders are not packages). Between motions the NC is idle (state 0).
"""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.monitor import MEASUREMENTS, Monitor, MonitorConfig, centred_speed
from feeddrive.estimator.history import History
from feeddrive.models.drives import drive_model

_spec = importlib.util.spec_from_file_location(
    "validation_plant", Path(__file__).parents[1] / "estimator" / "test_validation.py")
plant = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(plant)
H = plant.H
TRUTH = {k: v for k, v in plant.NOMINAL.items() if k in ("R", "L", "K", "Jt", "ft", "Cd")}
NOMINAL = drive_model("dc").nominal(("physical",))
IDLE = 0.05


def motion(seed=1, changes=(), **faults):
    return plant.measure(plant.plant_motion(changes), seed, **faults)


def run(monitor: Monitor, motions: list[dict], idle: float = IDLE) -> list[float]:
    """Feed idle, motion 1, idle, motion 2, ... idle; returns the ``request`` output after every step."""
    gap = int(round(idle / H))
    rows = []
    for k, m in enumerate(motions, start=1):
        rows.append(np.zeros((gap, len(MEASUREMENTS) + 2)))
        n = len(m["Im1"])
        rows.append(np.column_stack([np.asarray(m[s]) for s in MEASUREMENTS] + [np.ones(n), np.full(n, k)]))
    rows.append(np.zeros((gap, len(MEASUREMENTS) + 2)))
    inputs = np.vstack(rows).tolist()
    monitor.setup(0.0, H, len(inputs))
    request = [monitor.get_outputs()[0]]
    for n, values in enumerate(inputs):
        monitor.set_inputs(values)
        monitor.step(n)
        request.append(monitor.get_outputs()[0])
    return request


def new(tmp_path=None, **config) -> Monitor:
    """A monitor of the built-in plant's axis: its design values stated, as a scenario with that plant does."""
    db = {"db": str(tmp_path / "history.sqlite")} if tmp_path is not None else {}
    return Monitor("monitor", MonitorConfig(**db, **({"nominal": NOMINAL} | config)))


def test_healthy_then_sensor_offset(tmp_path):
    mon = new(tmp_path, axis="X1", scenario="unit")
    run(mon, [motion(1), motion(2, Im1=(1.0, 0.3))])
    report = json.loads(json.dumps(mon.report()))  # JSON-serialisable for report.json
    mon.terminate()
    first, second = report["motions"]
    assert [first["motion"], second["motion"]] == [1, 2]
    n = len(motion(1)["Im1"])
    assert first["start"] == pytest.approx(IDLE + H) and first["end"] == pytest.approx(IDLE + n * H)
    assert first["validated"] and first["reference"] == "nominal" and first["sensor_faults"] == []
    for name, truth in TRUTH.items():
        p = first["parameters"][name]
        assert p["value"] == pytest.approx(truth, rel=0.01), name
        assert p["ci95"][0] < p["value"] < p["ci95"][1]
    mm = first["mismatch"]
    assert mm["passed"] is True and mm["p_value"] >= mm["alpha"] == 0.01 and "Bonferroni" in mm["rule"]
    assert first["gain_ratio"] == pytest.approx(1.0, abs=2e-3)
    assert first["processing_s"] > 0 and first["diagnosis"] == []
    # estimated on every 3rd filtered sample: 2 pi 100 Hz (2 h D) <= 0.5 rad at 10 kHz (the decimation's rule)
    assert H == 1e-4 and first["estimation_rate_hz"] == pytest.approx(1e4 / 3)
    # motion 2: Im1 offset isolated against the model with motion 1's validated R, L, K; Im2 trusted
    assert second["reference"] == "last validated" and second["validated"]
    (fault,) = second["sensor_faults"]
    assert fault["sensor"] == "Im1" and fault["kind"] == "offset"
    assert fault["offset"] == pytest.approx(0.3, abs=0.02) and fault["offset_ci95"][0] < 0.3 < fault["offset_ci95"][1]
    assert second["residues"]["current"]["trusted"] == "Im2"
    assert second["parameters"]["R"]["value"] == pytest.approx(TRUTH["R"], rel=0.01)
    with History(tmp_path / "history.sqlite") as h:
        assert [m["motion"] for m in h.motions("X1")] == [1, 2]
        assert h.last_validated("X1")["motion"] == 2


def test_a_second_monitor_continues_from_the_database(tmp_path):
    """theta_{j-1} and the baseline come back from the history: the second run does not start over."""
    first = new(tmp_path, baseline_motions=2)
    run(first, [motion(3)])
    first.terminate()
    second = new(tmp_path, baseline_motions=2)
    run(second, [motion(4), motion(5, changes=(("Jt", 0.07, 0.0),))])
    results = second.report()["motions"]
    second.terminate()
    assert results[0]["reference"] == "last validated"
    assert results[0]["diagnosis"] == [] and "healthy baseline: motion 2 of 2" in results[0]["notes"]
    # the baseline (motion of run 1 + first motion of run 2) is complete: the lighter table is diagnosed
    (diag,) = results[1]["diagnosis"]
    assert diag["fault"] == "missing work-piece or work-piece holder" and diag["parameters"] == ["Jt"]
    (ev,) = diag["evidence"]
    assert ev["relative_change"] == pytest.approx(-0.3, abs=0.01) and ev["z_baseline"] < -10


def test_invalid_measurements_are_never_diagnosed(tmp_path):
    mon = new(tmp_path, baseline="nominal")
    run(mon, [motion(6, Im1=(1.02, 0.2), Im2=(0.96, -0.25), changes=(("Cd", 2.0, 0.0),))])
    (res,) = mon.report()["motions"]
    assert not res["measurements_valid"] and not res["validated"]
    assert {f["sensor"] for f in res["sensor_faults"]} == {"Im1", "Im2"}
    assert res["diagnosis"] == [] and res["parameters"]  # parameters reported, no plant fault claimed
    assert mon.pipeline.last_validated is None
    mon.terminate()


def test_model_mismatch_is_not_validated():
    mon = new()
    run(mon, [motion(7, changes=(("Cd", 2.4, 1.6),))])
    (res,) = mon.report()["motions"]
    assert res["measurements_valid"] and not res["mismatch"]["passed"] and not res["validated"]
    assert any("mismatch" in n for n in res["notes"])


def test_identification_request_by_motions_and_by_age():
    short = {k: v[:3000] for k, v in motion(8).items()}  # 0.3 s: too short to identify
    mon = new(max_motions=1, min_motion_s=1.0)
    request = run(mon, [short, short, motion(8)])
    results = mon.report()["motions"]
    assert [r["validated"] for r in results] == [False, False, True]
    assert "shorter than min_motion_s" in results[0]["error"]
    gap, n_short = int(round(IDLE / H)), 3000
    end2 = 2 * (gap + n_short)  # step at which motion 2 is seen to end
    assert max(request[:end2]) == 0.0 and request[end2 + 1] == 1.0  # 2 motions > max_motions = 1
    assert request[-1] == 0.0  # the identification is fresh again
    # by age: 0.02 s of machine time after the validated motion ended, the request rises
    mon = new(max_age_s=0.02)
    request = run(mon, [motion(9)], idle=0.05)
    n = len(motion(9)["Im1"])
    end = int(round(IDLE / H)) + n  # the step at which the motion's end is seen
    rise = int(np.argmax(np.array(request[end + 1:]) > 0)) + end + 1
    assert rise - end == pytest.approx(0.02 / H, abs=2)


def test_centred_encoder_speed_is_exact_on_a_quadratic_angle_without_delay():
    """theta = a t^2 / 2 + w0 t (constant acceleration a): the centred difference over 2 k h is exactly
    the speed a t + w0; a backward difference over the same window gives the speed k h earlier (delay
    k h = half the window), i.e. low by a k h during the ramp."""
    a, w0, window = 184.0, 3.0, 1e-3
    k = 5  # window / (2 h)
    t = H * np.arange(2000)
    theta = a * t**2 / 2 + w0 * t
    fallback = np.full(t.size, -1.0)
    w = centred_speed(theta, fallback, H, window)
    np.testing.assert_allclose(w[k:-k], a * t[k:-k] + w0, rtol=1e-9)
    np.testing.assert_array_equal(w[:k], fallback[:k])
    np.testing.assert_array_equal(w[-k:], fallback[-k:])
    backward = (theta[2 * k:] - theta[:-2 * k]) / (2 * k * H)  # at sample 2k.., the sensors' w_enc
    np.testing.assert_allclose(backward - (a * t[2 * k:] + w0), -a * k * H, rtol=1e-6)
    # too short for one centred window: the fallback everywhere
    np.testing.assert_array_equal(centred_speed(theta[:2 * k], fallback[:2 * k], H, window), fallback[:2 * k])


def test_config_errors_name_the_key():
    with pytest.raises(ScenarioError, match="^monitor.filter_cutof_hz: unknown key"):
        Monitor("monitor", {"filter_cutof_hz": 50})
    with pytest.raises(ScenarioError, match=r"^monitor.alpha: .*less than 0.5 \(got 0.9\)"):
        Monitor("monitor", {"alpha": 0.9})
    with pytest.raises(ScenarioError, match=r"^monitor.decimation: expected 'auto' or an integer >= 1 .*got 0"):
        Monitor("monitor", {"decimation": 0})


def test_unusable_motion_is_recorded_not_fatal():
    """A motion without speed excitation (standstill: every channel noise only) is stored, saying that there was
    no motion to judge and the threshold (segmentation.at_rest); the next motion is judged as usual. (Its noise
    was estimated from, every parameter but R refused one by one, and R given at 1 because u = i exactly.)"""
    still = {k: np.zeros(15000) + (0.05 * np.random.default_rng(0).standard_normal(15000) if k != "theta_enc" else 0)
             for k in MEASUREMENTS}
    mon = new()
    run(mon, [still, motion(10)])
    first, second = mon.report()["motions"]
    assert not first["validated"] and first["verdict"].startswith("not estimated: no high-speed motion: nothing to "
                                                                   "judge (largest |speed| ")
    assert first["parameters"] == {} and first["refused"] == {}
    assert second["refused"] == {}
    assert second["validated"] and second["reference"] == "nominal"


def test_monitor_plots(tmp_path):
    mon = new(tmp_path)
    run(mon, [motion(11), motion(12, Im2=(1.03, 0.0))])
    mon.terminate()
    paths = mon.write_plots(tmp_path / "plots")
    assert sorted(p.name for p in paths) == ["monitor_correlation1.png", "monitor_correlation2.png",
                                             "monitor_motion1.png", "monitor_motion2.png", "monitor_trends.png"]
    for p in paths:
        height, width = matplotlib.image.imread(p).shape[:2]
        assert width > 600 and height > (250 if "correlation" in p.name else 400)


@pytest.mark.slow
def test_friction_drift_over_12_motions_is_diagnosed_in_time():
    """Cd and ft rise 2 % per motion from motion 5 (plant data, whole pipeline): no alarm while the drift
    is <= 3 %, wear / lubrication from 8 % on (the threshold is 5 %), on each of the last four motions."""
    drift = [max(0, j - 4) * 0.02 for j in range(12)]
    assert sum(d >= 0.08 - 1e-12 for d in drift) == 4 and sum(d <= 0.03 for d in drift) == 6
    motions = [motion(100 + j, changes=(("Cd", 1.2 * (1 + d), 0.0), ("ft", 0.02 * (1 + d), 0.0)))
               for j, d in enumerate(drift)]
    mon = new(baseline_motions=3)
    run(mon, motions)
    results = mon.report()["motions"]
    assert all(r["validated"] for r in results)
    for d, r in zip(drift, results):
        faults = {x["fault"] for x in r["diagnosis"]}
        if d <= 0.03:
            assert faults == set(), (r["motion"], faults)
        elif d >= 0.08 - 1e-12:
            assert faults == {"bearing or slide-way wear", "lack or ageing of lubricating oil"}, r["motion"]
