"""The exported system run by OSP libcosim (a second, independent master) against ``cosim run``."""
from __future__ import annotations

import json
import sqlite3

import pytest

pytest.importorskip("libcosimpy")
pytest.importorskip("pythonfmu")

from export_helpers import HERE, scenario  # noqa: E402

from feeddrive.cosim.export.libcosim import run_osp_isolated as run_osp  # noqa: E402
from feeddrive.cosim.export.slave import FAULT_SENSORS, PARAMETERS  # noqa: E402
from feeddrive.cosim.export.system import export_system, stop_time  # noqa: E402

TRUTH = {"R": 0.6, "L": 4.0e-3, "K": 1.05, "Jt": 0.1, "ft": 0.02, "Cd": 1.2}
OUTPUTS = ["validated", "motions", "mismatch", "diagnosis"] + [f"fault_{s}" for s in FAULT_SENSORS]


def observe() -> dict[str, list[str]]:
    return {"monitor": list(PARAMETERS) + [f"{p}_std" for p in PARAMETERS] + OUTPUTS, "plant": ["x"]}


@pytest.fixture(scope="module")
def osp_healthy(healthy_system, tmp_path_factory):
    s, paths = healthy_system
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("TMPDIR", str(tmp_path_factory.mktemp("libcosim_unpack")))  # libcosim unpacks FMUs there
        return run_osp(paths["system"].parent, stop_time(s), observe())


def test_monitor_fmu_under_libcosim_validates_the_parameters_of_cosim_run(osp_healthy, healthy_system,
                                                                           healthy_zoh_run):
    s, paths = healthy_system
    v = osp_healthy.values
    assert osp_healthy.steps == round(stop_time(s) / s.step)
    assert v["monitor.validated"] == 1 and v["monitor.motions"] == 1
    assert v["monitor.mismatch"] == 0 and v["monitor.diagnosis"] == 0
    assert all(v[f"monitor.fault_{f}"] == 0 for f in FAULT_SENSORS)
    assert abs(v["plant.x"]) < 1e-5  # the tool change came back to 0 under the exported NC's position loop
    (reference,) = healthy_zoh_run.report["motions"]
    for p in PARAMETERS:
        ref = reference["parameters"][p]
        lo, hi = ref["ci95"]
        assert lo <= v[f"monitor.{p}"] <= hi, (p, v[f"monitor.{p}"], ref)
        assert v[f"monitor.{p}_std"] == pytest.approx(ref["std"], rel=0.15)
        assert v[f"monitor.{p}"] == pytest.approx(TRUTH[p], rel=5e-3)
    # the history and the report.json-style file beside it hold the same motion
    db = paths["system"].parent / "history.sqlite"
    report = json.loads(db.with_suffix(".report.json").read_text())
    (motion,) = report["motions"]
    assert motion["validated"] is True
    assert motion["parameters"]["R"]["value"] == v["monitor.R"]
    with sqlite3.connect(db) as con:
        assert con.execute("select count(*) from motions").fetchone()[0] == 1


def test_what_the_osp_hold_costs_is_the_zoh_bias_of_r_and_l(osp_healthy):
    """OSP masters hold the speed reference over each step: R and L come out 0.1-0.4 % low (README)."""
    v = osp_healthy.values
    for p in ("R", "L"):
        assert -4e-3 < v[f"monitor.{p}"] / TRUTH[p] - 1 < -1e-3


def test_sensor_fault_event_from_the_osp_scenario_flags_the_first_current_sensor(feeddrive_fmu, tmp_path,
                                                                                 monkeypatch):
    s = scenario(HERE / "sensor_fault_short.yaml", db=str(tmp_path / "history.sqlite"))
    paths = export_system(s, tmp_path / "system", ssp=False)
    events = json.loads(paths["scenario"].read_text())["events"]
    assert {(e["model"], e["variable"], e["value"]) for e in events} == {("sensors", "Im1.gain", 1.03),
                                                                         ("sensors", "Im1.offset", 0.2)}
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    v = run_osp(paths["system"].parent, stop_time(s), observe()).values
    assert v["monitor.motions"] == 1
    assert v["monitor.fault_Im1"] == 1
    assert all(v[f"monitor.fault_{f}"] == 0 for f in FAULT_SENSORS if f != "Im1")
    (motion,) = json.loads((tmp_path / "history.report.json").read_text())["motions"]
    (fault,) = motion["sensor_faults"]
    assert fault["gain"] == pytest.approx(1.03, abs=3e-3) and fault["offset"] == pytest.approx(0.2, abs=0.03)


def test_the_ssp_archive_runs_like_the_osp_system(healthy_system, tmp_path, monkeypatch):
    """libcosim reads the SSP archive into the same system: identical signals after 0.3 s (the motion's start)."""
    _, paths = healthy_system
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    watch = {"plant": ["x", "i"], "sensors": ["Im1", "w_enc"], "nc": ["speed_ref"]}
    osp = run_osp(paths["system"].parent, 0.3, watch)
    ssp = run_osp(paths["system"].parent, 0.3, watch, ssp=True)
    assert osp.values == ssp.values
    assert abs(osp.values["plant.x"]) > 1e-3  # the axis is moving: the connections carry the NC's reference
