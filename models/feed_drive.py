"""DC-motor feed drive (paper eq. 1 and 2) with its speed and current loops.

Physics (the paper's Fig. 2 chain: speed loop -> current loop -> converter -> motor -> drive chain)::

    electrical (eq. 1)   u = L di/dt + R i + K w
    mechanical (eq. 2)   K i = Jt dw/dt + ft w + Cd sgn_w + Tl + T0
    kinematics           dtheta/dt = w,   x = theta / (2 pi belt_ratio) * pitch

Dry friction. ``sign(w)`` is discontinuous at w = 0 and would stall any fixed-step or variable-step
integrator, so the plant uses ``sgn_w = tanh(w / w_eps)`` with ``w_eps = 1e-3 rad/s``. Above
``|w| = 10 w_eps`` (0.01 rad/s) the two differ by less than 5e-9, so an estimator that uses the
exact sign and excludes samples near zero speed sees no bias from the smoothing. The local stiffness
it adds, ``Cd / (Jt w_eps)`` ~ 1.2e4 1/s, is well inside the stability region of the FMU's RK4
substep (1e-5 s).

Drive. A speed PI (output: current reference, saturated at ``i_max``) and a current PI (output:
the regulator's voltage reference ``u_ref``, saturated at ``u_max``), both with back-calculation
anti-windup (tracking time = integral time). The power converter is a static gain ``Kc`` with
voltage saturation: ``u = sat(Kc u_ref, u_max)``. With ``bypass = 1`` the loops are cut, the
integrators are frozen and ``u_ref = u_in`` (identification experiments and analytic tests).

Reference filter. The NC's speed reference arrives as samples held over each communication step.
Through the proportional gains (Kp_i Kp_w ~ 150 V per rad/s) each held step would make the terminal
voltage jump by ~3 V during a 190 rad/s^2 ramp, and a voltage sampled at the end of each step would
then be biased against its average: the paper's electrical regression returned R 11 % low on
noise-free data. The drive low-passes its reference input (``tau_ref`` = 1 ms, as analog servo
drives do), so u is continuous and its samples are exact.

Defaults resemble the paper's bench (CEM T7F3B-1, 5.6 kW DC motor; a 3.5 s high-speed motion up to
about 70 rad/s, about 80 V, currents between -15 and 20 A). The paper gives no parameter values;
each ``source`` says how a default was chosen.
"""
from __future__ import annotations

import math

import casadi as ca

from feeddrive.models.base import Equation, Model, Variable


def _sat(v: ca.SX, limit: ca.SX) -> ca.SX:
    return ca.fmin(ca.fmax(v, -limit), limit)


