"""``cosim monitor --drive pmsm`` on what a servo drive's trace holds (issue 25 item 5; cosim/recorded_servo.py):
phase currents, a second sensor on a stated phase, voltage references, n_act [rpm], the motor encoder and a
linear scale [mm], dq currents as rms values [A rms]. The traces are written here in a drive's own terms from
the built-in PMSM's co-simulation (examples/pmsm_axis.yaml) and from the vendor PMSM FMU (fmpy)."""
from __future__ import annotations

import json
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from feeddrive.cosim.cli import main
from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import load_scenario, scenario_from_dict

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "plants"))
from vendor_pmsm import INVERTER, TRUTH  # noqa: E402

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "pmsm_axis.yaml"
BUILTIN = {"R": 0.7, "L_q": 8.0e-3, "psi_f": 0.23, "Jt": 3.0e-3}
RPM = 30 / math.pi
#: a drive's trace of the built-in run: column -> (signals.csv column, factor), unit in the header
TRACE = {"n_act [rpm]": ("sensors.w_tach", RPM), "pos_mot [rad]": ("sensors.theta_enc", 1.0),
         "I_U [A]": ("servo.I_U", 1.0), "I_V [A]": ("servo.I_V", 1.0), "I_W [A]": ("servo.I_W", 1.0),
         "I_U2 [A]": ("servo.I_2", 1.0), "iq [A rms]": ("sensors.Im1", 1 / math.sqrt(2)),
         "uq_ref [V]": ("servo.u_q_ref", 1.0), "ud_ref [V]": ("servo.u_d_ref", 1.0), "uq [V]": ("servo.u_q", 1.0),
         "ud [V]": ("servo.u_d", 1.0), "x_lin [mm]": ("servo.x_lin", 1e3), "state [1]": ("nc.state", 1.0)}
FULL = ["time=time", "speed=n_act", "position=pos_mot", "I_U=I_U", "I_V=I_V", "I_W=I_W", "I_U2=I_U2", "i_q=iq",
        "u_q_ref=uq_ref", "u_d_ref=ud_ref", "u_q=uq", "u_d=ud", "x_lin=x_lin", "state=state"]


def read_csv(path: Path) -> dict[str, np.ndarray]:
    """A CSV with a header row as column name (the unit in brackets dropped) -> values."""
    header = path.read_text(encoding="utf-8").split("\n", 1)[0].split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    return {h.split(" [")[0]: data[:, k] for k, h in enumerate(header)}


def write_csv(path: Path, columns: dict[str, np.ndarray]) -> Path:
    np.savetxt(path, np.column_stack(list(columns.values())), delimiter=",", header=",".join(columns), comments="",
               fmt="%.10g")
    return path


@pytest.fixture(scope="module")
def builtin_trace(tmp_path_factory: pytest.TempPathFactory) -> dict[str, np.ndarray]:
    """examples/pmsm_axis.yaml's signals.csv as a drive's trace: n_act [rpm], i_q [A rms], x_lin [mm], ..."""
    out = tmp_path_factory.mktemp("pmsm-axis")
    res = run_scenario(load_scenario(EXAMPLE), out / "run", plots=False)
    s = read_csv(res.out_dir / "signals.csv")
    return {"time [s]": s["time"]} | {name: factor * s[col] for name, (col, factor) in TRACE.items()}


def monitor(tmp_path: Path, trace: dict, roles: list[str], *extra: str, capsys) -> dict:
    csv = write_csv(tmp_path / f"trace{len(list(tmp_path.glob('*.csv')))}.csv", trace)
    pitch = ["--pitch", "0.01"] if any(r.startswith("x_lin=") for r in roles) else []  # the scale against the encoder
    code = main(["monitor", str(csv), "--map", *roles, "--drive", "pmsm", "--pole-pairs", "4", "--alpha", "0.01",
                 *pitch, "--db", str(tmp_path / "m.db"), "--axis", csv.stem, "--json", *extra])
    out = capsys.readouterr()
    assert code == 0, out.err
    return json.loads(out.out.splitlines()[-1])


