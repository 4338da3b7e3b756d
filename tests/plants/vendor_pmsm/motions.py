"""Out-and-back motions of the vendor PMSM FMU (fmpy), measured by the servo sensors: the lost-motion campaign.

One motion: at rest 20 ms, ``+n`` rpm for ``t_run``, ``-n`` rpm for ``t_run``, at rest 50 ms (the speed command
held, as the vendor's FMU holds it), sampled every ``h``. Used by tests/estimator/test_redundancy_servo.py (a
small campaign) and benchmarks/bench_lost_motion.py (the full one).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from fmpy import simulate_fmu

from feeddrive.cosim.sensors_servo import measure_servo
from feeddrive.estimator.redundancy_servo import lost_motion

OUTPUTS = ["I_d_rms", "I_q_rms", "phi_el", "U_d_soll", "U_q_soll", "U_d", "U_q", "s_mot_mm", "s_lin_mm", "n_ist"]


def out_and_back(fmu: Path | str, n_rpm: float, t_run: float, lost_motion_mm: float = 0.0, h: float = 1e-4,
                 parameters: dict | None = None) -> dict[str, np.ndarray]:
    """The true signals of one out-and-back motion, in the servo sensors' units (``cosim.sensors_servo.INPUTS``)."""
    t0, t1, t2, stop = 0.02, 0.02 + t_run, 0.02 + 2 * t_run, 0.07 + 2 * t_run
    start = {"lost_motion_mm": lost_motion_mm} | (parameters or {})
    load = start.pop("M_last", 0.0)  # an input: given with the signal (fmpy warns of inputs it is not given)
    signal = np.array([(t, n, load) for t, n in ((0.0, 0.0), (t0, 0.0), (t0, n_rpm), (t1, n_rpm), (t1, -n_rpm),
                                                 (t2, -n_rpm), (t2, 0.0), (stop, 0.0))],
                      dtype=[("time", float), ("n_soll", float), ("M_last", float)])
    r = simulate_fmu(str(fmu), start_values=start, stop_time=stop, output_interval=h, input=signal, output=OUTPUTS)
    p = start.get("p", 4.0)
    return {"i_d": math.sqrt(2) * r["I_d_rms"], "i_q": math.sqrt(2) * r["I_q_rms"], "theta": r["phi_el"] / p,
            "u_d_ref": r["U_d_soll"], "u_q_ref": r["U_q_soll"], "u_d": r["U_d"], "u_q": r["U_q"],
            "x_table": r["s_lin_mm"] * 1e-3, "s_mot_mm": r["s_mot_mm"]}


def campaign(fmu: Path | str, motions: int, lost_motion_mm: float, seed: int = 0, alpha: float = 0.01,
             h: float = 1e-4, parameters: dict | None = None, allowed_mm: float = 0.0) -> list:
    """``motions`` random out-and-back motions (300..1500 rpm, 0.1..0.25 s each way; sensor noise seeded per motion)
    with the plant's lost motion ``lost_motion_mm`` (and its ``parameters``, e.g. ``ELASTIC``); each one's
    ``redundancy_servo.LostMotion`` tested against ``allowed_mm`` at ``alpha``."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(motions):
        n_rpm, t_run = rng.uniform(300.0, 1500.0), rng.uniform(0.1, 0.25)
        true = out_and_back(fmu, n_rpm, t_run, lost_motion_mm, h, parameters)
        meas = measure_servo(true, {"seed": seed * 100_000 + k})
        out.append(lost_motion(meas["x_mot"] * 1e3, meas["x_lin"] * 1e3, h, alpha=alpha, allowed_mm=allowed_mm))
    return out
