"""The excitation design on the PMSM (issue 25): the same prediction, the model as data (its signals, the d axis
fitted with the q axis, the current and voltage vectors' limits)."""
from __future__ import annotations

import numpy as np
import pytest
from pmsm_data import FILTER, H

from feeddrive.estimator.design import design_acceleration, motion_data, predicted_std, simulate_closed_loop
from feeddrive.estimator.estimate import EstimationOptions, least_squares, prepare
from feeddrive.models.drives import drive_model

MODEL = drive_model("pmsm")
TRUTH = MODEL.nominal(("physical",))
OPTIONS = EstimationOptions(model="pmsm", filter=FILTER)
NOISE = {"u_q": 1.0, "u_d": 1.0, "i_q": 0.05, "i_d": 0.05, "w": 0.05}


def reference(accel: float, top: float = 188.5, hold: float = 0.2) -> np.ndarray:
    """Speed reference [rad/s]: from rest to ``top`` at ``accel`` [rad/s^2], held, back to rest."""
    r = top / accel
    tc = [0, 0.02, 0.02 + r, 0.02 + r + hold, 0.02 + 2 * r + hold, 0.02 + 2 * r + hold + 0.05]
    return np.interp(np.arange(int(tc[-1] / H)) * H, tc, [0, 0, top, top, 0, 0])


def test_predicted_std_matches_monte_carlo_on_the_pmsm():
    """120 least-squares fits with white noise on u_q, u_d, i_q, i_d and w against the prediction. Without the d
    axis's samples (p w L_q i_q carries most of L_q) the prediction of L_q was 12 times the spread."""
    sig = {k: v[1:] for k, v in simulate_closed_loop(reference(1885.0), H, {}, substeps=4, model=MODEL).items()}
    predicted = predicted_std(sig, H, NOISE, OPTIONS)
    assert tuple(predicted) == ("R", "L_d", "L_q", "psi_f", "Jt", "ft", "Cd")
    rng = np.random.default_rng(3)
    fits = []
    for _ in range(120):
        noisy = {k: sig[k] + NOISE[k] * rng.standard_normal(len(sig[k])) for k in NOISE}
        fits.append(least_squares(prepare(motion_data(noisy, H, MODEL), OPTIONS), OPTIONS).as_dict())
    for name, p in predicted.items():
        empirical = np.std([f[name] / TRUTH[name] - 1 for f in fits], ddof=1)
        assert empirical == pytest.approx(p, rel=0.25), name  # 120 draws: std of the std ~7 %


def test_design_scores_the_slopes_and_refuses_one_beyond_the_current_vectors_limit():
    """i_q ~ Jt a / K_t: 60000 rad/s^2 would need ~130 A: the current vector stays at its 25 A limit (peak
    24.8 A, above 99 % of it: infeasible); 4000 rad/s^2 (10 A) excites Jt and L_q best."""
    best, cands = design_acceleration(reference, [1000.0, 4000.0, 60000.0], H, NOISE, OPTIONS)
    assert [c.feasible for c in cands] == [True, True, False]
    assert cands[2].peak_current >= 0.99 * 25.0
    assert best.accel == 4000.0
    assert best.criterion < cands[0].criterion
