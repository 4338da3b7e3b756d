"""The vendor PMSM's own phase currents measured by the servo sensors (audit3).

The servo sensors made the phase currents from the mapped dq currents (inverse Park). A vendor PMSM whose q current
is an rms value mapped without its factor (``current: {var: I_q_rms}``: x 0.707, accepted by the units) then had
phase currents made from that same wrong i_q, so the Park check agreed with it (gain 0.9993), and the monitor validated
R = 0.975 (truth 0.7), L_q = 0.0113 (0.008) and Jt = 0.00212 (0.003) as a healthy motion: every equation scales with
the current. With ``phase_currents: measured`` the sensors measure the FMU's I_U, I_V, I_W, and the q current of
their Park transform is the drive's, sqrt(2) times the mis-mapped one (the monitor: "sensor fault: i_q gain 0.7069").
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from feeddrive.cosim.master import Master
from feeddrive.cosim.scenario import scenario_from_dict
from feeddrive.estimator.redundancy_servo import dq_current_consistency

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "plants"))
from vendor_pmsm import ROLE_MAP, TRUTH  # noqa: E402

SERVO_INPUTS = {"i_d": "plant.I_d_rms", "i_q": "plant.current", "theta": "plant.phi_el", "u_d_ref": "plant.U_d_soll",
                "u_q_ref": "plant.voltage_ref", "u_d": "plant.U_d", "u_q": "plant.voltage", "x_table": "plant.s_lin_mm"}
PHASES = {"i_u": "plant.I_U", "i_v": "plant.I_V", "i_w": "plant.I_W"}


def scenario(fmu: Path, phase_currents: str) -> dict:
    """The README's vendor PMSM wiring with the q current's rms factor forgotten; 0.25 s of a rapid at 1800 rpm."""
    servo = {"name": "servo", "class": "feeddrive.cosim.sensors_servo:ServoSensors",
             "config": {"scales": {"i_d": math.sqrt(2), "theta": 1 / TRUTH["p"], "x_table": 1e-3},
                        "phase_currents": phase_currents, "seed": 1},
             "inputs": SERVO_INPUTS | (PHASES if phase_currents == "measured" else {})}
    return {"name": "rms", "axis": {"name": "X", "pitch": 0.01}, "step": 1e-4, "stop_time": 0.25,
            "plant": {"fmu": str(fmu), "map": ROLE_MAP | {"current": {"var": "I_q_rms"}}},
            "sensors": {"seed": 1}, "components": [servo],
            "nc": {"program": [{"rapid": {"to": 0.05, "v_max": 0.3, "accel": 3.0}}]}}


@pytest.mark.parametrize("phase_currents, gain", [("dq", 1.0), ("measured", 1 / math.sqrt(2))])
def test_the_plants_own_phase_currents_catch_an_rms_current_mapped_as_a_peak(vendor_pmsm_fmu, phase_currents, gain):
    with Master.from_scenario(scenario_from_dict(scenario(vendor_pmsm_fmu, phase_currents))) as master:
        s = master.run().signals()
    assert np.abs(s["plant.current"]).max() > 1.0  # the rapid's acceleration current [A]
    phases = [s[f"servo.I_{p}"] for p in "UVW"]
    check = dq_current_consistency(s["sensors.Im1"], *phases, TRUTH["p"] * s["sensors.theta_enc"])
    # measured: the drive's phase currents, against which the mis-mapped i_q is 0.707; dq: made from it, they agree
    assert check.gain == pytest.approx(gain, abs=0.01)
    assert check.faulty is (phase_currents == "measured")