def test_a_drive_trace_with_phase_currents_rpm_rms_and_a_linear_scale(builtin_trace, tmp_path, capsys):
    """Everything a drive's trace holds: every servo check runs and passes; the q current given in A rms is
    converted (x sqrt 2, said in unit_notes) so that it agrees with the Park transform of the phase currents
    (gain within 0.5 % of 1); the estimate is the co-simulation's (R 1 %, L_q 0.5 %, psi_f and Jt 0.2 %).
    Measured: Park gain 0.9995, R +0.13 %, L_q -0.05 %, psi_f -0.001 %, lost motion -0.00005 mm."""
    out = monitor(tmp_path, builtin_trace, FULL, capsys=capsys)
    assert any("i_q: 'iq [A rms]' is an rms value" in n for n in out["unit_notes"])
    (m,) = out["motions"]
    assert m["validated"], (m["notes"], m["sensor_faults"])
    checks = m["servo_checks"]
    assert set(checks) == {"phase_current_sum", "phase_sensor_pair", "dq_current_consistency",
                           "voltage_reference_check", "lost_motion"}
    assert all(c.get("valid", True) for c in checks.values()), checks
    assert m["not_checked"]["current"].endswith("checked instead (phase_current_sum, phase_sensor_pair)")
    assert checks["dq_current_consistency"]["gain"] == pytest.approx(1.0, abs=0.005)
    assert abs(checks["lost_motion"]["value_mm"]) < 0.002 and not checks["lost_motion"]["detected"]
    for name, tol in (("R", 0.01), ("L_q", 0.005), ("psi_f", 0.002), ("Jt", 0.002)):
        assert m["parameters"][name]["value"] == pytest.approx(BUILTIN[name], rel=tol), name


def test_a_phase_sensor_fault_in_the_trace_is_found_by_the_phase_sum(builtin_trace, tmp_path, capsys):
    """Phase V's sensor reads 3 % high in the recording: the phase-current sum isolates I_V with its gain
    (1.03 +- 0.005; measured 1.0307) and the motion is a sensor fault, never validated."""
    trace = builtin_trace | {"I_V [A]": 1.03 * builtin_trace["I_V [A]"]}
    (m,) = monitor(tmp_path, trace, FULL, capsys=capsys)["motions"]
    assert m["verdict"] == "sensor fault" and not m["validated"]
    (fault,) = [f for f in m["sensor_faults"] if f["check"] == "phase_current_sum"]
    assert fault["sensor"] == "I_V" and fault["gain"] == pytest.approx(1.03, abs=0.005)


def test_two_phase_currents_and_the_voltage_references_only(builtin_trace, tmp_path, capsys):
    """A drive that records two phase currents and its voltage references: the third current is minus their
    sum, the dq currents their Park transform, the voltages the references; the checks this makes void say
    why, and the estimate is still the co-simulation's (R 1 %, L_q 0.5 %, psi_f 0.2 %)."""
    roles = ["time=time", "speed=n_act", "position=pos_mot", "I_U=I_U", "I_W=I_W", "u_q_ref=uq_ref",
             "u_d_ref=ud_ref", "state=state"]
    (m,) = monitor(tmp_path, builtin_trace, roles, capsys=capsys)["motions"]
    why = m["not_checked"]
    assert why["phase_current_sum"] == "not checked: two phase currents (I_V is minus their sum: no redundancy)"
    assert why["dq_current_consistency"].startswith("not checked: the q current is the Park transform")
    assert why["voltage_reference_check"].startswith("not checked: the terminal voltages are the references")
    assert m["gain_ratio_reason"].startswith("not checked: no q current sensor")
    assert m["validated"], m["notes"]
    for name, tol in (("R", 0.01), ("L_q", 0.005), ("psi_f", 0.002)):
        assert m["parameters"][name]["value"] == pytest.approx(BUILTIN[name], rel=tol), name


