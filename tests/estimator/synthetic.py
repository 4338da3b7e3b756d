"""Records built from the model's equations with known parameters, for any speed profile and rate.

The speed profile ``w(t)`` is given (piecewise-linear corners, smoothed); the current follows from the
mechanical equation ``K i = Jt dw/dt + ft w + Cd sgn(w) + T0`` and the voltage from the electrical one
``u = R i + L di/dt + K w``, both evaluated on a grid 20 times finer than the record (derivatives by
``np.gradient``, sgn smoothed as the model's over 0.1 rad/s), then sampled every ``h``. Exact to the
model, cheap (no ODE), so a test can choose L/R against h, one direction, a narrow speed range, ...

The smoothing is ``scipy.ndimage.gaussian_filter1d``'s (its kernel, truncated at 4 sigma, ``mode="nearest"``)
formed by FFT: at h = 1e-4 s the kernel has 32 001 taps over 840 000 fine samples, and the direct sum took
~6 s of CPU per record (the fuzz and the partial-estimate tests build ~40); the FFT's sums differ from the
direct ones by rounding only (5e-13 rad/s on 70 rad/s).
"""
from __future__ import annotations

import numpy as np
from scipy.signal import oaconvolve

from feeddrive.models import feed_drive

TRUTH = feed_drive().nominal(("physical",))
FINE = 20


def gaussian_smoothed(x: np.ndarray, sigma: float) -> np.ndarray:
    """``gaussian_filter1d(x, sigma, mode="nearest")`` by overlap-add FFT: the same normalised kernel of
    ``2 int(4 sigma + 0.5) + 1`` taps over ``x`` extended by its end values; shape of ``x``."""
    radius = int(4.0 * sigma + 0.5)
    k = np.arange(-radius, radius + 1)
    kernel = np.exp(-0.5 / sigma**2 * k**2)
    return oaconvolve(np.pad(x, radius, mode="edge"), kernel / kernel.sum(), mode="valid")


def record(corners: list[tuple[float, float]], h: float, params: dict | None = None, snr_db: float | None = None,
           seed: int = 0, smooth: float = 0.02) -> dict[str, np.ndarray]:
    """``t, u, i, w`` sampled every ``h`` along the speed corners ``[(t, w), ...]`` [s, rad/s].

    ``smooth``: the corners are rounded by a Gaussian of this many seconds; ``snr_db``: white noise
    on u, i, w at this signal-to-noise ratio (RMS), None for none.
    """
    par = {**TRUTH, **(params or {})}
    tc, wc = np.array(corners, dtype=float).T
    hf = h / FINE
    tf = np.arange(0.0, tc[-1] + hf / 2, hf)
    wf = gaussian_smoothed(np.interp(tf, tc, wc), smooth / hf)
    dw = np.gradient(wf, hf)
    i = (par["Jt"] * dw + par["ft"] * wf + par["Cd"] * np.tanh(wf / 0.1) + par.get("T0", 0.0)) / par["K"]
    u = par["R"] * i + par["L"] * np.gradient(i, hf) + par["K"] * wf
    out = {"t": tf[::FINE], "u": u[::FINE], "i": i[::FINE], "w": wf[::FINE]}
    if snr_db is not None:
        rng = np.random.default_rng(seed)
        for k in ("u", "i", "w"):
            x = out[k]
            out[k] = x + rng.standard_normal(x.size) * np.sqrt(np.mean(x ** 2)) / 10 ** (snr_db / 20)
    return out


#: a round trip with several speed levels (ft and Cd separable, both directions)
ROUND_TRIP = [(0, 0), (0.2, 0), (0.6, 70), (1.2, 70), (1.4, 30), (1.9, 30), (2.3, -60), (2.9, -60), (3.1, -20),
              (3.6, -20), (3.9, 0), (4.2, 0)]
#: one direction only, several levels
FORWARD = [(0, 0), (0.2, 0), (0.6, 70), (1.2, 70), (1.4, 30), (1.9, 30), (2.2, 60), (2.8, 60), (3.2, 0), (3.5, 0)]


def narrow(h: float) -> list[tuple[float, float]]:
    """+68 +- 2 rad/s for 2 s, a fast reversal, -68 +- 2 rad/s for 2 s: ft cannot be told from Cd."""
    t = np.arange(0.0, 2.0, 0.0625)
    up = [(0.1 + tk, 68 + 2 * np.sin(2 * np.pi * 1.5 * tk)) for tk in t]
    down = [(2.2 + tk, -68 - 2 * np.sin(2 * np.pi * 1.5 * tk)) for tk in t]
    return up + down
