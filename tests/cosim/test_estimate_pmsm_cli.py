"""``cosim estimate --drive pmsm`` on a CSV written from the built-in PMSM drive at a servo drive's 8 kHz trace rate,
the speed in rpm and the table position in mm (converted by the units in the headers)."""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "estimator"))
from pmsm_data import closed_loop  # noqa: E402
from test_estimate_cli import run  # noqa: E402

from feeddrive.models.drives import drive_model  # noqa: E402

TRUTH = drive_model("pmsm").nominal(("physical",))
HEADER = "time [s],n_act [rpm],pos [mm],iq [A],id [A],uq [V],ud [V]"
MAP = ["--map", "time=time", "speed=n_act", "position=pos", "i_q=iq", "i_d=id", "u_q=uq", "u_d=ud",
       "--drive", "pmsm", "--pitch", "0.01", "--filter-cutoff", "100"]


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    d = closed_loop()
    columns = [d["t"], d["w"] * 60 / (2 * math.pi), d["theta"] / (2 * math.pi) * 10.0,  # rpm; mm at a 10 mm pitch
               *(d[k] for k in ("i_q", "i_d", "u_q", "u_d"))]
    path = tmp_path_factory.mktemp("rec") / "pmsm_axis.csv"
    np.savetxt(path, np.column_stack(columns), delimiter=",", header=HEADER, comments="", fmt="%.12g")
    return path


def test_pmsm_recording_gives_every_parameter_with_its_unit_and_kt_ke(recording, capsys):
    code, out, _ = run(capsys, recording, *MAP, "--pole-pairs", "4", "--json")
    assert code == 0
    (seg,) = json.loads(out)["segments"]
    assert seg["method"] == "iv"
    assert list(seg["parameters"]) == ["R", "L_d", "L_q", "psi_f", "Jt", "ft", "Cd"]
    units = {n: p["unit"] for n, p in seg["parameters"].items()}
    assert units == {"R": "Ohm", "L_d": "H", "L_q": "H", "psi_f": "Wb", "Jt": "kg.m2", "ft": "N.m.s/rad", "Cd": "N.m"}
    for name, p in seg["parameters"].items():
        assert p["value"] == pytest.approx(TRUTH[name], rel=0.005), name
        assert p["ci95"][0] <= p["value"] <= p["ci95"][1]
    assert seg["derived"]["K_t"]["value"] == pytest.approx(1.5 * 4 * 0.23, rel=0.005)
    assert seg["derived"]["K_e"] | {"value": 0, "ci95": 0} == {"value": 0, "ci95": 0, "unit": "V.s/rad"}
    assert seg["model_check"]["verdict"] == "adequate"  # the d, q and mechanical equations' own residues


def test_pole_pairs_change_psi_f_not_the_torque_constant(recording, capsys):
    code, out, _ = run(capsys, recording, *MAP, "--known", "p=2")
    assert code == 0
    psi = float(out.split("\n  psi_f")[1].split()[0])
    k_t = float(out.split("\n  K_t")[1].split()[0])
    assert psi == pytest.approx(0.23 * 2, rel=0.005) and k_t == pytest.approx(1.38, rel=0.005)
    assert "N.m/A" in out and "(derived)" in out


def test_dc_roles_with_a_pmsm_and_bad_pole_pairs_are_one_line_errors(recording, capsys):
    code, _, err = run(capsys, recording, "--map", "time=time", "speed=n_act", "current=iq", "--drive", "pmsm")
    assert code == 2 and "unknown role(s) ['current']" in err and "Traceback" not in err
    code, _, err = run(capsys, recording, *MAP, "--pole-pairs", "0")
    assert code == 2 and "--pole-pairs 0: expected a positive number" in err


