"""A servo drive's (PMSM) recording for ``cosim monitor --drive pmsm``: its roles and the monitor signals they give.

A drive's trace holds what the drive measures and commands, in its own units; each role is converted to SI by
its column's unit (``recorded.si_factor``: pint, ``[rpm]``, ``[mm]``, ``[mA]``; ``[A rms]`` on a dq current is
converted to the amplitude-invariant peak, x sqrt 2, and said so; a column without a unit is taken as SI):

===================  ======  ===========================================================================
role                 SI      meaning
===================  ======  ===========================================================================
i_q, i_d             A       the drive's dq currents (phase peak; ``[A rms]`` converted)
u_q, u_d             V       terminal voltages (dq)
u_q_ref, u_d_ref     V       the current regulator's voltage references u_q*, u_d*
I_U, I_V, I_W        A       phase currents: two or three
I_U2, I_V2, I_W2     A       a second current sensor on that phase (at most one)
phi_el               rad     the drive's electrical angle (else ``p * position + --angle-offset``)
x_lin                m       table position on a linear scale (``[mm]``), against the motor encoder
speed, position      rad/s   n_act ``[rpm]``; the motor encoder's angle (or a table position with ``--pitch``)
===================  ======  ===========================================================================

What the trace lacks the monitor derives (``monitor_servo.complete_signals``): the dq currents from the phase
currents (Park at the electrical angle), the third phase current from two, the terminal voltages from the
references less the dead time's loss; each check this makes void says so. Required: a q and a d current
(or two phase currents and an angle), a q and a d voltage (or their references), a speed or a position.
"""
from __future__ import annotations

import argparse
import math

import numpy as np

from feeddrive.cosim.errors import InputError

#: role -> the monitor's signal (cosim/monitor_servo.py; the q axis as the DC monitor's Im1 and u)
PMSM_ROLES = {"i_q": "Im1", "i_d": "i_d", "u_q": "u", "u_d": "u_d", "u_q_ref": "u_q_ref", "u_d_ref": "u_d_ref",
              "I_U": "I_U", "I_V": "I_V", "I_W": "I_W", "I_U2": "I_2", "I_V2": "I_2", "I_W2": "I_2",
              "phi_el": "phi_el", "x_lin": "x_lin"}
#: the second current sensor's role -> its phase
SECOND = {"I_U2": "U", "I_V2": "V", "I_W2": "W"}
PHASE_ROLES = ("I_U", "I_V", "I_W")


def missing_roles(role_map: dict[str, str]) -> list[str]:
    """The required roles a PMSM recording's ``--map`` lacks (each with its alternatives); InputError for two
    second sensors."""
    have = set(role_map)
    seconds = sorted(have & set(SECOND))
    if len(seconds) > 1:
        raise InputError(f"--map: {' and '.join(seconds)}: a second current sensor on one phase only; expected one "
                         f"of {', '.join(SECOND)}")
    park = len(have & set(PHASE_ROLES)) >= 2 and bool(have & {"phi_el", "position"})
    out = []
    for dq in ("i_q", "i_d"):
        if dq not in have and not park:
            out.append(f"{dq} (or two of {', '.join(PHASE_ROLES)} with phi_el or position)")
    for u in ("u_q", "u_d"):
        if u not in have and f"{u}_ref" not in have:
            out.append(f"{u} (or {u}_ref)")
    return out


def second_phase(role_map: dict[str, str]) -> str:
    """The phase of the mapped second current sensor (``I_V2`` -> ``V``); U when none is mapped."""
    return next((SECOND[r] for r in role_map if r in SECOND), "U")


def servo_signals(signals: dict[str, np.ndarray], args: argparse.Namespace,
                  pole_pairs: int) -> dict[str, np.ndarray]:
    """The monitor's PMSM signals of a recording's roles (SI, the position on the motor side).

    Parameters
    ----------
    signals : dict of str to ndarray, shape (n,)
        Role -> values (``Recording.signals`` after ``to_motor_side``).
    args : argparse.Namespace
        ``angle_offset`` [rad, electrical], ``pitch`` [m] and ``ratio`` (the motor encoder on the table side).
    pole_pairs : int

    Returns
    -------
    dict of str to ndarray
        ``PMSM_ROLES``' signals, ``theta_enc`` (the motor angle [rad]), ``phi_el`` [rad] and ``x_mot`` [m].
    """
    out = {PMSM_ROLES[r]: v for r, v in signals.items() if r in PMSM_ROLES}
    offset = getattr(args, "angle_offset", None)
    if offset is not None and "phi_el" in signals:
        raise InputError("--angle-offset: the electrical angle is mapped (phi_el); the offset applies to the "
                         "encoder's angle only: give one of them")
    if "x_lin" in signals and getattr(args, "pitch", None) is None:
        raise InputError("--map x_lin: the linear scale is compared with the motor encoder on the table side; give "
                         "--pitch (and --ratio) to put the encoder there")
    if "x_lin" in signals and "position" not in signals:
        raise InputError("--map x_lin: the linear scale needs the motor encoder to compare with; map position")
    if "position" in signals:
        theta = np.asarray(signals["position"], float)
        out["theta_enc"] = theta
        if "phi_el" not in out:
            out["phi_el"] = pole_pairs * theta + (offset or 0.0)
        if "x_lin" in signals:
            out["x_mot"] = theta * args.pitch / (2 * math.pi * args.ratio)
    elif offset is not None:
        raise InputError("--angle-offset: no encoder angle to offset; map position (the motor encoder)")
    return out


def unit_notes(columns: dict[str, str], units: dict[str, str]) -> list[str]:
    """What the units did that a reader must know: a dq current given as an rms value, converted to the peak."""
    return [f"{role}: {columns[role]!r} is an rms value: x sqrt 2 = x {math.sqrt(2):.6g} to the phase peak "
            "(amplitude-invariant dq)" for role, unit in units.items() if "rms" in unit]
