"""The PMSM at a drive's trace rate (125 us) and at an NC's (1, 2, 4 ms), issue 25: every parameter is either
within its stated tolerance with its 95 % interval covering the truth, or refused with its reason."""
from __future__ import annotations

import math
import re
from functools import lru_cache

import numpy as np
import pytest
from pmsm_data import H, add_noise

from feeddrive.estimator import EstimationOptions, FilterSpec, MotionData
from feeddrive.estimator.design import simulate_closed_loop
from feeddrive.estimator.estimate import fell_back
from feeddrive.estimator.identifiability import time_constants
from feeddrive.estimator.lagged_iv import LABEL, LAGGED
from feeddrive.estimator.nc_rate import systematic
from feeddrive.estimator.partial import _fit_ls, estimate_parameters
from feeddrive.models.drives import drive_model

TRUTH = drive_model("pmsm").nominal(("physical",))
#: stated tolerance per parameter (noise-free); L_d is excited only through p w L_d i_d (i_d ~ 0 below base speed)
TOL = {"R": 0.02, "L_d": 0.10, "L_q": 0.01, "psi_f": 0.005, "Jt": 0.02, "ft": 0.05, "Cd": 0.05}
#: a numerical floor on the noise-free intervals (the 125 us interval of L_q is +-0.003 %)
FLOOR = 2e-4
RATES = (1, 8, 16, 32)  # x 125 us: 125 us, 1 ms, 2 ms, 4 ms


def tool_change(t: np.ndarray) -> np.ndarray:
    """Speed reference [rad/s]: a tool change's rapid out and back, 1885 rad/s^2 to 188.5 rad/s (0.3 m/s at a
    10 mm pitch), held 0.57 s."""
    a, v, hold = 1885.0, 188.5, 0.57
    corners = [(0.0, 0.0), (0.02, 0.0)]
    for sign in (1, -1):
        t0 = corners[-1][0]
        corners += [(t0 + v / a, sign * v), (t0 + v / a + hold, sign * v), (t0 + 2 * v / a + hold, 0.0),
                    (t0 + 2 * v / a + hold + 0.05, 0.0)]
    tc, wc = np.array(corners).T
    return np.interp(t, tc, wc)


@lru_cache(maxsize=2)
def simulated(params: tuple = ()) -> dict[str, np.ndarray]:
    t = np.arange(int(1.7 / H)) * H
    out = simulate_closed_loop(tool_change(t), H, dict(params), substeps=4, model=drive_model("pmsm"))
    return {k: out[k][1:] for k in ("u_d", "u_q", "i_d", "i_q", "w")}


def estimate(d: dict, k: int):
    h = H * k
    s = {n: v[::k] for n, v in d.items()}  # an NC's trace: instantaneous samples every h
    m = MotionData(h, w=s["w"], signals={n: s[n] for n in ("u_d", "u_q", "i_d", "i_q")})
    return estimate_parameters(m, EstimationOptions(model="pmsm", filter=FilterSpec(min(100.0, 0.1 / h))))


def check(est, truth: dict, rate: str, tolerance: bool = True) -> None:
    """Every parameter given is covered by its interval (and within ``TOL`` if ``tolerance``: noise-free), every
    refusal gives its reason with numbers."""
    for n, why in est.refused.items():
        assert re.search(r"\d", why), (rate, n, why)  # a reason with its numbers
    for n, p in est.parameters.items():
        err = p.value / truth[n] - 1
        assert not tolerance or abs(err) < TOL[n], (rate, n, err)
        lo, hi = p.ci95
        assert lo - FLOOR * abs(p.value) <= truth[n] <= hi + FLOOR * abs(p.value), (rate, n, err, p.ci95)


@pytest.mark.parametrize("k", RATES)
def test_every_parameter_is_within_tolerance_and_covered_or_refused(k):
    est = estimate(simulated(), k)
    check(est, TRUTH, f"{k * H * 1e3:g} ms")
    assert {"R", "L_q", "psi_f", "Jt"} <= set(est.parameters)  # the motion gives the electrical ones at every rate


def test_the_time_constant_rule_reads_each_equations_slope_and_resistance_from_the_model():
    assert time_constants(drive_model("dc")) == [("electrical", "i", "L", "R"), ("mechanical", "w", "Jt", "ft")]
    assert time_constants(drive_model("pmsm"))[:2] == [("electrical_q", "i_q", "L_q", "R"),
                                                      ("electrical_d", "i_d", "L_d", "R")]


