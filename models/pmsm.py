"""Permanent-magnet synchronous motor (PMSM) feed drive in the rotor (dq) frame, with its servo loops.

Physics (amplitude-invariant Park transform: dq quantities are phase peak values)::

    q axis       u_q = R i_q + L_q di_q/dt + p w (psi_f + L_d i_d)
    d axis       u_d = R i_d + L_d di_d/dt - p w L_q i_q
    torque       T = 1.5 p (psi_f i_q + (L_d - L_q) i_d i_q)
    mechanical   Jt dw/dt = T - ft w - Cd sgn_w - Tl - T0
    kinematics   dtheta/dt = w,   x = theta / (2 pi belt_ratio) * pitch

``w`` is the mechanical speed, ``p`` the number of pole pairs. The torque constant ``1.5 p psi_f`` and
the back-EMF constant ``p psi_f`` differ by 1.5, so the DC model's single K cannot describe this motor
(issue 25). A surface-magnet motor has ``L_d = L_q`` and no reluctance torque; ``pmsm_drive(surface=True)``
ties ``L_q`` to ``L_d`` (one inductance parameter), the default model keeps both.

Dry friction is smoothed as in ``feed_drive``, ``sgn_w = tanh(w / w_eps)``, with ``w_eps = 1e-2 rad/s``:
the servo's inertia is ~30 times smaller than the DC bench's, and ``Cd / (Jt w_eps)`` ~ 1.3e4 1/s keeps
the stiffest mode as far inside the RK4 stability region at the FMU's 1e-5 s substep as the DC model's.

Drive (field-oriented control, as a servo drive's 125 us cycle resolves it, here continuous):

* speed PI on the filtered reference (``tau_ref``, as the DC drive) -> ``i_q*``, limited to
  ``sqrt(i_max^2 - i_d*^2)`` so the current vector stays within ``i_max``;
* ``i_d* = 0`` (maximum torque per ampere of a surface-magnet motor). With ``fw = 1``, above the base
  speed ``w_base`` the flux is weakened as ``psi_f + L_d i_d* = psi_f w_base / |w|``, i.e.
  ``i_d* = -i_fw (1 - w_base / |w|)`` with ``i_fw = psi_f / L_d`` of the nominal motor (a controller
  setting, so a demagnetised motor does not change its controller), limited to ``-i_max``;
* two current PIs (d and q) -> voltage references, with back-calculation anti-windup;
* the PWM inverter as an average model: the voltage vector is limited to ``u_max = u_dc / sqrt(3)``
  (space-vector modulation's linear range), the d axis first (it keeps the field weakening working);
  with a dead time ``t_dead > 0`` each phase loses ``t_dead f_pwm u_dc`` against its current, whose
  fundamental in the dq frame is ``-(4 / pi) t_dead f_pwm u_dc i_dq / |i_dq|``, with ``|i_dq|``
  smoothed by ``i_eps`` (a smooth sign of the current, as for the dry friction).

With ``bypass = 1`` the loops are cut and the inverter receives ``u_d_in, u_q_in`` (open-loop tests).

Defaults are of the order of a Siemens 1FK7 compact servo motor of ~11 N.m stall torque (8 poles,
3000 rpm, 400 V mains -> 600 V DC link) on a 10 mm ball screw. They are catalogue-order values, not one
data sheet: each ``source`` says how the value was chosen.
"""
from __future__ import annotations

import math

import casadi as ca

from feeddrive.models.base import Equation, Model, Variable

_P = 4                       # pole pairs of the default motor (8 poles)
_PSI = 0.23                  # Wb
_L = 8.0e-3                  # H
_R = 0.7                     # Ohm
_JT = 3.0e-3                 # kg.m2
_KT = 1.5 * _P * _PSI        # N.m/A (peak), 1.38
_U_DC = 600.0                # V


def _sat(v: ca.SX, limit: ca.SX) -> ca.SX:
    return ca.fmin(ca.fmax(v, -limit), limit)