def test_an_ncs_4ms_trace_gives_r_within_its_interval_or_refuses_it(tmp_path, capsys):
    """The co-simulated tool changes (the NC's reference held over each 0.1 ms step) traced at 4 ms: IV's halves
    (8 ms) alias the current's transients, R came out 3 % low with an interval excluding 0.70. Now every motion
    gives R within its interval or refuses it with the sample-period rule's numbers."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from test_monitor_pmsm import AXIS, _run

    axis = {k: v for k, v in AXIS.items() if k != "monitor"} | {"name": "pmsm-4ms"}
    result = _run(tmp_path, axis, "pmsm-4ms")
    signals = result.out_dir / "signals.csv"
    header = signals.read_text().split("\n", 1)[0].split(",")
    rec = np.loadtxt(signals, delimiter=",", skiprows=1)
    cols = [header.index(c) for c in ("time [s]", "plant.voltage [V]", "plant.u_d [V]", "plant.current [A]",
                                      "plant.i_d [A]", "plant.speed [rad/s]", "nc.state [1]")]
    rec = rec[::40, cols]  # an NC's trace: instantaneous samples every 4 ms
    path = tmp_path / "rec4ms.csv"
    np.savetxt(path, rec, delimiter=",", comments="",
               header="time [s],u_q [V],u_d [V],i_q [A],i_d [A],w [rad/s],state [1]", fmt="%.12g")
    code, out, _ = run(capsys, path, "--map", "time=time", "u_q=u_q", "u_d=u_d", "i_q=i_q", "i_d=i_d", "speed=w",
                       "state=state", "--drive", "pmsm", "--pole-pairs", "4", "--json")
    assert code == 0
    segs = json.loads(out)["segments"]
    assert len(segs) == 2
    for seg in segs:
        if "R" in seg["parameters"]:
            lo, hi = seg["parameters"]["R"]["ci95"]
            assert lo <= 0.7 <= hi, seg["parameters"]["R"]
        else:
            assert seg["refused"]["R"].startswith("sample period 0.004 s: IV ("), seg["refused"]["R"]
        assert seg["parameters"]["L_q"]["value"] == pytest.approx(8e-3, rel=0.01)


def test_cosim_design_on_a_pmsm_axis_scores_the_dq_parameters(capsys):
    """``cosim design`` on examples/pmsm_axis.yaml: the PMSM's parameters, the dq noises from the servo sensors
    (three phases of 0.05 A through Park: 0.0408 A), the current vector's peak; --verify is DC-only, said in one
    line."""
    from feeddrive.cosim.cli import main

    example = Path(__file__).resolve().parents[2] / "examples" / "pmsm_axis.yaml"
    assert main(["design", str(example), "--accel", "1,3", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "i_q 0.0408248 A" in out and "(the encoder's speed: not in the prediction)" in out
    header = next(line for line in out.splitlines() if line.lstrip().startswith("accel"))
    assert header.split()[3:10] == ["R", "%", "L_d", "%", "L_q", "%", "psi_f"]
    rows = {float(line.split()[0]): line for line in out.splitlines() if line.strip()[:1].isdigit()}
    assert float(rows[3.0].split()[-1 if "<-" not in rows[3.0] else -3]) == pytest.approx(4.9, abs=0.3)  # peak A
    code = main(["design", str(example), "--accel", "3", "--verify", "2", "--no-progress"])
    _, err = capsys.readouterr()
    assert code == 2 and "--verify: the campaign check compares the DC drive's estimates" in err


def test_known_parameters_on_a_pmsm_by_ls_as_on_the_dc_drive(recording, capsys):
    """``--known`` with any subset, as on the DC drive: a known Jt used to fail the whole run with "fixing other
    parameters needs a known psi_f" (the residue check derived the mechanical regression with psi_f free). Now
    the known parameter is not printed, the others are given, and the residue check says it could not use it;
    without the voltages, what cannot be solved (the mechanical equation's scale psi_f) is said with the reason."""
    code, out, _ = run(capsys, recording, *MAP, "--method", "ls", "--known", "Jt=0.003", "--json")
    assert code == 0
    (seg,) = json.loads(out)["segments"]
    assert set(seg["parameters"]) == {"R", "L_d", "L_q", "psi_f", "ft", "Cd"}
    for name, p in seg["parameters"].items():
        assert p["value"] == pytest.approx(TRUTH[name], rel=0.005), name
    assert "known Jt (the mechanical equation is scaled by psi_f, not known) not used" in seg["model_check"]["reason"]
    currents = ["--map", "time=time", "speed=n_act", "i_q=iq", "i_d=id", "--drive", "pmsm", "--filter-cutoff", "100",
                "--method", "ls"]
    code, out, _ = run(capsys, recording, *currents, "--known", "psi_f=0.23", "--known", "Jt=0.003", "--json")
    assert code == 0
    (seg,) = json.loads(out)["segments"]
    assert {n: round(p["value"] / TRUTH[n], 3) for n, p in seg["parameters"].items()} == {"ft": 1.0, "Cd": 1.0}
    code, _, err = run(capsys, recording, *currents, "--known", "Jt=0.003")
    assert code != 0 and "scaled by psi_f, which is refused (no voltage signal: map the voltage or state psi_f " \
        "(--known psi_f=VALUE" in err and "Traceback" not in err
