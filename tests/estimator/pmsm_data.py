"""Closed-loop PMSM data for the estimator tests, from the model's own CasADi rollout.

``estimator.design.simulate_closed_loop(model=pmsm)``: the full PMSM drive (speed PI, d and q current PIs,
voltage-vector limit, smoothed dry friction), RK4 with 4 substeps of the servo's 125 us cycle. The speed
reference steps through nine levels of both signs (ramps of 0.05 s, up to 6000 rad/s^2: the q current
reaches the 25 A limit) and the base speed is lowered to 150 rad/s, so the field weakening drives the d
current to about -17 A above it: every parameter of the q-axis voltage equation is excited, L_d through
``p w L_d i_d``.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import plant_data

from feeddrive.estimator import FilterSpec
from feeddrive.estimator.design import simulate_closed_loop
from feeddrive.models.drives import drive_model

H = 1.25e-4  # a servo drive's 125 us trace rate (8 kHz)
LEVELS = (300, 120, 260, -300, -120, -260, 200, -200, 0)  # rad/s
#: cut-off of the estimator's filter [Hz]: the current loop's 1 kHz transients carry L_q (below 0.1125 / H)
FILTER = FilterSpec(100.0)
MEASURED = ("u_d", "u_q", "i_d", "i_q", "w")


def w_ref(t: np.ndarray) -> np.ndarray:
    """Speed reference [rad/s]: from rest, 0.05 s ramps to each of ``LEVELS``, each held 0.2 s."""
    corners = [(0.0, 0.0), (0.05, 0.0)]
    for level in LEVELS:
        t0 = corners[-1][0]
        corners += [(t0 + 0.05, level), (t0 + 0.25, level)]
    tc, wc = np.array(corners).T
    return np.interp(t, tc, wc)


@lru_cache(maxsize=4)
def closed_loop(kind: str = "pmsm", params: tuple = ()) -> dict[str, np.ndarray]:
    """``t`` and the measured signals (``MEASURED``, plus ``theta``), sampled every ``H`` over 2.55 s."""
    t = np.arange(int(round(2.55 / H))) * H
    out = simulate_closed_loop(w_ref(t), H, {"w_base": 150.0, **dict(params)}, substeps=4, model=drive_model(kind))
    return {"t": t, **{k: out[k][1:] for k in (*MEASURED, "theta")}}


def add_noise(data: dict, snr_db: float, seed: int) -> dict:
    """White Gaussian noise on every measured signal at ``snr_db`` (signal RMS over noise RMS)."""
    return plant_data.add_noise(data, snr_db, seed, MEASURED)
