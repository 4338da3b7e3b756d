"""The built-in PMSM plant FMU (``plant: {fmu: builtin-pmsm}``): the generic wrapper around models.pmsm_drive."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
import yaml
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu
from scipy.linalg import expm

from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import PMSM_MAP, load_scenario, scenario_from_dict
from feeddrive.fmu_build import FMUBuildInputError, builtin_fmu
from feeddrive.models import pmsm_drive

NOMINAL = pmsm_drive().nominal()
EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "pmsm_axis.yaml"
#: open loop: the rotor held at a constant speed by a huge inertia (torque / Jt ~ 1e-8 rad/s^2), no friction
OPEN_LOOP = {"bypass": 1.0, "Jt": 1.0e9, "ft": 0.0, "Cd": 0.0}
OUT = ["i_d", "i_q", "w", "theta", "u_d", "u_q", "torque", "x"]


@pytest.fixture(scope="module")
def pmsm_fmu(fmu_cache_dir: Path) -> Path:
    return builtin_fmu(fmu_cache_dir, motor="pmsm")


def open_loop_exact(t: np.ndarray, w: float, Ld: float, Lq: float, ud: float, uq: float) -> np.ndarray:
    """(i_d, i_q) of the dq circuit at constant speed w under constant voltages, from rest; shape (len(t), 2)."""
    p, psi, R = NOMINAL["p"], NOMINAL["psi_f"], NOMINAL["R"]
    A = np.array([[-R / Ld, p * w * Lq / Ld, ud / Ld],
                  [-p * w * Ld / Lq, -R / Lq, (uq - p * w * psi) / Lq],
                  [0.0, 0.0, 0.0]])
    return np.array([expm(A * tk) @ np.array([0.0, 0.0, 1.0]) for tk in t])[:, :2]


def simulate(fmu: Path, kind: str, start: dict[str, float], stop: float, dt: float = 1e-3) -> np.ndarray:
    return simulate_fmu(str(fmu), fmi_type=kind, start_values=start, stop_time=stop, output_interval=dt,
                        relative_tolerance=1e-10, output=OUT)


def test_validates_and_declares_the_dq_signals(pmsm_fmu):
    assert pmsm_fmu.name == "PMSMFeedDrive.fmu"
    assert validate_fmu(str(pmsm_fmu)) == []
    md = read_model_description(str(pmsm_fmu))
    assert md.fmiVersion == "2.0" and md.coSimulation is not None and md.modelExchange is not None
    by: dict[str, set[str]] = {}
    for v in md.modelVariables:
        by.setdefault(v.causality, set()).add(v.name)
    assert by["input"] == {"w_ref", "Tl", "u_d_in", "u_q_in"}
    assert {"i_q", "i_d", "u_q", "u_d", "w", "theta", "x"} <= by["output"]
    units = {v.name: v.unit for v in md.modelVariables}
    assert (units["psi_f"], units["L_q"], units["u_q"], units["torque"]) == ("Wb", "H", "V", "N.m")
    # the role map of the DC pipeline: q axis for voltage and current
    assert {PMSM_MAP[r] for r in ("voltage", "current", "speed", "position")} == {"u_q", "i_q", "w", "x"}
    assert all(PMSM_MAP[r] in by["input"] for r in ("speed_ref", "load"))
    assert all(PMSM_MAP[r] in by["output"] for r in ("voltage", "voltage_ref", "current", "speed", "position"))


def test_backlash_is_refused_for_the_pmsm(fmu_cache_dir):
    with pytest.raises(FMUBuildInputError, match="backlash"):
        builtin_fmu(fmu_cache_dir, motor="pmsm", backlash=True)
    with pytest.raises(FMUBuildInputError, match="motor 'bldc'"):
        builtin_fmu(fmu_cache_dir, motor="bldc")


@pytest.mark.parametrize("kind", ["CoSimulation", "ModelExchange"])
def test_open_loop_voltage_step_matches_the_matrix_exponential(pmsm_fmu, kind):
    w, Ld, Lq, ud, uq = 200.0, NOMINAL["L_d"], 1.5 * NOMINAL["L_d"], -20.0, 220.0
    start = OPEN_LOOP | {"w": w, "L_q": Lq, "u_d_in": ud, "u_q_in": uq}
    res = simulate(pmsm_fmu, kind, start, 0.05)
    t = res["time"]
    exact = open_loop_exact(t, w, Ld, Lq, ud, uq)
    got = np.column_stack([res["i_d"], res["i_q"]])
    # RK4 at 1e-5 s (CS) or CVode at rtol 1e-10 (ME)
    assert np.max(np.abs(got - exact)) < 1e-6 * np.max(np.abs(exact))
    assert np.max(np.abs(res["w"] - w)) < 1e-6


def test_cs_and_me_agree_in_closed_loop_with_field_weakening(pmsm_fmu):
    start = {"w_ref": 450.0, "Tl": 1.0}
    cs = simulate(pmsm_fmu, "CoSimulation", start, 0.6)
    me = simulate(pmsm_fmu, "ModelExchange", start, 0.6)
    # RK4 (CS) is first order across the kinks of the current and voltage limits the start saturates
    # (measured 1.3e-5 of i_q's range in the first ms); elsewhere the two agree to ~1e-9
    for name in ("i_d", "i_q", "w", "u_q", "u_d", "x"):
        scale = np.max(np.abs(me[name]))
        assert np.max(np.abs(cs[name] - me[name])) < 5e-5 * scale, name
        assert np.max(np.abs(cs[name][100:] - me[name][100:])) < 1e-6 * scale, name
    # settled above the base speed: weakened field, torque balance with the load torque
    assert cs["w"][-1] == pytest.approx(450.0, rel=1e-5)
    assert cs["i_d"][-1] == pytest.approx(-NOMINAL["i_fw"] * (1 - NOMINAL["w_base"] / 450.0), rel=1e-5)
    load = NOMINAL["ft"] * 450.0 + NOMINAL["Cd"] + 1.0
    assert cs["torque"][-1] == pytest.approx(load, rel=1e-5)


def test_cosim_run_of_the_pmsm_example_follows_the_nc(pmsm_fmu, tmp_path):
    scenario = load_scenario(EXAMPLE)
    assert scenario.plant.map["current"].var == "i_q" and scenario.plant.map["voltage"].var == "u_q"
    assert Path(scenario.plant.fmu).name == "PMSMFeedDrive.fmu"
    # in this process and without figures (what is checked is the run's signals.csv; the README's session runs the
    # example through `cosim run`, figures and all: tests/layout/test_readme_outputs.py)
    run_scenario(scenario, tmp_path / "run", plots=False)
    with open(tmp_path / "run" / "signals.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    x = np.array([float(r["plant.position [m]"]) for r in rows])
    x_ref = np.array([float(r["nc.x_ref [m]"]) for r in rows])
    w = np.array([float(r["plant.speed [rad/s]"]) for r in rows])
    target = yaml.safe_load(EXAMPLE.read_text())["nc"]["program"][1]["tool_change"]["position"]
    assert x_ref.max() == pytest.approx(target, rel=1e-9)
    assert x.max() == pytest.approx(target, abs=0.2e-3)       # reaches the tool-change position
    assert np.max(np.abs(x - x_ref)) < 0.5e-3                  # follows the NC within 0.5 mm
    assert abs(x[-1]) < 1e-5                                   # and comes back home
    # 0.3 m/s on a 10 mm screw is 60 pi rad/s (1800 rpm), below the base speed: no field weakening
    assert np.max(np.abs(w)) == pytest.approx(0.3 / 0.01 * 2 * np.pi, rel=0.05)
    i_d = np.array([float(r["plant.i_d [A]"]) for r in rows])
    assert np.max(np.abs(i_d)) < 1.0


def test_an_axis_without_pitch_takes_the_pmsm_models_screw(pmsm_fmu):
    """The drive chain stated nowhere is the plant model's own (10 mm), not the DC model's 20 mm."""
    data = {"name": "p", "axis": "X", "step": 1e-4, "plant": {"fmu": "builtin-pmsm"},
            "nc": {"program": [{"dwell": {"time": 0.05}}]}}
    s = scenario_from_dict(data)
    assert s.axis.pitch == s.plant.parameters["pitch"] == s.nc.pitch == s.sensors.encoder.pitch == 0.01
    dc = scenario_from_dict(data | {"plant": {"fmu": "builtin"}})
    assert dc.axis.pitch == dc.plant.parameters["pitch"] == 0.02