def _variables(surface: bool) -> list[Variable]:
    V = Variable
    cat = "1FK7-class servo motor (catalogue order, ~11 N.m stall, 3000 rpm)"
    out = [
        # states
        V("i_d", "A", "d-axis current (field)", "state", 0.0, output=True),
        V("i_q", "A", "q-axis current (torque)", "state", 0.0, output=True),
        V("w", "rad/s", "motor speed (mechanical)", "state", 0.0, output=True),
        V("theta", "rad", "motor angle (mechanical)", "state", 0.0, output=True),
        V("xi_w", "A", "speed PI integrator (q-current reference part)", "state", 0.0),
        V("xi_d", "V", "d-current PI integrator (voltage reference part)", "state", 0.0),
        V("xi_q", "V", "q-current PI integrator (voltage reference part)", "state", 0.0),
        V("w_rf", "rad/s", "speed reference after the drive's input filter", "state", 0.0),
        # inputs
        V("w_ref", "rad/s", "speed reference from the NC position loop", "input", 0.0),
        V("Tl", "N.m", "load torque of the cutting process", "input", 0.0),
        V("u_d_in", "V", "d voltage reference used when the loops are bypassed", "input", 0.0),
        V("u_q_in", "V", "q voltage reference used when the loops are bypassed", "input", 0.0),
        # physical parameters
        V("R", "Ohm", "stator phase resistance", "physical", _R,
          cat + ": phase resistance 0.6..0.8 Ohm at 20 C", lower=0.0, lower_strict=True),
        V("L_d", "H", "d-axis inductance" + (" (= q-axis, surface magnets)" if surface else ""), "physical", _L,
          cat + ": phase inductance 7..9 mH; L/R ~ 11 ms", lower=0.0, lower_strict=True),
    ]
    if not surface:
        out.append(V("L_q", "H", "q-axis inductance", "physical", _L,
                     cat + ": surface magnets, L_q = L_d (an interior-magnet motor has L_q > L_d)",
                     lower=0.0, lower_strict=True))
    out += [
        V("psi_f", "Wb", "permanent-magnet flux linkage (phase peak)", "physical", _PSI,
          cat + ": k_T = 1.5 p psi_f = 1.38 N.m/A peak (1.95 N.m/A rms), k_E ~ 118 V/1000 rpm line-line rms",
          lower=0.0, lower_strict=True),
        V("Jt", "kg.m2", "total inertia seen by the motor", "physical", _JT,
          "rotor ~1.5e-3 kg.m2 (" + cat + ") plus screw, coupling and table reflected through a 10 mm pitch",
          lower=0.0, lower_strict=True),
        V("ft", "N.m.s/rad", "total viscous friction coefficient", "physical", 1.5e-3,
          "0.45 N.m at 3000 rpm: a few % of the stall torque, typical of a preloaded ball-screw axis", lower=0.0),
        V("Cd", "N.m", "total dry (Coulomb) friction torque", "physical", 0.4,
          "screw-nut preload and guides: ~4 % of the stall torque", lower=0.0),
        V("T0", "N.m", "constant load torque (gravity on a vertical axis) or torque offset", "physical", 0.0,
          "horizontal axis, no offset", optional=True),
        # design parameters
        V("p", "1", "number of pole pairs", "design", float(_P), cat + ": 8 poles", lower=0.0, lower_strict=True,
          tunable=False),
        V("u_dc", "V", "inverter DC-link voltage", "design", _U_DC, "400 V mains, rectified (565 V) and regulated",
          lower=0.0, lower_strict=True),
        V("u_max", "V", "inverter voltage-vector limit (phase peak)", "design", _U_DC / math.sqrt(3),
          "u_dc / sqrt(3): linear range of space-vector modulation", lower=0.0, lower_strict=True),
        V("t_dead", "s", "inverter dead time (0: ideal inverter)", "design", 0.0,
          "off by default; IGBT inverters of this size use 1..3 us", lower=0.0),
        V("f_pwm", "Hz", "PWM frequency", "design", 8.0e3, "8 kHz: 125 us servo cycle, 1 PWM period per half cycle",
          lower=0.0, lower_strict=True),
        V("i_eps", "A", "current scale of the dead time's smooth sign", "design", 0.2,
          "a few % of the rated current: the dead-time distortion fades out around zero current",
          lower=0.0, lower_strict=True),
        V("i_max", "A", "current-vector limit (peak)", "design", 25.0,
          "~3x the stall current (8 A peak): the peak current of a servo drive", lower=0.0, lower_strict=True),
        V("fw", "1", "1: field weakening above w_base; 0: i_d* = 0 at all speeds", "design", 1.0,
          "on: idle below the base speed", lower=0.0, upper=1.0),
        V("w_base", "rad/s", "base speed, where field weakening begins", "design", 300.0,
          "~rated speed 3000 rpm: p w psi_f = 276 V leaves ~20 % of u_max for R i and L di/dt",
          lower=0.0, lower_strict=True),
        V("i_fw", "A", "field-weakening current scale psi_f / L_d of the nominal motor", "design", _PSI / _L,
          "psi_f / L_d of the defaults (characteristic current)", lower=0.0, lower_strict=True),
        V("Kp_i", "V/A", "current PI proportional gain (d and q)", "design", _L * 2 * math.pi * 1000,
          "L x 2 pi 1 kHz: a 1 kHz current loop (pole cancellation), as a 125 us servo cycle allows",
          lower=0.0, lower_strict=True),
        V("Ki_i", "V/(A.s)", "current PI integral gain (d and q)", "design", _R * 2 * math.pi * 1000,
          "R x 2 pi 1 kHz", lower=0.0),
        V("Kp_w", "A.s/rad", "speed PI proportional gain", "design", _JT * 2 * math.pi * 50 / _KT,
          "Jt x 2 pi 50 Hz / k_T: a 50 Hz speed loop", lower=0.0, lower_strict=True),
        V("Ki_w", "A/rad", "speed PI integral gain", "design", _JT * 2 * math.pi * 50 / _KT * 2 * math.pi * 10,
          "Kp_w x 2 pi 10 Hz: integral corner a fifth of the bandwidth", lower=0.0),
        V("pitch", "m", "ball-screw pitch (table travel per screw turn)", "design", 0.01,
          "10 mm: 3000 rpm is a 30 m/min rapid traverse", lower=0.0, lower_strict=True),
        V("belt_ratio", "1", "motor turns per screw turn (1 = direct drive)", "design", 1.0,
          "direct drive", lower=0.0, lower_strict=True),
        V("w_eps", "rad/s", "speed scale of the dry-friction smoothing tanh(w/w_eps)", "design", 1.0e-2,
          "see the module docstring", lower=0.0, lower_strict=True),
        V("tau_ref", "s", "time constant of the drive's speed-reference input filter", "design", 1.0e-3,
          "as the DC drive: keeps the voltages continuous between the NC's held reference samples",
          lower=0.0, lower_strict=True),
        V("bypass", "1", "1: loops bypassed, u_dq_ref = u_dq_in; 0: speed and current loops closed", "design",
          0.0, "closed loop", lower=0.0, upper=1.0, tunable=False),
        # algebraic signals
        V("sgn_w", "1", "smoothed sign of the speed (dry friction)", "algebraic"),
        V("i_d_ref", "A", "d-current reference (0, or field weakening)", "algebraic", output=True),
        V("i_q_ref", "A", "q-current reference from the speed PI", "algebraic", output=True),
        V("u_d_ref", "V", "the regulator's d voltage reference to the inverter", "algebraic", output=True),
        V("u_q_ref", "V", "the regulator's q voltage reference to the inverter", "algebraic", output=True),
        V("u_d", "V", "d-axis terminal voltage", "algebraic", output=True),
        V("u_q", "V", "q-axis terminal voltage", "algebraic", output=True),
        V("torque", "N.m", "air-gap torque", "algebraic", output=True),
        V("x", "m", "table position", "algebraic", output=True),
    ]
    return out