def test_the_second_sensor_phase_from_the_map_and_the_encoder_offset(builtin_trace, tmp_path, capsys):
    """A second sensor on phase V (``--map I_V2=...``) is checked against I_V (valid; mapped as I_U2 the same
    column is a gross fault: the phases are 120 degrees apart). An encoder zeroed 0.3 rad (mechanical) off the
    d axis turns the Park transform by 1.2 rad: i_q against its q current has a gain of 1 / cos(1.2) = 2.76, a fault;
    ``--angle-offset -1.2`` restores it (gain within 0.5 % of 1)."""
    rng = np.random.default_rng(5)
    trace = builtin_trace | {"I_V2 [A]": builtin_trace["I_V [A]"] + 0.05 * rng.standard_normal(len(builtin_trace["I_V [A]"])),
                             "pos_mot [rad]": builtin_trace["pos_mot [rad]"] + 0.3}
    roles = [r for r in FULL if not r.startswith("I_U2")]
    (m,) = monitor(tmp_path, trace, [*roles, "I_V2=I_V2"], "--angle-offset", "-1.2", capsys=capsys)["motions"]
    pair = m["servo_checks"]["phase_sensor_pair"]
    assert pair["phase"] == "V" and pair["valid"] and pair["gain_ratio"] == pytest.approx(1.0, abs=0.005)
    assert m["servo_checks"]["dq_current_consistency"]["gain"] == pytest.approx(1.0, abs=0.005)
    (m,) = monitor(tmp_path, trace, [*roles, "I_U2=I_V2"], capsys=capsys)["motions"]
    assert not m["servo_checks"]["phase_sensor_pair"]["valid"]
    dq = m["servo_checks"]["dq_current_consistency"]
    assert not dq["valid"] and dq["gain"] == pytest.approx(1 / math.cos(1.2), rel=0.01)


