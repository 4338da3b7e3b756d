"""Excitation design: closed-loop simulation physics, the predicted covariance against Monte Carlo, the choice."""
from __future__ import annotations

import math

import numpy as np
import pytest

from feeddrive.estimator.design import MODEL, PHYSICAL, design_acceleration, predicted_std, simulate_closed_loop
from feeddrive.estimator.errors import EstimatorInputError
from feeddrive.estimator.estimate import EstimationOptions, MotionData, least_squares, prepare

H = 1e-4
NOISE = {"u": 0.2, "i": 0.05, "w": 0.05}
P = MODEL.nominal()


def tool_change(accel, distance=0.25, v_max=0.22, dwell=0.2):
    """Motor speed reference [rad/s] of an out-and-back trapezoid move, then 0.1 s at rest."""
    v = min(v_max, math.sqrt(accel * distance))
    t_move = distance / v + v / accel
    t = np.arange(int(round((2 * t_move + dwell + 0.1) / H))) * H

    def one(tt):
        return np.clip(np.minimum(accel * tt, accel * (t_move - tt)), 0, v) * (tt >= 0)

    return (one(t) - one(t - t_move - dwell)) * 2 * math.pi * P["belt_ratio"] / P["pitch"]


@pytest.fixture(scope="module")
def motion():
    return simulate_closed_loop(tool_change(0.6), H)


def test_closed_loop_steady_state_satisfies_both_equations():
    sig = simulate_closed_loop(np.full(8000, 50.0), H)  # 0.8 s at 50 rad/s: the 4 Hz integral corner has settled
    i, w, u = sig["i"][-1], sig["w"][-1], sig["u"][-1]
    assert w == pytest.approx(50.0, rel=1e-6)
    assert i == pytest.approx((P["ft"] * w + P["Cd"]) / P["K"], rel=1e-6)
    assert u == pytest.approx(P["R"] * i + P["K"] * w, rel=1e-6)


def test_noise_free_regressions_recover_the_plant(motion):
    fit = least_squares(prepare(MotionData(h=H, u=motion["u"], i=motion["i"], w=motion["w"]), EstimationOptions()),
                        EstimationOptions()).as_dict()
    for name in PHYSICAL:  # only the zero-forcing derivative's and the filter's errors remain
        assert fit[name] == pytest.approx(P[name], rel=0.02), name


def test_predicted_std_matches_monte_carlo_through_the_estimator():
    """The predicted spread against 120 least-squares fits of the estimator (filter, derivative,
    regressions) on the same motion with white noise on u, i and w."""
    short = simulate_closed_loop(tool_change(0.6, distance=0.12, dwell=0.05), H)
    predicted = predicted_std(short, H, NOISE)
    white = predicted_std(short, H, {"u": NOISE["u"], "i": NOISE["i"]})
    rng = np.random.default_rng(3)
    fits = []
    for _ in range(120):
        noisy = {s: short[s] + NOISE[s] * rng.standard_normal(len(short[s])) for s in ("u", "i", "w")}
        fits.append(least_squares(prepare(MotionData(h=H, **noisy), EstimationOptions()), EstimationOptions()).as_dict())
    for name in PHYSICAL:
        empirical = np.std([f[name] / P[name] - 1 for f in fits], ddof=1)
        assert empirical == pytest.approx(predicted[name], rel=0.2), name  # 120 draws: std of the std ~7 %
    # the tachometer noise, differentiated, dominates the friction's spread: output noise alone misses it
    assert predicted["Cd"] > 2 * white["Cd"] and predicted["ft"] > 2 * white["ft"]


@pytest.mark.slow
def test_design_trades_inductance_against_friction():
    best, cands = design_acceleration(tool_change, [0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.2], H, NOISE)
    by = {c.accel: c for c in cands}
    # L is identified from the current transients, whose size grows with the slope: std(L) ~ 1 / accel
    assert by[0.4].rel_std["L"] / by[0.8].rel_std["L"] == pytest.approx(2.0, rel=0.1)
    # steeper ramps leave less of the move to separate viscous and dry friction from the inertia term
    assert by[0.2].rel_std["Cd"] < by[0.4].rel_std["Cd"] < by[0.8].rel_std["Cd"]
    # the end of the ramp needs (Jt a 2 pi / pitch + ft w_max + Cd) / K: 20.4 A at 0.6 m/s^2 (paper: about
    # 20 A), plus the speed loop's overshoot
    w_max = 0.22 * 2 * math.pi / P["pitch"]
    need = (P["Jt"] * 0.6 * 2 * math.pi / P["pitch"] + P["ft"] * w_max + P["Cd"]) / P["K"]
    assert need < by[0.6].peak_current < 1.1 * need
    assert not by[1.2].feasible and by[0.8].feasible  # 1.2 m/s^2 needs more than i_max = 30 A
    assert best.accel == 0.4 and by[0.4].criterion < min(by[0.3].criterion, by[0.5].criterion)
    with pytest.raises(EstimatorInputError, match="i_max"):
        design_acceleration(tool_change, [1.2, 2.0], H, NOISE)


@pytest.mark.parametrize(("n", "mid"), [(50, 200), (3000, 300), (300, 3)])
def test_toeplitz_product_is_the_sum_over_lags(n, mid):
    """The FFT form of the equation error's covariance equals the lag-by-lag sum it replaced (kernels longer
    and shorter than the record)."""
    from feeddrive.estimator.design import _toeplitz_times

    rng = np.random.default_rng(n)
    Phi, a = rng.standard_normal((n, 3)), rng.standard_normal(mid)
    acov = np.concatenate([a[::-1], [2.0], a])
    direct = acov[mid] * Phi.T @ Phi
    for k in range(1, min(mid, n - 1) + 1):
        C = Phi[:-k].T @ Phi[k:]
        direct = direct + acov[mid + k] * (C + C.T)
    assert np.allclose(Phi.T @ _toeplitz_times(acov, Phi), direct, rtol=1e-12, atol=1e-12 * np.abs(direct).max())
