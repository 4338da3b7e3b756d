"""The servo sensors (``cosim.sensors_servo.ServoSensors``) in the compiled fine loop.

A PMSM axis has the servo sensors right after the standard sensors, stepped at the plant's rate (their interval
means and low-pass filters) or at the recording rate. In Python they ended every block of the compiled loop (a
Python component stepping at every recording step): a PMSM run then left the compiled loop at every sample and
stepped the servo sensors in the interpreter. ``fineloop.c`` (``servo_step``) steps them inside the block
instead, with the arithmetic of ``ServoSensors._fine``, ``_true`` and ``_sample`` in the same order, so the
outputs are bit-identical (tests/cosim/test_fastloop_servo.py); their noise is drawn in Python, a block of
``sensors.BLOCK`` rows at a time, as ``ServoSensors`` draws it.

:func:`candidate` decides whether the compiled loop takes them; :func:`load`, :func:`changed`, :func:`new_rows`
and :func:`sync` move their state between the component and the loop's ``fine_t``.
"""
from __future__ import annotations

import ctypes
import math
from typing import Any

_d, _l = ctypes.c_double, ctypes.c_long


def candidate(master: Any, plant: Any, sensors: Any, max_sections: int) -> Any:
    """The ``ServoSensors`` component the compiled loop can step, or None.

    It must follow the standard sensors in the stepping order, step every tick (``fine_rate``, its
    ``oversample`` the master's) or at every recording step, read only the plant's and the sensors' outputs or
    numbers, and feed neither the plant nor the NC (they hold their inputs over a block).
    """
    from feeddrive.cosim.sensors_servo import ServoSensors

    names = list(master.components)
    j = names.index("sensors") + 1
    if j >= len(names):
        return None
    name = names[j]
    servo = master.components[name]
    if type(servo) is not ServoSensors or servo.config.phase_currents != "dq":  # C makes the phases from i_d, i_q
        return None
    rate = master.rates[name]
    if servo.fine_rate and (rate != 1 or servo.config.oversample != master.m):
        return None
    if not servo.fine_rate and rate != master.m:
        return None
    a, b = master._slices[plant][0], master._slices[sensors][1]
    n_sig = master.n_signals
    if not all(a <= i < b or i >= n_sig for i in master._input_index[name]):
        return None
    sa, sb = master._slices[servo]
    feeds = [i for n in ("plant", "nc") if n in master._input_index for i in master._input_index[n]]
    if any(sa <= i < sb for i in feeds):
        return None
    if any(len(coefs) > max_sections for _, coefs, _ in servo._filters):
        return None
    return servo


def load(fine: Any, master: Any, servo: Any) -> None:
    """The servo sensors' ports, settings and state into ``fine.s``; their outputs are ``fine.out[fine.sv:]``."""
    s, a, n_sig, Y0 = fine.s, fine.a, master.n_signals, master._constants
    src = master._input_index[list(master.components)[list(master.components.values()).index(servo)]]
    fine._sv_src = (_l * 8)(*[-1 if i >= n_sig else i - a for i in src])
    fine._sv_const = (_d * 8)(*[Y0[i - n_sig] if i >= n_sig else 0.0 for i in src])
    fine._sv_scale = (_d * 8)(*servo._scales)
    fine._sv_weights = (_d * len(servo._weights))(*servo._weights)
    s.sv_src, s.sv_const = ctypes.addressof(fine._sv_src), ctypes.addressof(fine._sv_const)
    s.sv_scale, s.sv_weights = ctypes.addressof(fine._sv_scale), ctypes.addressof(fine._sv_weights)
    s.sv_fine = int(servo.fine_rate)
    s.sv_kinds[:] = servo._kinds
    s.sv_second, s.sv_copy_iu = servo._second, int(servo.config.second_sensor_on is None)
    # the constants as the component computes them (its int pole pairs times a float, its angles)
    s.sv_p, s.sv_sin120, s.sv_inv_m = float(servo._p), math.sqrt(3.0) / 2, 1.0 / servo._m
    s.sv_angle[:] = (0.0, 2 * math.pi / 3, 4 * math.pi / 3)
    s.sv_acc[:] = servo._acc
    s.sv_lp[:] = servo._lp
    s.sv_nfilt = len(servo._filters)
    for f, (j, coefs, states) in enumerate(servo._filters):
        s.sv_filt_channel[f], s.sv_filt_sections[f] = j, len(coefs)
        for k, (c, z) in enumerate(zip(coefs, states)):
            s.sv_coefs[(f * fine.max_sections + k) * 5:(f * fine.max_sections + k + 1) * 5] = c
            s.sv_zst[(f * fine.max_sections + k) * 2:(f * fine.max_sections + k + 1) * 2] = z
    s.sv_q, s.sv_conv, s.sv_res = servo._q, servo._conv, servo.config.scale.resolution
    fine.sv = master._slices[servo][0] - a
    fine.out[fine.sv:fine.sv + 11] = servo._y
    s.sv_out = ctypes.addressof(fine.out) + fine.sv * ctypes.sizeof(_d)
    s.sv_block = len(servo._zarr)
    changed(fine, servo)
    new_rows(fine, servo, reset=False)
    s.sv = 1


def changed(fine: Any, servo: Any) -> None:
    """The channels' gain, offset and noise (an event changed one) into the loop."""
    from feeddrive.cosim.sensors_servo import OUTPUTS

    s, p = fine.s, servo._params
    channels = [*OUTPUTS[:8], "encoder", "scale"]
    s.sv_gain[:] = [p[c]["gain"] for c in channels]
    s.sv_offset[:] = [p[c]["offset"] for c in channels]
    s.sv_noise[:] = [p[c]["noise"] for c in channels]


def new_rows(fine: Any, servo: Any, reset: bool = True) -> None:
    """A new block of noise draws (``reset``: drawn now, as ``ServoSensors._sample`` would at this sample)."""
    s = fine.s
    if reset:
        servo._new_block()
    fine._sv_z = servo._zarr  # kept alive while the loop reads it
    s.sv_z, s.sv_k = servo._zarr.ctypes.data, servo._k


def sync(fine: Any, servo: Any) -> None:
    """The loop's servo state back into the component (after a block, or a failure)."""
    s, ms = fine.s, fine.max_sections
    servo._acc, servo._lp, servo._k = list(s.sv_acc), list(s.sv_lp), s.sv_k
    for f, (_, _, states) in enumerate(servo._filters):
        for k, z in enumerate(states):
            z[:] = s.sv_zst[(f * ms + k) * 2:(f * ms + k + 1) * 2]
    servo._y = fine.out[fine.sv:fine.sv + 11]
