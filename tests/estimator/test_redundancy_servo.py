"""The servo drive's redundancies (estimator.redundancy_servo) on the vendor PMSM FMU's motions, measured by
cosim.sensors_servo: injected sensor faults and lost motion recovered within stated tolerances."""
from __future__ import annotations

import math
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest

from feeddrive.cosim.sensors import BLOCK
from feeddrive.cosim.sensors_servo import INPUTS, OUTPUTS, ServoSensors, measure_servo
from feeddrive.estimator import redundancy_servo as rs

sys.path.insert(0, str(Path(__file__).parents[1] / "plants"))
from vendor_pmsm import ELASTIC, INVERTER  # noqa: E402
from vendor_pmsm.motions import campaign, out_and_back  # noqa: E402

H = 1e-4
U_LOSS = INVERTER["t_dead"] * INVERTER["f_pwm"] * INVERTER["u_dc"]  # 4.8 V per leg


@pytest.fixture(scope="module")
def motion(vendor_pmsm_fmu) -> dict:
    """1000 rpm out and back (0.2 s each way), 1 N.m load: i_q ~ 1 A, 67 Hz electrical."""
    return out_and_back(vendor_pmsm_fmu, 1000.0, 0.2, 0.0, H, {"M_last": 1.0})


def measured(true: dict, **channels) -> dict:
    """The servo sensors (seed 1) with some channels' ``{gain, offset, noise}`` changed."""
    base = {c: {"gain": 1.0, "offset": 0.0, "noise": 0.05 if c.startswith("I") else 0.2}
            for c in ("I_U", "I_V", "I_W", "I_2", "u_d_ref", "u_q_ref", "u_d", "u_q")}
    base |= {"encoder": {"gain": 1.0, "offset": 0.0, "noise": 0.0}, "scale": {"gain": 1.0, "offset": 0.0, "noise": 2e-7}}
    return measure_servo(true, {"seed": 1}, base | {c: base[c] | v for c, v in channels.items()})


def test_phase_currents_are_the_inverse_park_transform(motion):
    m = measure_servo(motion, {"seed": 1, "phases": [{"noise": 0}] * 3, "second": {"noise": 0}})
    phi = 4 * motion["theta"]
    np.testing.assert_allclose(m["I_U"] + m["I_V"] + m["I_W"], 0.0, atol=1e-12)
    d, q = rs.park(np.vstack([m["I_U"], m["I_V"], m["I_W"]]), phi)
    np.testing.assert_allclose(q, motion["i_q"], atol=1e-12)
    np.testing.assert_allclose(d, motion["i_d"], atol=1e-12)
    np.testing.assert_array_equal(m["I_2"], m["I_U"])  # the second sensor sits on phase U by default
    # the encoder's count: within half a count of the motor angle; x_mot on the 10 mm screw
    q_enc = 2 * math.pi / 10_000
    assert np.max(np.abs(m["theta_enc"] - motion["theta"])) <= q_enc / 2 + 1e-12
    np.testing.assert_allclose(m["x_mot"], m["theta_enc"] / (2 * math.pi) * 0.01, rtol=1e-12)


def test_healthy_phase_sensors_pass_every_check(motion):
    m = measured(motion)
    phi = 4 * motion["theta"]
    assert not rs.phase_current_sum(m["I_U"], m["I_V"], m["I_W"]).faulty
    pair = rs.phase_sensor_pair(m["I_U"], m["I_2"], H)
    assert not pair.faulty and pair.gain_ratio == pytest.approx(1.0, abs=0.01)
    assert not rs.dq_current_consistency(motion["i_q"], m["I_U"], m["I_V"], m["I_W"], phi).faulty


@pytest.mark.parametrize("phase", ["U", "V", "W"])
def test_a_gain_fault_on_one_phase_is_isolated_by_the_sum(motion, phase):
    m = measured(motion, **{f"I_{phase}": {"gain": 1.03}})
    check = rs.phase_current_sum(m["I_U"], m["I_V"], m["I_W"])
    assert check.faulty and check.phase == phase
    assert check.gain == pytest.approx(1.03, abs=0.005)  # measured within 0.001


