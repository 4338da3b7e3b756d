"""Isolation by analytical redundancy (paper Fig. 6, eq. 13, 14): which sensor of a disagreeing pair is faulty.

A model-based value of the quantity is computed from the other two and the electrical equation (eq. 1) with
the last validated (or the axis's stated) ``R, L, K`` (``model_reference``); each filtered sensor is fitted
on it, ``xkf = ak x_hat + bk``, by OLS with Newey-West errors (``isolate``). See ``validation``'s docstring
for the whole measurement validation this is part of.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from feeddrive.estimator import lti
from feeddrive.estimator.errors import EstimatorInputError
from feeddrive.estimator.hac import ols_hac
from feeddrive.estimator.kernels import bilinear_first_order

#: a sensor fault's kind: index offset + 2 gain
KINDS = ("none", "offset", "gain", "gain+offset")
QUANTITIES = ("current", "voltage", "speed")


@dataclass(frozen=True)
class SensorFit:
    """Isolation fit of one sensor against the model-based value (eq. 13, 14)."""

    sensor: str
    gain: float
    gain_ci95: tuple[float, float]
    offset: float
    offset_ci95: tuple[float, float]
    faulty: bool
    kind: str
    error_rms: float

    def to_dict(self) -> dict:
        return {"sensor": self.sensor, "kind": self.kind, "gain": self.gain, "gain_ci95": list(self.gain_ci95),
                "offset": self.offset, "offset_ci95": list(self.offset_ci95)}



def model_reference(quantity: str, filtered: Mapping[str, np.ndarray], h: float,
                    electrical: Mapping[str, float]) -> np.ndarray:
    """Model-based value of one quantity from the two others and eq. 1 (analytical redundancy).

    Parameters
    ----------
    quantity : {"current", "voltage", "speed"}
    filtered : mapping with filtered ``u`` [V], ``i`` [A], ``w`` [rad/s], arrays of shape (n,)
        (only the two quantities other than ``quantity`` are read).
    h : float
        Sample time [s].
    electrical : mapping with ``R`` [Ohm], ``L`` [H], ``K`` [V s/rad]

    Returns
    -------
    ndarray, shape (n,)
        ``Ir_hat`` [A], ``u_hat`` [V] or ``w_hat`` [rad/s].
    """
    R, L, K = (float(electrical[k]) for k in ("R", "L", "K"))
    if quantity == "current":
        v = filtered["u"] - K * filtered["w"]
        b, a = bilinear_first_order(L, R, h)
        zi = lti.lfilter_zi(b, a) * v[0]  # start in steady state: i = v / R
        return lti.lfilter(b, a, v, zi=zi)[0]
    di = np.gradient(filtered["i"], h)
    if quantity == "voltage":
        return R * filtered["i"] + L * di + K * filtered["w"]
    if quantity == "speed":
        return (filtered["u"] - R * filtered["i"] - L * di) / K
    raise EstimatorInputError(f"model_reference: quantity must be one of {QUANTITIES}, got {quantity!r}")


def isolate(x1f: np.ndarray, x2f: np.ndarray, reference: np.ndarray, names: tuple[str, str], h: float,
            cutoff_hz: float, options: Any) -> tuple[SensorFit, SensorFit]:  # validation.ValidationOptions (its importer)
    """Fit each filtered sensor on the model-based value, ``xkf = ak x_hat + bk`` (eq. 13, 14).

    Parameters
    ----------
    x1f, x2f, reference : ndarray, shape (n,)
        Filtered sensors and the model-based value (``model_reference``).
    names : (str, str)
        Sensor names.
    h : float
        Sample time [s].
    cutoff_hz : float
        Cut-off of the filter applied to the signals [Hz]: the fit uses about 4 samples per
        cut-off period and Newey-West errors over 4 cut-off periods, since the residuals are coloured.
    options : validation.ValidationOptions
        Its ``edge_s``, ``alpha``, ``gain_tol`` and ``offset_tol`` (not imported here: validation imports this).

    Returns
    -------
    (SensorFit, SensorFit)
    """
    edge = int(round(options.edge_s / h))
    step = max(1, int(1.0 / (4.0 * cutoff_hz * h)))
    sl = slice(edge, x1f.size - edge, step)
    ref = reference[sl]
    if ref.size < 20:
        raise EstimatorInputError(f"isolate: {ref.size} samples left after trimming {options.edge_s} s edges")
    X = np.column_stack([ref, np.ones(ref.size)])
    span = float(np.max(np.abs(ref)))
    fits = []
    for name, x in zip(names, (x1f, x2f)):
        res = ols_hac(x[sl], X, maxlags=16)  # statsmodels' OLS with HAC errors, without its 2 s of imports
        (a, b), ((alo, ahi), (blo, bhi)) = res.params, res.conf_int(0.05)  # reported: 95 % intervals
        # decided at the level of every other test (alpha), not at the reported intervals' 5 %
        (tlo_a, thi_a), (tlo_b, thi_b) = res.conf_int(options.alpha)
        gain = not tlo_a <= 1.0 <= thi_a and abs(a - 1.0) > options.gain_tol
        offset = not tlo_b <= 0.0 <= thi_b and abs(b) > options.offset_tol * span
        err = float(np.sqrt(np.mean(((a - 1.0) * ref + b) ** 2)))
        fits.append(SensorFit(name, float(a), (float(alo), float(ahi)), float(b), (float(blo), float(bhi)),
                              bool(gain or offset), KINDS[int(offset) + 2 * int(gain)], err))
    return fits[0], fits[1]
