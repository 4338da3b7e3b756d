"""Closed-loop plant data for the estimator tests, simulated from the model with CasADi.

RK4 at 1e-5 s substeps of the full model (``estimator.design.simulate_closed_loop``: speed and current
loops, converter, smoothed dry friction), trapezoidal round trip of the speed reference, output every
``h``. Also the FMU run (fmpy) and the noise used by the statistical tests.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from feeddrive.estimator.design import simulate_closed_loop
from feeddrive.models import feed_drive

H = 1e-4
TRUTH = feed_drive().nominal(("physical",))
#: (time [s], w_ref [rad/s]) corners: 0 -> +70 -> 0 -> -70 -> 0 rad/s, ramps of 70/0.38 = 184 rad/s^2.
RAMP = 0.38
CORNERS = np.cumsum([0, 0.1, RAMP, 0.8, RAMP, 0.2, RAMP, 0.8, RAMP, 0.2])
LEVELS = [0, 0, 70, 70, 0, 0, -70, -70, 0, 0]


def w_ref(t: np.ndarray) -> np.ndarray:
    """Trapezoidal speed reference [rad/s] at times t [s]."""
    return np.interp(t, CORNERS, LEVELS)


@lru_cache(maxsize=4)
def closed_loop(h: float = H, substeps: int = 10, params: tuple = ()) -> dict[str, np.ndarray]:
    """Simulate the closed-loop model over the round trip (RK4, reference interpolated in each step).

    Returns
    -------
    dict
        ``t, w_ref, u, i, w, theta`` arrays, shape (n,), sampled every h.
    """
    t = np.arange(int(round(CORNERS[-1] / h)) + 1) * h
    out = simulate_closed_loop(w_ref(t), h, dict(params), substeps)
    return {"t": t, "w_ref": w_ref(t), **{k: out[k][:-1] for k in ("u", "i", "w", "theta")}}


def add_noise(data: dict, snr_db: float, seed: int, names=("u", "i", "w")) -> dict:
    """White Gaussian noise on each signal at ``snr_db`` (signal RMS over noise RMS)."""
    rng = np.random.default_rng(seed)
    noisy = dict(data)
    for name in names:
        x = data[name]
        noisy[name] = x + rng.standard_normal(x.size) * np.sqrt(np.mean(x ** 2)) / 10 ** (snr_db / 20)
    return noisy


def fmu_closed_loop(fmu: str, h: float = H) -> dict[str, np.ndarray]:
    """Run the plant FMU (Co-Simulation, fmpy's ``simulate_fmu``) over the round trip, output every h.

    fmpy holds the reference over each communication step (zero-order hold; its set_input_derivatives
    option fails on this FMU's table in fmpy 0.3.32), which leaves R and L ~0.2 % low (see
    tests/cosim/test_input_hold.py; the co-simulation master's default first-order hold has no such bias).
    """
    from fmpy import simulate_fmu

    t = np.arange(int(round(CORNERS[-1] / h)) + 1) * h
    table = np.array(list(zip(t, w_ref(t))), dtype=[("time", float), ("w_ref", float)])
    r = simulate_fmu(str(fmu), stop_time=t[-1], output_interval=h, input=table,
                     output=["u", "i", "w", "theta"])
    return {"t": r["time"], "w_ref": w_ref(r["time"]), **{k: r[k] for k in ("u", "i", "w", "theta")}}
