"""Defects of an independent review: each bad input is one line (exit 2) found before anything runs, sensor
events show one sample after their grid point, and the campaign scores the estimator the monitor validates."""
from __future__ import annotations

import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest

from feeddrive.cosim.campaign import Campaign, run_campaign
from feeddrive.cosim.cli import main
from feeddrive.cosim.component import Component
from feeddrive.cosim.errors import DataError, ScenarioError
from feeddrive.cosim.recorded import load_recording
from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import load_scenario, scenario_from_dict
from feeddrive.estimator.history import History

BASE = """\
name: t
step: 1.0e-4
plant: {fmu: builtin}
nc:
  program:
    - rapid: {to: 0.01}
"""


def write(tmp_path: Path, text: str, name: str = "s.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def one_line_error(capsys, argv: list[str]) -> str:
    """Run the CLI, expect exit 2, return its single stderr line."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


class Counter(Component):
    """A user component with no settable parameter: its event target is checked when the event fires."""

    output_names = ("n",)
    output_units = ("1",)

    def setup(self, t0, h, n_steps):
        self.n = 0

    def step(self, n):
        self.n = n + 1

    def get_outputs(self):
        return [float(self.n)]


# -- 1. event targets checked at load time -----------------------------------------------------------------
@pytest.mark.parametrize("event, key, expected", [
    ("{time: 2.9, target: sensors.Im3.gain, value: 1}", "events[0].target",
     "sensors.Im3.gain: expected sensors.<channel>.<field> with channel in Im1, Im2, u, u_ref, w_tach, encoder "
     "and field in gain, offset, noise"),
    ("{time: 0.1, target: sensors.Im1, value: 1}", "events[0].target", "expected sensors.<channel>.<field>"),
    ("{time: 0.1, target: sensors.Im1.gain, value: big}", "events[0].value",
     "expected a finite number for sensors.Im1.gain, got 'big'"),
    ("{time: 0.1, target: sensors.encoder.noise, value: -0.1}", "events[0].value",
     "expected a finite number >= 0 for sensors.encoder.noise, got -0.1"),
    ("{time: 0.1, target: nc.kv, value: 10}", "events[0].target", "'nc' accepts no events"),
    ("{time: 0.1, target: monitor.alpha, value: 0.01}", "events[0].target", "'monitor' accepts no events"),
])
def test_event_targets_are_checked_when_the_file_is_read(tmp_path, feeddrive_fmu, event, key, expected):
    path = write(tmp_path, BASE + "monitor: {}\nevents:\n  - " + event + "\n")
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert str(info.value).startswith(f"{path}:9: {key}: ") and expected in str(info.value)


def test_user_component_event_fails_at_run_time_in_one_line(tmp_path, feeddrive_fmu, capsys):
    path = write(tmp_path, BASE + "stop_time: 0.002\ncomponents:\n  - {name: cnt, class: 'test_robustness:Counter'}\n"
                 "events:\n  - {time: 0.001, target: cnt.gain, value: 2}\n")
    assert load_scenario(path).events[0].target == "cnt.gain"  # a user component is only known when it runs
    err = one_line_error(capsys, ["run", str(path), "--out", str(tmp_path / "out")])
    assert "component 'cnt' has no parameter 'gain' that events can change" in err


# -- 2. a sensor event at t_n shows in the sample at t_(n+1) -------------------------------------------------
def test_sensor_event_shows_one_sample_after_its_grid_point(tmp_path, feeddrive_fmu):
    h, n_event = 1e-4, 10
    s = scenario_from_dict({"name": "ev", "step": h, "stop_time": 20 * h, "plant": {"fmu": "builtin"},
                            "sensors": {"current": [{"noise": 0}, {"noise": 0}]},
                            "nc": {"program": [{"dwell": {"time": 0.01}}]},
                            "events": [{"time": n_event * h, "target": "sensors.Im1.offset", "value": 0.25}]},
                           base_dir=tmp_path)
    res = run_scenario(s, tmp_path / "out", plots=False)
    d = res.signals["sensors.Im1"] - res.signals["sensors.Im2"]
    # the sample at t_n was measured in step n-1, before the event applied at t_n
    assert np.all(d[:n_event + 1] == 0) and np.allclose(d[n_event + 1:], 0.25, rtol=0, atol=1e-12)


# -- 3. recordings: byte-order mark and non-UTF-8 files -------------------------------------------------------
def _csv(path: Path, header: str, encoding: str, extra: str = "") -> Path:
    rows = "".join(f"{k * 1e-3:.3f},{np.sin(k):.6f}\n" for k in range(20))
    path.write_bytes((f"{header}\n{rows}{extra}").encode(encoding))
    return path


def test_utf8_bom_does_not_hide_the_first_column(tmp_path):
    rec = load_recording(_csv(tmp_path / "bom.csv", "time,u [V]", "utf-8-sig"), {"time": "time", "voltage": "u"})
    assert rec.h == pytest.approx(1e-3) and rec.columns == {"voltage": "u [V]"}
    assert rec.signals["voltage"][3] == pytest.approx(np.sin(3), abs=1e-6)


def test_non_utf8_csv_is_one_data_error_naming_file_and_line(tmp_path, capsys):
    path = _csv(tmp_path / "latin.csv", "time,u", "latin-1", extra="0.020,\u00b5\n")
    with pytest.raises(DataError, match=rf"^{path}: line 22: byte 0xb5 is not UTF-8; expected a UTF-8 CSV file$"):
        load_recording(path, {"time": "time", "voltage": "u"})
    err = one_line_error(capsys, ["estimate", str(path), "--map", "time=time", "--map", "voltage=u"])
    assert f"{path}: line 22" in err


# -- 4. an FMU whose modelDescription.xml fails fmpy's validation ----------------------------------------------
@pytest.fixture
def bad_fmu(tmp_path, feeddrive_fmu) -> Path:
    """The built-in FMU with one output's causality misspelt (refused by the FMI 2.0 schema)."""
    path = tmp_path / "bad.fmu"
    with zipfile.ZipFile(feeddrive_fmu) as z, zipfile.ZipFile(path, "w") as out:
        for item in z.infolist():
            data = z.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = data.replace(b'causality="output"', b'causality="outptu"', 1)
            out.writestr(item, data)
    return path


def test_invalid_model_description_is_one_line(tmp_path, bad_fmu, capsys):
    err = one_line_error(capsys, ["info", str(bad_fmu)])
    assert err.startswith(f"cosim info: error: {bad_fmu}: invalid modelDescription.xml: ERROR (line ")
    assert "'outptu' is not an element of the set" in err
    scenario = write(tmp_path, BASE.replace("fmu: builtin", f"fmu: {bad_fmu}"))
    err = one_line_error(capsys, ["run", str(scenario), "--out", str(tmp_path / "out")])
    assert f"{scenario}:3: plant.fmu: {bad_fmu}: invalid modelDescription.xml" in err
    assert not (tmp_path / "out").exists()


# -- 6., 7. command-line options checked before any work --------------------------------------------------------
def test_design_refuses_bad_verify_and_workers_up_front(capsys):
    scenario = str(Path(__file__).parents[2] / "examples" / "tool_change.yaml")
    assert "--verify: expected 0 (no check) or a number of runs >= 2 per slope, got -1" in one_line_error(
        capsys, ["design", scenario, "--verify", "-1"])
    assert "--workers: expected >= 1, got 0" in one_line_error(capsys, ["design", scenario, "--verify", "2",
                                                                         "--workers", "0"])
    assert capsys.readouterr().out == ""  # no design sweep printed


@pytest.mark.parametrize("address, reason", [("notanaddress", "missing port number"),
                                             ("tcp://localhost", "missing port number")])
def test_campaign_refuses_a_malformed_scheduler_address(tmp_path, capsys, address, reason):
    path = write(tmp_path, "name: c\nbase: {name: b, nc: {program: [{dwell: {time: 0.1}}]}}\n", "c.yaml")
    err = one_line_error(capsys, ["campaign", str(path), "--scheduler", address, "--out", str(tmp_path / "out")])
    assert f"--scheduler {address}: {reason}" in err and "tcp://host:8786" in err
    assert not (tmp_path / "out").exists()


# -- 8. history: the axes the file holds ----------------------------------------------------------------------
def test_history_names_the_axes_in_the_file(tmp_path, capsys):
    db = tmp_path / "h.sqlite"
    with History(db) as h:
        h.record("X", {"motion": 1, "start": 0.0, "end": 1.0, "validated": False, "parameters": {}}, time=1.7e9)
    err = one_line_error(capsys, ["history", "--db", str(db), "--axis", "Y"])
    assert err.endswith("no motion for axis 'Y' (axes in the file: X)\n")


# -- 9. a communication step longer than the run ----------------------------------------------------------------
@pytest.mark.parametrize("extra, expected", [  # a 0.01 m rapid at the default 0.6 m/s^2: a 2 sqrt(d / a) triangle
    ("", f"step: 10 s is longer than the run ({2 * np.sqrt(0.01 / 0.6) + 0.3:g} s, the default stop time: "
         "the NC program + 0.3 s)"),
    ("stop_time: 5\n", "step: 10 s is longer than the run (5 s, stop_time)")])
def test_step_longer_than_the_run_is_refused(tmp_path, extra, expected):
    path = write(tmp_path, BASE.replace("step: 1.0e-4", "step: 10") + extra)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert str(info.value).startswith(f"{path}:2: {expected}")


# -- 10. the campaign scores the monitor's own estimator -------------------------------------------------------
@pytest.mark.slow
def test_campaign_iv_is_the_monitors_iv(tmp_path):
    """With the monitor's filter (100 Hz), speed (tachometer and centred encoder speed averaged) and
    currents, the campaign's IV on the recorded signals gives the very parameters the monitor validated."""
    base = {"name": "tc", "step": 1e-4, "plant": {"fmu": "builtin"},
            "nc": {"program": [{"dwell": {"time": 0.02}},
                               {"tool_change": {"position": 0.15, "v_max": 0.22, "accel": 0.8, "time": 0.02}}]},
            "monitor": {"baseline": "nominal"}}
    c = Campaign.model_validate({"name": "tc", "base": base, "seed": 2, "repetitions": 2, "root": str(tmp_path),
                                 "run_options": {"methods": ["ls", "iv"]}})
    res = run_campaign(c, tmp_path / "out", plots=False)
    assert not res.failed
    for r in res.records:
        (m,) = r["result"]["motions"]
        assert m["validated"] and m["method"] == "iv"
        for p, est in m["parameters"].items():
            assert m["methods"]["iv"][p]["value"] == pytest.approx(est["value"], rel=1e-9)
            assert m["methods"]["iv"][p]["ci95"] == pytest.approx(est["ci95"], rel=1e-9)
    rows = {(e["parameter"], e["method"]): e for e in res.aggregates.estimation}
    for p in ("R", "L", "K", "Jt", "ft", "Cd"):
        assert rows[p, "monitor"]["n"] == 2
        assert rows[p, "monitor"]["bias_pct"] == pytest.approx(rows[p, "iv"]["bias_pct"], rel=1e-9, abs=1e-12)
        assert abs(rows[p, "monitor"]["bias_pct"]) < 1.0  # healthy plant: within 1 % of the truth