def pmsm_drive(surface: bool = False) -> Model:
    """Build the PMSM feed-drive model.

    Parameters
    ----------
    surface : bool
        False (default): separate ``L_d`` and ``L_q`` (their defaults are equal, a surface-magnet motor;
        set ``L_q != L_d`` for an interior-magnet one). True: the surface-magnet variant, ``L_q = L_d``
        with one inductance parameter ``L_d`` (model ``PMSMFeedDriveSPM``).

    Returns
    -------
    Model
        States ``i_d, i_q, w, theta, xi_w, xi_d, xi_q, w_rf``; inputs ``w_ref, Tl, u_d_in, u_q_in``;
        physical parameters ``R, L_d, (L_q,) psi_f, Jt, ft, Cd`` (and the optional offset ``T0``);
        outputs ``i_d, i_q, w, theta, i_d_ref, i_q_ref, u_d_ref, u_q_ref, u_d, u_q, torque, x``.
        The same interface as ``feed_drive()``: ``fmu_build`` wraps it without knowing the motor.
    """
    variables = _variables(surface)
    s = {v.name: v.sym for v in variables}
    L_d = s["L_d"]
    L_q = L_d if surface else s["L_q"]
    closed = s["bypass"] < 0.5
    i_d, i_q, w = s["i_d"], s["i_q"], s["w"]

    # current references: i_d* = 0 below the base speed, field weakening above; i_q* from the speed PI
    w_abs = ca.fabs(w)
    i_d_ref = ca.fmax(-s["fw"] * s["i_fw"] * (1 - s["w_base"] / ca.fmax(w_abs, s["w_base"])), -s["i_max"])
    i_q_lim = ca.sqrt(ca.fmax(s["i_max"] ** 2 - s["i_d_ref"] ** 2, 0))
    e_w = s["w_rf"] - w
    v_w = s["Kp_w"] * e_w + s["xi_w"]
    # current PIs -> voltage references (or the bypass inputs)
    e_d, e_q = s["i_d_ref"] - i_d, s["i_q_ref"] - i_q
    v_d = s["Kp_i"] * e_d + s["xi_d"]
    v_q = s["Kp_i"] * e_q + s["xi_q"]
    # voltage-vector limit, d axis first
    u_d_ref = ca.if_else(closed, _sat(v_d, s["u_max"]), s["u_d_in"])
    u_q_lim = ca.sqrt(ca.fmax(s["u_max"] ** 2 - ca.fmin(s["u_d_ref"] ** 2, s["u_max"] ** 2), 0))
    u_q_ref = ca.if_else(closed, _sat(v_q, u_q_lim), s["u_q_in"])
    # inverter average model: the limit, then the dead time's loss against the current vector
    u_d_lim = _sat(s["u_d_ref"], s["u_max"])
    u_q_out = _sat(s["u_q_ref"], ca.sqrt(ca.fmax(s["u_max"] ** 2 - u_d_lim ** 2, 0)))
    u_dead = 4 / math.pi * s["t_dead"] * s["f_pwm"] * s["u_dc"]
    i_norm = ca.sqrt(i_d ** 2 + i_q ** 2 + s["i_eps"] ** 2)

    algebraic = {
        "sgn_w": ca.tanh(w / s["w_eps"]),
        "i_d_ref": i_d_ref,
        "i_q_ref": _sat(v_w, i_q_lim),
        "u_d_ref": u_d_ref,
        "u_q_ref": u_q_ref,
        "u_d": u_d_lim - u_dead * i_d / i_norm,
        "u_q": u_q_out - u_dead * i_q / i_norm,
        "torque": 1.5 * s["p"] * (s["psi_f"] * i_q + (L_d - L_q) * i_d * i_q),
        "x": s["theta"] / (2 * math.pi * s["belt_ratio"]) * s["pitch"],
    }
    # back-calculation anti-windup, tracking time = integral time (Ki/Kp), as in the DC drive
    explicit = {
        "theta": w,
        "w_rf": (s["w_ref"] - s["w_rf"]) / s["tau_ref"],
        "xi_w": ca.if_else(closed, s["Ki_w"] * e_w + s["Ki_w"] / s["Kp_w"] * (s["i_q_ref"] - v_w), 0),
        "xi_d": ca.if_else(closed, s["Ki_i"] * e_d + s["Ki_i"] / s["Kp_i"] * (s["u_d_ref"] - v_d), 0),
        "xi_q": ca.if_else(closed, s["Ki_i"] * e_q + s["Ki_i"] / s["Kp_i"] * (s["u_q_ref"] - v_q), 0),
    }
    der = {v.name: ca.SX.sym("der_" + v.name) for v in variables if v.kind == "state"}
    p = s["p"]
    equations = [
        Equation("electrical_q", L_q * der["i_q"] + s["R"] * i_q + p * w * (s["psi_f"] + L_d * i_d) - s["u_q"],
                 solves_for="i_q", output="u_q", normaliser=None, paper_ref="eq. 1 in the dq frame (issue 25)"),
        Equation("electrical_d", L_d * der["i_d"] + s["R"] * i_d - p * w * L_q * i_q - s["u_d"],
                 solves_for="i_d", output="u_d", normaliser=None, paper_ref="issue 25 (no DC counterpart)"),
        # the torque is 1.5 p (psi_f i_q + (L_d - L_q) i_d i_q): psi_f scales the output i_q as K does in
        # eq. 5, through the known factor 1.5 p (the estimator's PMSM increment derives it from here)
        Equation("mechanical", s["Jt"] * der["w"] + s["ft"] * w + s["Cd"] * s["sgn_w"] + s["Tl"] + s["T0"]
                 - s["torque"], solves_for="w", output="i_q", normaliser="psi_f",
                 paper_ref="eq. 2 with the PMSM torque (issue 25)"),
    ]
    return Model(
        "PMSMFeedDriveSPM" if surface else "PMSMFeedDrive",
        variables,
        equations,
        explicit,
        algebraic,
        description="PMSM feed drive (dq frame, field-oriented control, speed and current PI loops, "
                    "average-model inverter)" + (", surface magnets (L_q = L_d)" if surface else ""),
        derivative_symbols=der,
    )
