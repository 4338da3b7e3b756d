"""The PMSM feed drive (models.pmsm_drive) against the analytic dq equations."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from feeddrive.models import pmsm_drive

MODEL = pmsm_drive()
NOMINAL = MODEL.nominal()
STATES = [s.name for s in MODEL.states]
OUTPUTS = [o.name for o in MODEL.outputs]


def run(stop: float, w_ref: float = 0.0, u_d_in: float = 0.0, u_q_in: float = 0.0, model=MODEL,
        x0: dict[str, float] | None = None, **params: float) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Integrate the model's ODE (LSODA, tight tolerances) from rest; returns time and every output over it."""
    nominal = model.nominal() | params
    p = np.array([nominal[v.name] for v in model.parameters])
    u = np.array([w_ref, 0.0, u_d_in, u_q_in])
    f, g = model.rhs_function(), model.output_function()
    x_init = np.array([(x0 or {}).get(s.name, 0.0) for s in model.states])
    sol = solve_ivp(lambda t, x: np.asarray(f(x, u, p)).ravel(), (0.0, stop), x_init, method="LSODA",
                    rtol=1e-10, atol=1e-10, dense_output=True)
    assert sol.success, sol.message
    t = np.linspace(0.0, stop, 201)
    y = np.array([np.asarray(g(sol.sol(tk), u, p)).ravel() for tk in t])
    return t, {name: y[:, k] for k, name in enumerate(o.name for o in model.outputs)}


def final(stop: float, **kw) -> dict[str, float]:
    return {k: float(v[-1]) for k, v in run(stop, **kw)[1].items()}


def test_interface_matches_the_dc_model():
    assert [v.name for v in MODEL.inputs] == ["w_ref", "Tl", "u_d_in", "u_q_in"]
    assert {"i_q", "i_d", "u_q", "u_d", "w", "theta", "x", "torque"} <= set(OUTPUTS)
    assert [v.name for v in MODEL.of_kind("physical")] == ["R", "L_d", "L_q", "psi_f", "Jt", "ft", "Cd", "T0"]
    # every default carries its source and a unit, as in feed_drive.py
    assert all(v.source and v.unit for v in MODEL.parameters)
    # torque constant 1.5 p psi_f and back-EMF constant p psi_f of a 1FK7-class motor (catalogue order)
    kt = 1.5 * NOMINAL["p"] * NOMINAL["psi_f"]
    assert 1.0 < kt * math.sqrt(2) < 3.0  # N.m/A rms
    ke = NOMINAL["p"] * NOMINAL["psi_f"] * 1000 * math.pi / 30 * math.sqrt(3 / 2)  # V/1000 rpm, line-line rms
    assert 80 < ke < 160


def test_steady_state_below_base_speed_is_the_analytic_dq_solution():
    w = 100.0
    y = final(1.5, w_ref=w)
    p, psi, R, Lq = NOMINAL["p"], NOMINAL["psi_f"], NOMINAL["R"], NOMINAL["L_q"]
    assert y["w"] == pytest.approx(w, rel=1e-7)
    assert abs(y["i_d"]) < 1e-7
    # torque balance: 1.5 p psi_f i_q = ft w + Cd (tanh(w / w_eps) = 1 to 1e-300)
    assert 1.5 * p * psi * y["i_q"] == pytest.approx(NOMINAL["ft"] * w + NOMINAL["Cd"], rel=1e-7)
    assert y["torque"] == pytest.approx(NOMINAL["ft"] * w + NOMINAL["Cd"], rel=1e-7)
    assert y["u_q"] == pytest.approx(R * y["i_q"] + p * w * psi, rel=1e-7)
    assert y["u_d"] == pytest.approx(-p * w * Lq * y["i_q"], rel=1e-6)


def test_reluctance_torque_with_l_d_unequal_l_q():
    """Interior magnets (L_q = 1.8 L_d) in field weakening: i_d < 0 adds (L_d - L_q) i_d i_q > 0 to the torque,
    so the q current needed for the same load is smaller than the surface-magnet motor's."""
    w, Ld, Lq = 400.0, NOMINAL["L_d"], 1.8 * NOMINAL["L_d"]
    y = final(1.5, w_ref=w, L_q=Lq)
    p, psi, R = NOMINAL["p"], NOMINAL["psi_f"], NOMINAL["R"]
    load = NOMINAL["ft"] * w + NOMINAL["Cd"]
    assert y["w"] == pytest.approx(w, rel=1e-7)
    assert y["i_d"] < -5.0
    assert y["torque"] == pytest.approx(1.5 * p * (psi * y["i_q"] + (Ld - Lq) * y["i_d"] * y["i_q"]), rel=1e-9)
    assert y["torque"] == pytest.approx(load, rel=1e-7)
    reluctance = 1.5 * p * (Ld - Lq) * y["i_d"] * y["i_q"]
    assert reluctance / load > 0.1
    assert y["i_q"] < 0.9 * load / (1.5 * p * psi)
    assert y["u_q"] == pytest.approx(R * y["i_q"] + p * w * (psi + Ld * y["i_d"]), rel=1e-7)
    assert y["u_d"] == pytest.approx(R * y["i_d"] - p * w * Lq * y["i_q"], rel=1e-6)


