"""Test data: a DC-motor-like motion recorded in SI (4 s at 1 kHz by default), from the exact inverse dynamics.

The speed is two sines (reversals separate Cd from ft); the torque what the rotor needs to follow it,
``T = Jt dw/dt + ft w + Cd sign(w)``, plus noise; the position the exact integral of the speed quantised by a
2^16-count encoder; the speed carries noise of its own.
"""
from __future__ import annotations

import math

import numpy as np

TRUTH = {"Jt": 2e-3, "ft": 1e-3, "Cd": 0.05}
H = 1e-3
_A = ((30.0, 0.5), (12.0, 1.3))  # (amplitude rad/s, frequency Hz)


def motor(n: int = 4000, seed: int = 0) -> dict[str, np.ndarray]:
    """``{"t" [s], "w" [rad/s], "x" [rad], "T" [N.m]}`` of the motion (module docstring)."""
    t = np.arange(n) * H
    w = sum(a * np.sin(2 * math.pi * f * t) for a, f in _A)
    dw = sum(a * 2 * math.pi * f * np.cos(2 * math.pi * f * t) for a, f in _A)
    x = sum(a / (2 * math.pi * f) * (1 - np.cos(2 * math.pi * f * t)) for a, f in _A)
    rng = np.random.default_rng(seed)
    torque = TRUTH["Jt"] * dw + TRUTH["ft"] * w + TRUTH["Cd"] * np.sign(w) + 2e-3 * rng.normal(size=n)
    count = 2 * math.pi / 2**16
    return {"t": t, "w": w + 0.05 * rng.normal(size=n), "x": np.round(x / count) * count, "T": torque}