def test_an_offset_fault_is_detected_by_the_sum_and_isolated_by_the_second_sensor(motion):
    m = measured(motion, I_U={"offset": 0.2})
    check = rs.phase_current_sum(m["I_U"], m["I_V"], m["I_W"])
    assert check.faulty and check.phase is None  # an offset on the sum belongs to no phase in particular
    assert check.offset == pytest.approx(0.2, abs=0.01) and check.offset_ci95[0] < 0.2 < check.offset_ci95[1]
    pair = rs.phase_sensor_pair(m["I_U"], m["I_2"], H)  # the paper's two sensors on phase U
    assert pair.residue.kind == "offset" and pair.residue.offset == pytest.approx(0.2, abs=0.01)


def test_a_gain_fault_of_the_second_sensor_shows_in_the_gain_ratio(motion):
    m = measured(motion, I_2={"gain": 1.03})
    pair = rs.phase_sensor_pair(m["I_U"], m["I_2"], H)
    assert pair.residue.kind == "gain" and pair.residue.gain_diff == pytest.approx(-0.03, abs=0.005)
    assert pair.gain_ratio == pytest.approx(1 / 1.03, abs=0.005)
    # the sum does not see the second sensor: it stays healthy
    assert not rs.phase_current_sum(m["I_U"], m["I_V"], m["I_W"]).faulty


def test_an_rms_current_taken_for_a_peak_is_caught(motion):
    """The vendor's I_q_rms mapped without its sqrt(2): the dq current is 1/sqrt(2) of the phase currents'."""
    m = measured(motion)
    check = rs.dq_current_consistency(motion["i_q"] / math.sqrt(2), m["I_U"], m["I_V"], m["I_W"], 4 * motion["theta"])
    assert check.faulty and check.gain == pytest.approx(1 / math.sqrt(2), abs=0.005)


def test_the_dead_time_is_modelled_not_flagged(motion):
    m = measured(motion)
    args = (m["u_d_ref"], m["u_q_ref"], m["u_d"], m["u_q"], m["I_U"], m["I_V"], m["I_W"], 4 * motion["theta"], H)
    check = rs.voltage_reference_check(*args, u_loss=U_LOSS)
    assert not check.faulty, {k: (r.kind, r.offset, r.gain_diff) for k, r in check.residue.items()}
    # the leg's loss re-estimated from the data: measured 0.9 % low (the smooth sign of the noisy measured
    # currents, 0.05 A noise against i_eps = 0.2 A, is flatter near the zero crossings than the plant's)
    assert check.u_loss == pytest.approx(U_LOSS, rel=0.02)
    # ignoring it, the reference and the terminal voltage disagree: the naive comparison would flag it
    naive = rs.voltage_reference_check(*args, u_loss=0.0)
    assert naive.faulty
    # a real fault on top: the terminal q voltage sensor 1 V off
    m = measured(motion, u_q={"offset": 1.0})
    args = (m["u_d_ref"], m["u_q_ref"], m["u_d"], m["u_q"], m["I_U"], m["I_V"], m["I_W"], 4 * motion["theta"], H)
    fault = rs.voltage_reference_check(*args, u_loss=U_LOSS)
    assert fault.residue["q"].kind in ("offset", "gain+offset") and fault.residue["q"].offset == pytest.approx(1.0, abs=0.1)
    assert fault.residue["d"].kind == "none"