def test_an_inductance_below_the_sample_period_is_refused_and_the_others_come_from_the_quasi_static_equation():
    """L = 0.4 mH, L/R = 0.57 ms, sampled every 1 ms: L_q (and L_d) refused with the time constant, fixed at 0;
    R, psi_f and Jt from the q axis without its L di/dt term. (The current loop tuned for that L.)"""
    small = {"L_d": 4e-4, "L_q": 4e-4, "Kp_i": 4e-4 * 2 * math.pi * 1000, "fw": 0.0}
    est = estimate(simulated(tuple(small.items())), 8)
    assert est.refused["L_q"].startswith("sample period 0.001 s too long for the electrical_q time constant L_q/R")
    assert est.fixed["L_q"] == 0.0
    truth = TRUTH | small
    for n in ("R", "psi_f", "Jt"):
        assert est.parameters[n].value == pytest.approx(truth[n], rel=TOL[n]), n


@pytest.mark.parametrize("k", (16, 32))
@pytest.mark.parametrize("snr", (40.0, 30.0))
def test_at_an_nc_rate_with_noise_every_interval_given_covers_the_truth(k, snr):
    """2 and 4 ms, 40 and 30 dB, two noise draws: every parameter given is covered, the others refused with
    their numbers. (Over 10 draws each, benchmarks/bench_pmsm_rates.py: 5 of 224 intervals given missed, 2 %.)"""
    for seed in (0, 1):
        est = estimate(add_noise(simulated(), snr, seed), k)
        check(est, TRUTH, f"{k * H * 1e3:g} ms, {snr:g} dB, seed {seed}", tolerance=False)
        assert {"psi_f", "L_q"} & set(est.parameters)  # the back-EMF and q inductance are given at every rate


def test_dry_friction_tied_to_a_refused_viscous_friction_is_refused_not_given_on_its_estimate():
    """2 ms, 40 dB: ft refused (+-132 %); Cd used to be given +26 % with an interval of +-12 % that held only
    if ft's estimate were the truth (ft and Cd -0.98 correlated): refused with the correlation."""
    est = estimate(add_noise(simulated(), 40.0, 0), 16)
    assert est.refused["ft"].startswith("95 % interval")
    why = est.refused["Cd"]
    assert why.startswith("determined only together with ft (refused; correlation -0.9"), why
    assert float(why.split("variance is ")[1].split(" times")[0]) > 10


def test_lagged_iv_standing_in_for_iv_at_an_nc_rate_is_not_biased_by_the_noise_of_its_regressors():
    """2 ms, 30 dB: the split-sample IV cannot run (its simulation of the q axis is unstable at its halves' 4 ms),
    the lagged IV stands in (estimator/lagged_iv.py): Jt +16 % +-39 % (over 40 noise draws +0.7 % +- 9.4 %, given
    in 39, 97 % of them covering the truth); LS's Jt is -16 % (the noise of the speed's derivative; over the 40
    draws -17 % +- 6 %). (LS stood in here before, its interval widened by its noise bias: the next test.)"""
    est = estimate(add_noise(simulated(), 30.0, 0), 16)
    assert est.iv.ran == LAGGED and est.iv.message.startswith(LABEL + ": the split-sample IV failed (the simulation")
    assert {"L_q", "psi_f", "Jt"} <= set(est.parameters)
    assert est.ls.values[est.ls.names.index("Jt")] / TRUTH["Jt"] - 1 < -0.1
    check(est, TRUTH, "2 ms, 30 dB", tolerance=False)


def test_ls_standing_in_for_iv_at_an_nc_rate_holds_its_noise_bias_in_its_interval():
    """2 ms, 30 dB, where the lagged IV failed too and LS stood in: the noise of the speed's derivative biases LS's
    Jt by -16 % (the halves' LS, twice the filtered noise: -35 %), the interval used to miss the truth."""
    s = {n: v[::16] for n, v in add_noise(simulated(), 30.0, 0).items()}
    m = MotionData(16 * H, w=s["w"], signals={n: s[n] for n in ("u_d", "u_q", "i_d", "i_q")})
    options = EstimationOptions(method="iv", model="pmsm", filter=FilterSpec(min(100.0, 0.1 / m.h)))
    _, ls, fixed, _, _ = _fit_ls(m, options)
    res = systematic(m, ls, fell_back(ls, "iv", "IV fell back to LS"), options, fixed, _fit_ls)
    assert res.ran == "ls" and "the halves' LS - LS (LS's noise bias" in res.message
    jt = res.parameters["Jt"]
    assert jt.value / TRUTH["Jt"] - 1 < -0.1 and jt.ci95[0] <= TRUTH["Jt"] <= jt.ci95[1]
    assert jt.std > 1.5 * ls.parameters["Jt"].std  # LS's own interval just reached the truth (+0.4 %)