def feed_drive(backlash: bool = False) -> Model:
    """Build the feed-drive model.

    Parameters
    ----------
    backlash : bool
        False (default): the paper's rigid drive chain, eq. 1 and 2. True: the variant
        ``FeedDriveBacklash``, a plant the monitor's model does NOT describe (paper IV.B.3): the
        inertia is split into a motor part ``(1 - load_fraction) Jt`` and a load part
        ``load_fraction Jt`` coupled through a stiff, damped spring with a dead zone of width
        ``backlash`` [rad, motor side]; friction acts on the load. Used to provoke a model mismatch.

    Returns
    -------
    Model
        States ``i, w, theta, xi_w, xi_i, w_rf`` (plus ``wl, thetal`` with backlash); inputs
        ``w_ref, Tl, u_in``; physical parameters ``R, L, K, Jt, ft, Cd`` (and the optional offset
        ``T0``); outputs ``i, w, theta, i_ref, u_ref, u, x``.
    """
    V = Variable
    bench = "chosen so that the paper's bench figures follow (70 rad/s, ~80 V, -15..20 A)"
    variables = [
        # states
        V("i", "A", "armature current", "state", 0.0, output=True),
        V("w", "rad/s", "motor speed", "state", 0.0, output=True),
        V("theta", "rad", "motor angle", "state", 0.0, output=True),
        V("xi_w", "A", "speed PI integrator (current reference part)", "state", 0.0),
        V("xi_i", "V", "current PI integrator (voltage reference part)", "state", 0.0),
        V("w_rf", "rad/s", "speed reference after the drive's input filter", "state", 0.0),
        # inputs
        V("w_ref", "rad/s", "speed reference from the NC position loop", "input", 0.0),
        V("Tl", "N.m", "load torque of the cutting process", "input", 0.0),
        V("u_in", "V", "voltage reference used when the loops are bypassed", "input", 0.0),
        # physical parameters (estimated by the monitor)
        V("R", "Ohm", "armature resistance", "physical", 0.6,
          "typical armature resistance of a 5.6 kW, ~200 V DC servo motor", lower=0.0, lower_strict=True),
        V("L", "H", "armature inductance", "physical", 4.0e-3,
          "electrical time constant L/R ~ 7 ms, typical of DC servo motors", lower=0.0, lower_strict=True),
        V("K", "N.m/A", "torque / back-EMF constant (V.s/rad)", "physical", 1.05,
          "K w ~ 74 V at 70 rad/s: the paper's ~80 V at top speed", lower=0.0, lower_strict=True),
        V("Jt", "kg.m2", "total inertia seen by the motor", "physical", 0.1,
          bench + ": a 0.38 s ramp to 70 rad/s needs ~20 A", lower=0.0, lower_strict=True),
        V("ft", "N.m.s/rad", "total viscous friction coefficient", "physical", 0.02,
          bench + ": with Cd, the -15/+20 A asymmetry of accel/decel", lower=0.0),
        V("Cd", "N.m", "total dry (Coulomb) friction torque", "physical", 1.2,
          "the issue's example scenario value", lower=0.0),
        V("T0", "N.m", "constant load torque (gravity on a vertical axis) or torque offset", "physical", 0.0,
          "horizontal axis, no offset", optional=True),
        # design parameters (known)
        V("Kc", "1", "power converter gain", "design", 1.0, "ideal converter"),
        V("u_max", "V", "converter voltage limit", "design", 150.0, "DC bus of a ~200 V drive with margin",
          lower=0.0, lower_strict=True),
        V("i_max", "A", "current reference limit", "design", 30.0, "peak current ~1.5x the paper's 20 A",
          lower=0.0, lower_strict=True),
        V("Kp_i", "V/A", "current PI proportional gain", "design", 4.0e-3 * 2 * math.pi * 500,
          "L x 2 pi 500 Hz: a 500 Hz current loop (pole cancellation)", lower=0.0, lower_strict=True),
        V("Ki_i", "V/(A.s)", "current PI integral gain", "design", 0.6 * 2 * math.pi * 500,
          "R x 2 pi 500 Hz", lower=0.0),
        V("Kp_w", "A.s/rad", "speed PI proportional gain", "design", 0.1 * 2 * math.pi * 20 / 1.05,
          "Jt x 2 pi 20 Hz / K: a 20 Hz speed loop", lower=0.0, lower_strict=True),
        V("Ki_w", "A/rad", "speed PI integral gain", "design", 0.1 * 2 * math.pi * 20 / 1.05 * 2 * math.pi * 4,
          "Kp_w x 2 pi 4 Hz: integral corner a fifth of the bandwidth", lower=0.0),
        V("pitch", "m", "ball-screw pitch (table travel per screw turn)", "design", 0.02,
          "20 mm: 70 rad/s is a 0.22 m/s rapid traverse", lower=0.0, lower_strict=True),
        V("belt_ratio", "1", "motor turns per screw turn (1 = direct drive)", "design", 1.0,
          "direct drive", lower=0.0, lower_strict=True),
        V("w_eps", "rad/s", "speed scale of the dry-friction smoothing tanh(w/w_eps)", "design", 1.0e-3,
          "see the module docstring", lower=0.0, lower_strict=True),
        V("tau_ref", "s", "time constant of the drive's speed-reference input filter", "design", 1.0e-3,
          "analog servo drives low-pass their reference input; it also keeps u continuous between the "
          "NC's held reference samples (see the module docstring)", lower=0.0, lower_strict=True),
        V("bypass", "1", "1: loops bypassed, u_ref = u_in; 0: speed and current loops closed", "design",
          0.0, "closed loop", lower=0.0, upper=1.0, tunable=False),
        # algebraic signals
        V("sgn_w", "1", "smoothed sign of the speed (dry friction)", "algebraic"),
        V("i_ref", "A", "current reference from the speed PI", "algebraic", output=True),
        V("u_ref", "V", "the regulator's voltage reference to the converter", "algebraic", output=True),
        V("u", "V", "armature (terminal) voltage", "algebraic", output=True),
        V("x", "m", "table position", "algebraic", output=True),
    ]
    if backlash:
        variables += [
            V("wl", "rad/s", "load speed (motor side)", "state", 0.0),
            V("thetal", "rad", "load angle (motor side)", "state", 0.0),
            V("backlash", "rad", "dead-zone width of the drive chain (motor side)", "design", 0.02,
              "~64 um at the table with a 20 mm pitch: a worn ball-screw nut", lower=0.0),
            V("load_fraction", "1", "share of Jt on the load side of the backlash", "design", 0.6,
              "table and screw dominate the reflected inertia", lower=0.0, upper=1.0),
            V("k_s", "N.m/rad", "drive-chain stiffness in contact", "design", 2.0e4,
              "first torsional mode ~ 100 Hz", lower=0.0, lower_strict=True),
            V("c_s", "N.m.s/rad", "drive-chain damping in contact", "design", 10.0,
              "damping ratio ~ 0.2 of the torsional mode", lower=0.0),
        ]
    s = {v.name: v.sym for v in variables}
    closed = s["bypass"] < 0.5

    # speed PI -> current reference, on the filtered reference
    e_w = s["w_rf"] - s["w"]
    v_w = s["Kp_w"] * e_w + s["xi_w"]
    i_ref = _sat(v_w, s["i_max"])
    # current PI -> voltage reference (or the bypass input)
    e_i = s["i_ref"] - s["i"]
    v_i = s["Kp_i"] * e_i + s["xi_i"]
    u_ref = ca.if_else(closed, _sat(v_i, s["u_max"]), s["u_in"])

    w_fric = s["wl"] if backlash else s["w"]
    algebraic = {
        "sgn_w": ca.tanh(w_fric / s["w_eps"]),
        "i_ref": i_ref,
        "u_ref": u_ref,
        "u": _sat(s["Kc"] * s["u_ref"], s["u_max"]),
        "x": (s["thetal"] if backlash else s["theta"]) / (2 * math.pi * s["belt_ratio"]) * s["pitch"],
    }
    # back-calculation anti-windup, tracking time = integral time (Ki/Kp)
    explicit = {
        "theta": s["w"],
        "w_rf": (s["w_ref"] - s["w_rf"]) / s["tau_ref"],
        "xi_w": ca.if_else(closed, s["Ki_w"] * e_w + s["Ki_w"] / s["Kp_w"] * (s["i_ref"] - v_w), 0),
        "xi_i": ca.if_else(closed, s["Ki_i"] * e_i + s["Ki_i"] / s["Kp_i"] * (s["u_ref"] - v_i), 0),
    }
    der = {v.name: ca.SX.sym("der_" + v.name) for v in variables if v.kind == "state"}
    electrical = Equation(
        "electrical",
        s["L"] * der["i"] + s["R"] * s["i"] + s["K"] * s["w"] - s["u"],
        solves_for="i", output="u", normaliser=None, paper_ref="eq. 1, 4",
    )
    if backlash:
        return _with_backlash(variables, s, der, electrical, explicit, algebraic)
    equations = [
        electrical,
        Equation(
            "mechanical",
            s["Jt"] * der["w"] + s["ft"] * s["w"] + s["Cd"] * s["sgn_w"] + s["Tl"] + s["T0"]
            - s["K"] * s["i"],
            solves_for="w", output="i", normaliser="K", paper_ref="eq. 2, 5",
        ),
    ]
    return Model(
        "FeedDrive",
        variables,
        equations,
        explicit,
        algebraic,
        description="DC-motor feed drive with speed and current PI loops (Habbadi et al., SDEMPED'99)",
        derivative_symbols=der,
    )


