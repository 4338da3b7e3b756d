"""Closed-loop plant data for the estimator tests, simulated from the model with CasADi.

RK4 at 1e-5 s substeps of the full model (speed and current loops, converter, smoothed dry friction),
trapezoidal round trip of the speed reference, output every ``h``. Also the FMU run (fmpy) when the
plant FMU is available, and the noise used by the statistical tests.
"""
from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from models import feed_drive

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
def closed_loop(h: float = H, substep: float = 1e-5, params: tuple = ()) -> dict[str, np.ndarray]:
    """Simulate the closed-loop plant over the round trip.

    Returns
    -------
    dict
        ``t, w_ref, u, i, w, theta`` arrays, shape (n,), sampled every h.
    """
    m = feed_drive()
    f = m.rhs_function()
    g = m.output_function()
    x, u, p = (ca.SX.sym(n, v.numel()) for n, v in zip("xup", m.vectors()))
    u1 = ca.SX.sym("u1", u.numel())
    k = int(round(h / substep))
    xk = x
    # The reference is interpolated linearly inside the output step. Held constant (zero-order hold),
    # each 0.018 rad/s step of the ramp would make the PI gains jump u by 2.8 V at every sample, and
    # the sampled u would sit at one phase of that sawtooth (1.4 V off its mean during the ramps).
    for j in range(k):
        a, b = u + (u1 - u) * (j / k), u + (u1 - u) * ((j + 1) / k)
        k1 = f(xk, a, p)
        k2 = f(xk + substep / 2 * k1, (a + b) / 2, p)
        k3 = f(xk + substep / 2 * k2, (a + b) / 2, p)
        k4 = f(xk + substep * k3, b, p)
        xk = xk + substep / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    n = int(round(CORNERS[-1] / h)) + 1
    t = np.arange(n) * h
    values = {**m.nominal(), **dict(params)}
    pv = [values[v.name] for v in m.parameters]
    step = ca.Function("step", [x, ca.vertcat(u, u1), p], [xk]).mapaccum(n - 1)
    U = np.zeros((len(m.inputs), n))
    U[0] = w_ref(t)
    X = np.hstack([np.zeros((len(m.states), 1)),
                   np.asarray(step(np.zeros(len(m.states)), np.vstack([U[:, :-1], U[:, 1:]]), pv))])
    Y = np.asarray(g.map(n)(X, U, pv))
    out = {v.name: Y[j] for j, v in enumerate(m.outputs)}
    return {"t": t, "w_ref": w_ref(t), "u": out["u"], "i": out["i"], "w": out["w"], "theta": out["theta"]}


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

    The reference is held over each communication step, as the co-simulation master does; the drive's
    reference input filter (``tau_ref``) keeps the sampled voltage free of the held steps.
    """
    from fmpy import simulate_fmu

    t = np.arange(int(round(CORNERS[-1] / h)) + 1) * h
    table = np.array(list(zip(t, w_ref(t))), dtype=[("time", float), ("w_ref", float)])
    r = simulate_fmu(str(fmu), stop_time=t[-1], output_interval=h, input=table,
                     output=["u", "i", "w", "theta"])
    return {"t": r["time"], "w_ref": w_ref(r["time"]), **{k: r[k] for k in ("u", "i", "w", "theta")}}