def test_field_weakening_gives_negative_i_d_above_base_speed():
    w = 450.0  # p w psi_f = 414 V > u_max = 346 V: unreachable without weakening the field
    y = final(1.5, w_ref=w)
    wb, ifw = NOMINAL["w_base"], NOMINAL["i_fw"]
    assert y["w"] == pytest.approx(w, rel=1e-6)
    assert y["i_d"] == pytest.approx(-ifw * (1 - wb / w), rel=1e-6)
    assert math.hypot(y["u_d"], y["u_q"]) <= NOMINAL["u_max"] * (1 + 1e-9)
    # without field weakening the voltage limit stops the motor where p w psi_f + R i_q ~ u_max
    y0 = final(1.5, w_ref=w, fw=0.0)
    assert abs(y0["i_d"]) < 0.5
    assert y0["w"] < 0.9 * w
    assert math.hypot(y0["u_d"], y0["u_q"]) == pytest.approx(NOMINAL["u_max"], rel=1e-6)
    # below the base speed field weakening is idle
    assert abs(final(1.0, w_ref=0.5 * wb)["i_d"]) < 1e-7


def open_loop_exact(t: np.ndarray, w: float, Ld: float, Lq: float, ud: float, uq: float) -> np.ndarray:
    """(i_d, i_q) of the dq circuit at constant speed w under constant voltages, from rest; shape (len(t), 2)."""
    p, psi, R = NOMINAL["p"], NOMINAL["psi_f"], NOMINAL["R"]
    A = np.array([[-R / Ld, p * w * Lq / Ld, ud / Ld],
                  [-p * w * Ld / Lq, -R / Lq, (uq - p * w * psi) / Lq],
                  [0.0, 0.0, 0.0]])
    return np.array([expm(A * tk) @ np.array([0.0, 0.0, 1.0]) for tk in t])[:, :2]


#: open loop: the rotor held at a constant speed by a huge inertia (torque / Jt ~ 1e-8 rad/s^2), no friction
OPEN_LOOP = {"bypass": 1.0, "Jt": 1.0e9, "ft": 0.0, "Cd": 0.0}


def test_open_loop_voltage_step_matches_the_matrix_exponential():
    w, Ld, Lq, ud, uq = 200.0, NOMINAL["L_d"], 1.5 * NOMINAL["L_d"], -20.0, 220.0
    t, y = run(0.05, u_d_in=ud, u_q_in=uq, x0={"w": w}, L_q=Lq, **OPEN_LOOP)
    exact = open_loop_exact(t, w, Ld, Lq, ud, uq)
    got = np.column_stack([y["i_d"], y["i_q"]])
    assert np.max(np.abs(got - exact)) < 1e-6 * np.max(np.abs(exact))
    # the rotating coupling matters: the q current's steady state is not the uncoupled (uq - p w psi_f) / R
    assert abs(exact[-1, 1] - (uq - NOMINAL["p"] * w * NOMINAL["psi_f"]) / NOMINAL["R"]) > 1.0


def test_dead_time_subtracts_a_voltage_against_the_current():
    t_dead = 2e-6
    y = final(0.3, u_d_in=0.0, u_q_in=20.0, t_dead=t_dead, **OPEN_LOOP)  # 27 L/R: settled
    drop = 4 / math.pi * t_dead * NOMINAL["f_pwm"] * NOMINAL["u_dc"]
    norm = math.sqrt(y["i_d"] ** 2 + y["i_q"] ** 2 + NOMINAL["i_eps"] ** 2)
    assert y["u_q"] == pytest.approx(20.0 - drop * y["i_q"] / norm, rel=1e-9)
    assert y["u_d"] == pytest.approx(-drop * y["i_d"] / norm, abs=1e-9)
    # at standstill the circuit is R only: i_q = u_q / R with the dead-time loss (~12 V at 2 us, 8 kHz, 600 V)
    assert y["i_q"] == pytest.approx(y["u_q"] / NOMINAL["R"], rel=1e-6)
    assert y["i_q"] < 0.5 * 20.0 / NOMINAL["R"]


def test_surface_magnet_variant_ties_l_q_to_l_d():
    spm = pmsm_drive(surface=True)
    assert "L_q" not in spm.variables and spm.name == "PMSMFeedDriveSPM"
    y_spm = final(0.3, w_ref=150.0, model=spm)
    y_gen = final(0.3, w_ref=150.0)
    for name in ("i_q", "i_d", "u_q", "u_d", "w"):
        assert y_spm[name] == pytest.approx(y_gen[name], rel=1e-9, abs=1e-12)
