"""Realistic damaged records through the per-parameter estimator: a refusal or finite estimates, never an
exception, a warning or a nan (issue 22). Rates 10 Hz to 10 kHz, records of 0.3 s to 4 s, one direction
or both, rounding to 3 significant figures, quantisation, saturation, constant stretches, spikes, a
commanded voltage through a nonlinear amplifier, L/R from far below to far above the sample period.
``FUZZ_EXAMPLES`` sets the count (default 8; a fuzz profile runs thousands)."""
from __future__ import annotations

import json
import os
import warnings

import numpy as np
import pytest
from synthetic import FORWARD, ROUND_TRIP, TRUTH, record

from feeddrive.estimator import EstimationOptions, EstimatorInputError, FilterSpec, MotionData, NotEnoughExcitation
from feeddrive.estimator.partial import estimate_parameters

EXAMPLES = int(os.environ.get("FUZZ_EXAMPLES", "8"))


def damaged(seed: int) -> MotionData:
    rng = np.random.default_rng(seed)
    h = 1 / 10 ** rng.uniform(1, 4)
    par = {"L": TRUTH["R"] * 10 ** rng.uniform(-5, -2), "Cd": -0.5 if rng.random() < 0.2 else TRUTH["Cd"]}
    d = record(ROUND_TRIP if rng.random() < 0.5 else FORWARD, h, par, snr_db=rng.choice([None, 20, 40, 60]),
               seed=seed)
    n = max(2, int(rng.choice([0.3, 1.0, 4.0]) / h))
    start = int(rng.integers(0, max(1, len(d["w"]) - n)))
    d = {k: v[start:start + n].copy() for k, v in d.items()}
    for k in ("u", "i", "w"):
        x, r = d[k], rng.random()
        if r < 0.15:
            x[:] = [float(f"{v:.3g}") for v in x]
        elif r < 0.3:
            x[:] = np.round(x / 0.1) * 0.1
        elif r < 0.4:
            x[:] = np.clip(x, -0.5 * np.abs(x).max(), 0.5 * np.abs(x).max())
        elif r < 0.5 and x.size > 10:
            a = int(rng.integers(0, x.size - 5))
            x[a:a + x.size // 5] = x[a]
        elif r < 0.6:
            x[rng.integers(0, x.size, size=max(1, x.size // 100))] *= 10
    if rng.random() < 0.2:
        d["u"] = 27 * np.tanh(d["u"] / 30) + 0.5
    return MotionData(h, u=d["u"], i=d["i"], w=d["w"])


@pytest.mark.parametrize("seed", range(EXAMPLES))
def test_damaged_records_give_a_refusal_or_finite_estimates(seed):
    data = damaged(seed)
    for method in ("ls", "iv", "oe"):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            try:
                est = estimate_parameters(data, EstimationOptions(method=method, filter=FilterSpec(min(50, 0.1 / data.h))),
                                          {"Jt": (1e-3, None)})
            except (NotEnoughExcitation, EstimatorInputError) as exc:
                assert exc.args and "nan" not in str(exc) and "\n" not in str(exc)
                continue
        text = json.dumps(est.to_dict())
        assert "NaN" not in text and "Infinity" not in text
        for p in est.parameters.values():
            assert np.isfinite([p.value, p.std, *p.ci95]).all()