def _with_backlash(variables, s, der, electrical, explicit, algebraic) -> Model:
    """Two-inertia drive chain with a dead zone (see ``feed_drive(backlash=True)``)."""
    half_gap = s["backlash"] / 2
    twist = s["theta"] - s["thetal"]
    # dead zone: no torque while the twist is inside the gap; damping only in contact
    spring = twist - ca.fmin(ca.fmax(twist, -half_gap), half_gap)
    in_contact = ca.fabs(twist) > half_gap
    t_chain = s["k_s"] * spring + ca.if_else(in_contact, s["c_s"] * (s["w"] - s["wl"]), 0)
    j_motor = (1 - s["load_fraction"]) * s["Jt"]
    j_load = s["load_fraction"] * s["Jt"]
    equations = [
        electrical,
        Equation("mechanical", j_motor * der["w"] + t_chain - s["K"] * s["i"],
                 solves_for="w", output="i", normaliser="K", paper_ref="eq. 2 (motor side)"),
        Equation("load", j_load * der["wl"] + s["ft"] * s["wl"] + s["Cd"] * s["sgn_w"] + s["Tl"] + s["T0"]
                 - t_chain, solves_for="wl", output="wl", normaliser=None, paper_ref="not in the paper"),
    ]
    return Model(
        "FeedDriveBacklash",
        variables,
        equations,
        {**explicit, "thetal": s["wl"]},
        algebraic,
        description="feed drive with backlash in the drive chain (a plant the monitor's model does not describe)",
        derivative_symbols=der,
    )