@pytest.mark.parametrize(("roles", "extra", "words"), [
    (["I_U2=I_U2", "I_V2=I_U2"], (), "--map: I_U2 and I_V2: a second current sensor on one phase only"),
    (["I_U=iq"], (), "an rms value is not a sample of role I_U"),
    (["phi_el=pos_mot"], ("--angle-offset", "0.1"), "--angle-offset: the electrical angle is mapped (phi_el)"),
])
def test_bad_pmsm_roles_are_one_line(builtin_trace, tmp_path, capsys, roles, extra, words):
    csv = write_csv(tmp_path / "t.csv", builtin_trace)
    base = [r for r in FULL if r.split("=")[0] not in {x.split("=")[0] for x in roles}]
    assert main(["monitor", str(csv), "--map", *base, *roles, "--drive", "pmsm", "--pitch", "0.01",
                 "--db", str(tmp_path / "m.db"), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and "\n" not in err, err
    assert main(["monitor", str(csv), "--map", *FULL, "--drive", "pmsm", "--db", str(tmp_path / "m.db")]) == 2
    assert "--map x_lin: the linear scale is compared with the motor encoder" in capsys.readouterr().err


VENDOR_OUT = {"n_ist": "rpm", "I_U": "A", "I_V": "A", "I_W": "A", "I_q_rms": "A rms", "I_d_rms": "A rms",
              "U_d_soll": "V", "U_q_soll": "V", "U_d": "V", "U_q": "V", "s_mot_mm": "mm", "s_lin_mm": "mm",
              "phi_el": "rad"}
VENDOR_NOISE = {"n_ist": 0.5, "I_U": 0.05, "I_V": 0.05, "I_W": 0.05, "I_q_rms": 0.03, "I_d_rms": 0.03, "U_d_soll": 0.2,
                "U_q_soll": 0.2, "U_d": 0.2, "U_q": 0.2, "s_mot_mm": 0.0, "s_lin_mm": 2e-4, "phi_el": 0.0}


def vendor_trace(fmu: Path, path: Path, lost_motion_mm: float, h: float = 1.25e-4) -> Path:
    """The vendor PMSM FMU's own outputs (rpm, A rms, mm, its electrical angle) at a drive's 125 us trace rate,
    with seeded sensor noise: 1500, 400 and -1000 rpm, ramped, 1.35 s."""
    from fmpy import simulate_fmu

    stop = 1.35
    t = np.arange(0.0, stop + h / 2, h)
    n = np.interp(t, [0, 0.05, 0.2, 0.35, 0.5, 0.65, 0.95, 1.15, 1.25, stop], [0, 0, 1500, 1500, 400, 400, -1000,
                                                                               -1000, 0, 0])
    signal = np.array(list(zip(t, n, 0 * t)), dtype=[("time", float), ("n_soll", float), ("M_last", float)])
    r = simulate_fmu(str(fmu), start_values={"lost_motion_mm": lost_motion_mm}, stop_time=stop, output_interval=h,
                     input=signal, output=list(VENDOR_OUT))
    rng = np.random.default_rng(7)
    columns = {"time [s]": r["time"]} | {f"{k} [{u}]": r[k] + VENDOR_NOISE[k] * rng.standard_normal(len(r))
                                         for k, u in VENDOR_OUT.items()}
    return write_csv(path, columns)


def test_the_vendor_pmsm_trace_in_its_own_units(vendor_pmsm_fmu, tmp_path, capsys):
    """The vendor FMU's trace with 0.02 mm of play: n_ist [rpm], s_mot_mm and s_lin_mm [mm] and the dq currents
    [A rms] are converted by their units (the rms ones x sqrt 2: i_q agrees with the Park transform of the phase
    currents at the drive's phi_el within 0.5 %); the dead time's loss is measured (4.8 V per leg within 1 %); the
    two encoders see the lost motion (0.02 mm within 0.002 mm). The estimate from these instantaneous samples:
    R within 5 %, L_q 1 %, psi_f 0.5 % of the FMU's values. Mapped without its factor (``I_q_rms*1``: the values
    taken as SI, ``I_q_rms*1 [A]``: a scale contradicting the header needs its unit stated), the rms current is caught by the Park check: gain 1/sqrt 2. Measured: Park gain 0.9984, loss
    4.771 V, lost motion 0.01999 mm, R -2.97 %, L_q -0.01 %, psi_f +0.01 %; without the factor gain 0.7059."""
    csv = vendor_trace(vendor_pmsm_fmu, tmp_path / "vendor.csv", 0.02)
    loss = INVERTER["t_dead"] * INVERTER["f_pwm"] * INVERTER["u_dc"]
    roles = ["time=time", "speed=n_ist", "position=s_mot_mm", "I_U=I_U", "I_V=I_V", "I_W=I_W", "i_d=I_d_rms",
             "u_q_ref=U_q_soll", "u_d_ref=U_d_soll", "u_q=U_q", "u_d=U_d", "x_lin=s_lin_mm", "phi_el=phi_el"]
    common = ["--drive", "pmsm", "--pole-pairs", "4", "--pitch", "0.01", "--dead-time-loss", f"{loss}", "--alpha",
              "0.01", "--segment", "none", "--json"]
    assert main(["monitor", str(csv), "--map", *roles, "i_q=I_q_rms", *common, "--db", str(tmp_path / "a.db")]) == 0
    out = json.loads(capsys.readouterr().out.splitlines()[-1])
    (m,) = out["motions"]
    assert len(out["unit_notes"]) == 2  # i_q and i_d, each said
    checks = m["servo_checks"]
    assert checks["phase_current_sum"]["valid"] and checks["dq_current_consistency"]["valid"]
    assert checks["dq_current_consistency"]["gain"] == pytest.approx(1.0, abs=0.005)
    assert checks["voltage_reference_check"]["valid"]
    assert checks["voltage_reference_check"]["u_loss"] == pytest.approx(loss, rel=0.01)
    assert checks["lost_motion"]["detected"] and checks["lost_motion"]["value_mm"] == pytest.approx(0.02, abs=0.002)
    p = {k: v["value"] for k, v in m["parameters"].items()}
    for name, tol in (("R", 0.05), ("L_q", 0.01), ("psi_f", 0.005)):
        assert p[name] == pytest.approx(TRUTH[name], rel=tol), name
    # a scale that contradicts the header's [A rms] is refused at the map, naming the column; stated, it is taken
    assert main(["monitor", str(csv), "--map", *roles, "i_q=I_q_rms*1", *common, "--db", str(tmp_path / "b.db")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "(role i_q): the header says [A rms]" in err
    assert main(["monitor", str(csv), "--map", *roles, "i_q=I_q_rms*1 [A]", *common, "--db",
                 str(tmp_path / "b.db")]) == 0
    (m,) = json.loads(capsys.readouterr().out.splitlines()[-1])["motions"]
    dq = m["servo_checks"]["dq_current_consistency"]
    assert not dq["valid"] and dq["gain"] == pytest.approx(1 / math.sqrt(2), abs=0.005)
    assert not m["validated"] and any(f["check"] == "dq_current_consistency" for f in m["sensor_faults"])


def page_text(path: Path) -> str:
    """The visible text of a report.html (figures' data URIs and tags dropped)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "report"))
    from page_checks import parse

    return " ".join(" ".join(parse(path).find("body").itertext()).split())


def test_known_parameters_and_reasons_on_the_console_and_the_page_and_no_nan(builtin_trace, tmp_path, capsys):
    """A PMSM run with monitor.known psi_f: the console shows it with its unit, as the DC console shows --known;
    the page lists it as known. The q-axis current sensors' gain ratio is computed (within 0.5 % of 1, never a
    bare "not computed"), and no "nan" anywhere on the console, in report.json or on the page. On a recording
    with one q current sensor the console and the page say why the ratio is not checked."""
    from feeddrive.cosim.cli.run import summary

    data = load_scenario(EXAMPLE).to_dict()
    data["monitor"] = {"db": ":memory:", "alpha": 0.01, "known": {"psi_f": 0.23}}
    res = run_scenario(scenario_from_dict(data), tmp_path / "run", plots=False)
    text = summary(res)
    assert "known psi_f=0.23 Wb (monitor.known)" in text and "nan" not in text.lower(), text
    (m,) = res.report["motions"]
    assert m["validated"] and "psi_f" not in m["parameters"] and m["known"] == {"psi_f": 0.23}
    assert m["gain_ratio"] == pytest.approx(1.0, abs=0.005) and "gain_ratio_reason" not in m
    page = page_text(tmp_path / "run" / "report.html")
    assert "known (monitor.known, --known)" in page and "current gain ratio a1/a2 (eq. 12)" in page
    for where in (page, (tmp_path / "run" / "report.json").read_text()):
        assert not re.search(r"(?i)\bnan\b", where)
        assert "not computed" not in where or "not computed:" in where
    # cosim monitor on a recording with one q current sensor, psi_f known: the reason and the known value
    csv = write_csv(tmp_path / "t.csv", builtin_trace)
    assert main(["monitor", str(csv), "--map", *FULL, "--drive", "pmsm", "--pitch", "0.01", "--known", "psi_f=0.23",
                 "--db", str(tmp_path / "m.db"), "--out", str(tmp_path / "out")]) == 0
    console = capsys.readouterr().out
    assert "current gain ratio a1/a2: not checked: one q current sensor" in console
    assert any(line.split()[:3] == ["psi_f", "0.23", "Wb"] and "known" in line for line in console.splitlines())
    assert "nan" not in console.lower()
    page = page_text(tmp_path / "out" / "report.html")
    assert "not checked: one q current sensor" in page and "known (monitor.known, --known)" in page
    assert not re.search(r"(?i)\bnan\b", page)