def test_references_against_the_observed_terminal_voltage(motion):
    """No voltage sensor: the terminal voltage observed from the phase currents (Park at the encoder's angle)
    and the encoder's speed with the dq equations. The dead time modelled, the check passes and re-estimates the
    leg's loss within 2 % (measured 4.82 V for 4.80 V, its interval covering it); unmodelled, the q axis is
    flagged with the loss's mean as an offset (-4.6 V: below (4 / pi) 4.8 V at these 1..4 A, the sign smoothed
    over i_eps = 0.2 A)."""
    from vendor_pmsm import TRUTH as T

    m = measured(motion)
    phi = 4 * m["theta_enc"]
    i_d, i_q = rs.park(np.vstack([m["I_U"], m["I_V"], m["I_W"]]), phi)
    u_d, u_q = rs.observed_terminal_voltage(i_d, i_q, m["theta_enc"], H, T["R"], T["L_d"], T["L_q"], T["psi_f"], 4)
    args = (m["u_d_ref"], m["u_q_ref"], u_d, u_q, m["I_U"], m["I_V"], m["I_W"], phi, H)
    check = rs.voltage_reference_check(*args, u_loss=U_LOSS)
    assert not check.faulty and check.u_loss == pytest.approx(U_LOSS, rel=0.02)
    assert check.u_loss_ci95[0] < U_LOSS < check.u_loss_ci95[1]
    naive = rs.voltage_reference_check(*args, u_loss=0.0)
    _, loss_q = rs.dead_time_loss(m["I_U"], m["I_V"], m["I_W"], phi, U_LOSS)
    assert naive.residue["q"].kind == "offset"
    assert naive.residue["q"].offset == pytest.approx(-np.mean(loss_q), rel=0.1)


#: 2 Fc / k: the lost motion of the healthy elastic drive chain [mm]
ELASTIC_MM = 2 * ELASTIC["Fc_table"] / ELASTIC["k_axial"] * 1e-3


@pytest.mark.parametrize("backlash_mm, seed", [(0.0, 11), (0.02, 12)], ids=["healthy", "worn"])
def test_lost_motion_campaign_of_twenty_motions(vendor_pmsm_fmu, backlash_mm, seed):
    """An elastic drive chain (``ELASTIC``: the table's guide friction deflects the screw, 2 Fc / k = 1.2 um of
    lost motion on a healthy axis; its acceleration up to ~14 um in the speed steps, left out by the estimator)
    tested against an acceptance value of 5 um at alpha = 1 %: 10 healthy motions and 10 with 0.02 mm of
    backlash (random 300..1500 rpm out-and-back motions; one test each, so that the two halves run on two
    workers). All 10 worn ones detected, at most 1 healthy alarm (measured 0); every estimate within 0.5 um of
    1.2 um or 21.2 um (measured about 0.05 um low: the speed loop's settling tail, accelerations below the
    0.2 m/s^2 cut, still deflects the screw by m a / k). The full campaign (100 + 100 motions) is
    benchmarks/bench_lost_motion.py."""
    runs = campaign(vendor_pmsm_fmu, 10, backlash_mm, seed=seed, parameters=ELASTIC, allowed_mm=0.005)
    if backlash_mm:
        assert all(r.detected for r in runs)
    else:
        assert sum(r.detected for r in runs) <= 1
    for r in runs:
        assert r.value_mm == pytest.approx(backlash_mm + ELASTIC_MM, abs=5e-4)
        assert r.ci95_mm[1] - r.ci95_mm[0] < 1e-3  # a 95 % interval narrower than 1 um


def test_lost_motion_needs_out_and_back():
    with pytest.raises(ValueError, match="out and back"):
        rs.lost_motion(np.linspace(0, 10, 3000), np.linspace(0, 10, 3000), H)


def test_the_component_measures_as_the_array_function(motion):
    """ServoSensors sample by sample (inputs scaled by ``scales``) gives measure_servo's samples for the same draws."""
    n = 300
    scales = {"i_d": math.sqrt(2), "i_q": math.sqrt(2), "x_table": 1e-3}
    comp = ServoSensors("servo", {"seed": 3, "scales": scales})
    comp.setup(0.0, H, n)
    rows = []
    for k in range(n):
        comp.set_inputs([motion[c][k] / scales.get(c, 1.0) for c in INPUTS])
        comp.step(k)
        rows.append(comp.get_outputs())
    got = np.array(rows)
    z = {c: np.random.default_rng([3, zlib.crc32(c.encode())]).standard_normal(BLOCK)[1:n + 1]
         for c in comp.config.channels()}
    want = measure_servo({c: motion[c][:n] for c in INPUTS}, comp.config, z=z)
    for j, name in enumerate(OUTPUTS):
        np.testing.assert_allclose(got[:, j], want[name], rtol=1e-12, atol=1e-12, err_msg=name)


def monitor_voltage_check(true: dict, u_loss: float, **channels) -> tuple[dict, list]:
    """cosim.monitor_servo's voltage check (``servo_checks``) of the measured motion, ``u_loss`` stated."""
    from feeddrive.cosim.monitor_servo import servo_checks
    from feeddrive.estimator.validation import ValidationOptions

    m = measured(true, **channels)
    sig = {k: m[k] for k in ("u_d_ref", "u_q_ref", "u_d", "u_q", "I_U", "I_V", "I_W")} | {"phi_el": 4 * true["theta"]}
    out, faults, _ = servo_checks(sig, H, 4, None, 1e-3, 0.005, 0.005, u_loss, ValidationOptions(), None)
    return out["voltage_reference_check"], faults


def test_an_unstated_dead_time_is_said_with_its_measured_loss_not_called_a_sensor_fault(motion):
    """The monitor not told the inverter's dead time (monitor.dead_time_loss_v; found by audit3: 4.8 V per leg
    unstated read "sensor fault: u_q or u_q_ref gain 0.9741; parameters not validated")."""
    from feeddrive.cosim.monitor_servo import servo_line
    from feeddrive.cosim.report.views import servo_rows

    check, faults = monitor_voltage_check(motion, 0.0)
    assert faults == [] and check["valid"]
    assert check["u_loss"] == pytest.approx(U_LOSS, rel=0.03) and check["u_loss_stated"] == 0.0
    assert ("not the 0 V stated (monitor.dead_time_loss_v, not given), and are checked with it: state "
            "monitor.dead_time_loss_v: 4.") in check["note"]
    assert check["u_loss_ci95"][0] < U_LOSS * 1.01 and check["u_loss_ci95"][1] > U_LOSS * 0.97
    servo = {"voltage_reference_check": check}
    assert "u_ref/u ok (dead time 4." in servo_line(servo) and "not the stated 0: state monitor.dead_time_loss_v" \
        in servo_line(servo)
    (row,) = servo_rows({"servo_checks": servo})
    assert not row["bad"] and row["decision"].startswith("valid with the measured loss: the references")
    stated, faults = monitor_voltage_check(motion, U_LOSS)  # stated: no note
    assert faults == [] and "u_loss_stated" not in stated and "note" not in stated


def test_a_voltage_sensor_fault_is_found_with_the_dead_time_unstated(motion):
    """A 1 V offset of u_q with the loss unstated: the unmodelled loss hid it (q residue offset -3.6 V, "valid"
    before); judged with the loss the data give (fitted beside each axis's gain and offset) it is a fault of u_q,
    its offset within 0.2 V (measured 0.86 V: the loss fitted beside the offset, 4.67 V for 4.8, leaves its
    share of the loss's mean), and the unstated loss is said beside it."""
    check, faults = monitor_voltage_check(motion, 0.0, u_q={"offset": 1.0})
    assert not check["valid"] and check["u_loss_stated"] == 0.0 and check["u_loss"] == pytest.approx(U_LOSS, rel=0.05)
    (fault,) = faults
    assert fault["sensor"] == "u_q or u_q_ref" and fault["offset"] == pytest.approx(1.0, abs=0.2), fault
    check, faults = monitor_voltage_check(motion, U_LOSS, u_q={"offset": 1.0})  # stated: the same fault, no note
    assert [f["sensor"] for f in faults] == ["u_q or u_q_ref"] and "u_loss_stated" not in check
