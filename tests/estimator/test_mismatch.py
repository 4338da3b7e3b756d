"""Model validation (paper IV.B.3): healthy motions pass, a fault appearing during the motion fails.

Plant data from the closed-loop CasADi model (see test_validation.py), parameters and their covariance
from the estimator on the validated signals, as the monitor does.
"""
import importlib.util
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from feeddrive.estimator.errors import EstimatorInputError
from feeddrive.estimator.estimate import MotionData, estimate_motion
from feeddrive.estimator.mismatch import USES, check_model, residue_check, uncertainty_band, window_rms
from feeddrive.estimator.simulation import simulate_speed
from feeddrive.estimator.validation import model_reference

# the plant data of test_validation.py, loaded by path (test folders are not packages)
_spec = importlib.util.spec_from_file_location("validation_plant", Path(__file__).with_name("test_validation.py"))
_plant = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_plant)
FILTER, H, measure, plant_motion, validate = (_plant.FILTER, _plant.H, _plant.measure, _plant.plant_motion,
                                             _plant.validate)
TRUTH = {k: v for k, v in _plant.NOMINAL.items() if k in ("R", "L", "K", "Jt", "ft", "Cd")}
C_SPEED, C_CURRENT = np.sqrt(stats.chi2.isf(1e-3, 4)), np.sqrt(stats.chi2.isf(1e-3, 3))  # K Jt ft Cd; R L K


def checked(changes=(), seed=1, band=False):
    v = validate(measure(plant_motion(changes), seed))
    est = estimate_motion(MotionData(H, v.u, v.i, v.w))
    uncertainty = {"covariance": est.covariance, "names": est.names} if band else {}
    return est, check_model(v.u, v.i, v.w, H, {k: p.value for k, p in est.parameters.items()}, FILTER,
                            **uncertainty)


def test_healthy_motion_passes():
    """The true model's open-loop speed residue is coloured (Ljung-Box rejects it) but small: the size
    rule accepts the model and the result says so."""
    _, res = checked()
    assert res.passed and res.test == "size" and res.p_value < 1e-3
    assert res.statistic == max(c.peak_rms_relative for c in res.checks.values()) < 0.2 * res.rms_tol
    assert res.checks["speed"].rms_relative < 1e-3 and res.checks["current"].rms_relative < 1e-3
    d = res.to_dict()
    assert set(d) >= {"test", "statistic", "p_value", "passed"} and d["passed"] is True


def test_healthy_motion_passes_within_its_band():
    """With the covariance: the band factors are sqrt(chi2_p^-1(1 - alpha)) for the 4 speed and 3 current
    parameters, and the effect of the actual parameter error (simulation with the plant's values minus
    simulation with the estimate) stays within c times the band's RMS in every 50 ms window (the
    Cauchy-Schwarz bound of the module docstring)."""
    v = validate(measure(plant_motion(), 1))
    est, res = checked(band=True)
    assert res.passed and res.test == "size" and res.p_value < 1e-3
    truth = check_model(v.u, v.i, v.w, H, TRUTH, FILTER)
    for name, c in (("speed", C_SPEED), ("current", C_CURRENT)):
        check = res.checks[name]
        assert check.band_factor == pytest.approx(c, rel=1e-12)
        assert check.excess_relative <= check.peak_rms_relative < 0.1 * res.rms_tol
        assert np.all(check.band[500:] > 0)  # 0 at t0 for the speed: the simulation starts from the measured w
        effect = window_rms((truth.checks[name].simulated - check.simulated)[500:-500], 500)
        assert np.max(effect / window_rms(check.band[500:-500], 500)) < c
    d = res.to_dict()
    assert d["band_factor"] == {"speed": pytest.approx(C_SPEED), "current": pytest.approx(C_CURRENT)}
    assert d["statistic"] == max(d["excess_relative"].values())
    assert set(d["band_relative"]) == {"speed", "current"}


@pytest.mark.parametrize("band", [False, True])
def test_friction_step_during_the_motion_is_a_mismatch(band):
    """Cd doubles at 1.6 s (between the two plateaus): one model cannot explain both halves, with or
    without the uncertainty band (the residue beyond the band is still 5.7 % of the range)."""
    est, res = checked((("Cd", 2.4, 1.6),), band=band)
    assert not res.passed
    speed = res.checks["speed"]
    assert not speed.passed and speed.p_value < 1e-3 and speed.rms_relative > 0.03
    assert speed.excess_relative > 4 * res.rms_tol
    assert res.checks["current"].passed  # the electrical part is unaffected
    assert res.p_value == speed.p_value and res.statistic == speed.statistic
    # the residue grows after the step: far larger in the second half than in the first
    r = speed.residue
    assert np.sqrt(np.mean(r[r.size // 2:] ** 2)) > 2 * np.sqrt(np.mean(r[: r.size // 2] ** 2))
    # parameters are still estimated and reported
    assert set(est.parameters) == {"R", "L", "K", "Jt", "ft", "Cd"}
    assert all(np.isfinite(p.value) for p in est.parameters.values())


def test_whiteness_and_size_rules():
    rng = np.random.default_rng(0)
    w = 70 * np.sin(np.linspace(0, 6, 40000))
    white = residue_check("speed", w + 0.05 * rng.standard_normal(w.size), w, H, 1e-3, 50.0, 10, 0.01)
    assert white.p_value > 1e-3 and white.passed
    slow = 3.0 * np.sin(np.linspace(0, 30, w.size))  # coloured and 1.5 % of the range
    coloured = residue_check("speed", w + slow, w, H, 1e-3, 50.0, 10, 0.01)
    assert coloured.p_value < 1e-6
    assert coloured.rms_relative == pytest.approx(np.sqrt(np.mean(slow**2)) / np.ptp(w + slow), rel=1e-12)
    assert not coloured.passed
    assert residue_check("speed", w + 0.1 * slow, w, H, 1e-3, 50.0, 10, 0.01).passed  # coloured but small


N, SIGMA, BLOCK = 40000, 0.05, 200  # 4 s at 10 kHz; white residue std; samples per 50 Hz block
W = 70 * np.sin(np.linspace(0, 6, N))  # simulated speed [rad/s]


def test_burst_test_catches_a_short_burst_that_ljung_box_misses():
    """White residue, plus one 50 ms burst of k standard errors of a block mean (2.5 blocks of 20 ms).

    Without it both tests pass; with it the burst test rejects every seed while Ljung-Box, which sums
    autocorrelations over the whole motion, still passes nearly always. burst_z is the largest of the
    two fully covered block means over the robust scale: k + E[max of 2 N(0, 1)] = k + 1/sqrt(pi) on
    average, and burst_p the Sidak p-value of the largest of 200 block means."""
    k, alpha, sb = 6.0, 1e-3, SIGMA / np.sqrt(BLOCK)
    z, ljung_box_passed = [], 0
    for seed in range(20):
        r = SIGMA * np.random.default_rng(seed).standard_normal(N)
        white = residue_check("speed", W + r, W, H, alpha, 50.0, 10, 1e-4)
        assert white.p_value >= alpha and white.burst_p >= alpha and white.passed
        r[20000:20500] += k * sb  # starts on a block boundary
        burst = residue_check("speed", W + r, W, H, alpha, 50.0, 10, 1e-4)
        assert burst.burst_p < alpha and not burst.passed  # not white, and above rms_tol = 1e-4 of the range
        assert burst.burst_p == pytest.approx(N // BLOCK * 2 * stats.norm.sf(burst.burst_z), rel=1e-3)
        z.append(burst.burst_z)
        ljung_box_passed += burst.p_value >= alpha
    assert ljung_box_passed >= 18
    assert np.mean(z) == pytest.approx(k + 1 / np.sqrt(np.pi), abs=0.5)


@pytest.mark.parametrize("length_s, expected", [(0.05, 1.0), (0.0125, 0.5), (0.2, 1.0)])
def test_worst_window_rms_of_a_known_burst(length_s, expected):
    """A burst of amplitude A on a zero residue: the worst 50 ms window holds min(length, 50 ms) of it,
    so its RMS is A sqrt(min(length, 50 ms) / 50 ms); the whole-motion RMS is A sqrt(length / 4 s)."""
    amplitude, start = 0.7, 15000
    r = np.zeros(N)
    r[start:start + int(round(length_s / H))] = amplitude
    c = residue_check("speed", W + r, W, H, 1e-3, 50.0, 10, 0.01)
    span = np.ptp(W + r)
    assert c.peak_rms_relative == pytest.approx(amplitude * expected / span, rel=1e-9)
    assert c.rms_relative == pytest.approx(amplitude * np.sqrt(length_s / (N * H)) / span, rel=1e-9)


def test_edge_s_leaves_the_ends_out():
    """A large burst in the first 50 ms (a filter transient) and a small one mid-motion: with edge_s = 0.1 s
    the worst window and the burst test see only the small one."""
    big, small, sb = 2.0, 0.1, SIGMA / np.sqrt(BLOCK)
    r = SIGMA * np.random.default_rng(3).standard_normal(N)
    r[:500] += big
    exact = np.zeros(N)
    exact[:500], exact[20000:20500] = big, small
    for edge_s, amplitude in ((0.0, big), (0.1, small)):
        peak = residue_check("speed", W + exact, W, H, 1e-3, 50.0, 10, 0.01, edge_s=edge_s).peak_rms_relative
        assert peak == pytest.approx(amplitude / np.ptp(W + exact), rel=1e-9)
        c = residue_check("speed", W + r, W, H, 1e-3, 50.0, 10, 0.01, edge_s=edge_s)
        if edge_s:
            assert c.burst_p > 1e-3 and c.burst_z < 4
        else:
            assert c.burst_z == pytest.approx(big / sb, rel=0.15) and c.burst_p < 1e-100


def test_the_band_widens_the_size_rule_by_c_times_its_rms():
    """A coloured residue of A = 1.5 % of the range over 50 ms and a constant band B: the worst window's
    excess is exactly (A - c B) / range; accepted when that is below rms_tol, rejected without the band."""
    r = np.zeros(N)
    r[20000:20500] = amplitude = 0.015 * np.ptp(W)
    span = np.ptp(W + r)
    for c, band_rms, passed in ((4.0, 0.002 * span, True), (4.0, 0.001 * span, False), (0.0, 0.002 * span, False)):
        check = residue_check("speed", W + r, W, H, 1e-3, 50.0, 10, 0.01, band=np.full(N, band_rms), band_factor=c)
        assert check.burst_p < 1e-3  # not white: the size rule decides
        assert check.excess_relative == pytest.approx((amplitude - c * band_rms) / span, rel=1e-9)
        assert check.band_relative == pytest.approx(band_rms / span, rel=1e-9)
        assert check.peak_rms_relative == pytest.approx(amplitude / span, rel=1e-9)
        assert check.passed is passed
    plain = residue_check("speed", W + r, W, H, 1e-3, 50.0, 10, 0.01)
    assert not plain.passed and plain.band is None and plain.band_relative == 0.0
    assert plain.excess_relative == plain.peak_rms_relative


def test_band_of_a_linear_model_is_exact():
    """y(t) = a t + b t^2 (c unused): sigma(t)^2 = t^2 Saa + 2 t^3 Sab + t^4 Sbb, whatever the correlation,
    also for a singular covariance (a and b perfectly correlated: one axis, rank 1)."""
    t = np.linspace(0.0, 2.0, 201)

    def simulate(p):
        return p["a"] * t + p["b"] * t**2

    theta = {"a": 1.0, "b": -0.5, "c": 3.0}
    for cov, rank in ((np.array([[0.04, -0.01, 0.5], [-0.01, 0.09, 0.2], [0.5, 0.2, 9.0]]), 2),
                      (np.array([[0.04, 0.06, 0.0], [0.06, 0.09, 0.0], [0.0, 0.0, 9.0]]), 1)):
        band, k = uncertainty_band(simulate, theta, ("a", "b", "c"), cov, ("a", "b"))
        expected = np.sqrt(t**2 * cov[0, 0] + 2 * t**3 * cov[0, 1] + t**4 * cov[1, 1])
        assert k == rank and band == pytest.approx(expected, rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("signal", ["speed", "current"])
def test_band_matches_the_spread_of_simulations(signal):
    """Second engine: 300 simulations with parameters drawn from N(theta, Sigma) (the estimator's own
    estimate and covariance, healthy motion) have, in every 50 ms window, the RMS standard deviation of
    the finite-difference band within 20 % (5 times the 4 % sampling error of a standard deviation from
    300 draws; the windows see different combinations of the parameters), and over the whole motion
    within 8 %."""
    v = validate(measure(plant_motion(), 1))
    est = estimate_motion(MotionData(H, v.u, v.i, v.w))
    f = FILTER.apply({"u": v.u, "i": v.i, "w": v.w}, H)

    def simulate(p):
        if signal == "current":
            return model_reference("current", f, H, p)
        return simulate_speed(f["i"], p, H, w0=float(f["w"][0]), step=5e-4, w_eps=0.01)

    values = {k: p.value for k, p in est.parameters.items()}
    band, _ = uncertainty_band(simulate, values, est.names, est.covariance, USES[signal])
    draws = np.random.default_rng(5).multivariate_normal(est.result.values, est.covariance, 300)
    spread = np.std([simulate(dict(zip(est.names, d))) for d in draws], axis=0, ddof=1)
    ratio = window_rms(spread[500:-500], 500) / window_rms(band[500:-500], 500)
    assert np.all(np.abs(ratio - 1) < 0.2)
    assert np.sqrt(np.mean(spread**2) / np.mean(band**2)) == pytest.approx(1.0, abs=0.08)


def test_bad_input_is_named():
    y = plant_motion()
    with pytest.raises(EstimatorInputError, match="Cd"):
        check_model(y["u"], y["i"], y["w"], H, {"R": 0.6, "L": 4e-3, "K": 1.05, "Jt": 0.1, "ft": 0.02}, FILTER)
    with pytest.raises(EstimatorInputError, match="blocks"):
        residue_check("speed", np.ones(1000), np.zeros(1000), H, 1e-3, 50.0, 10, 0.01)
    with pytest.raises(EstimatorInputError, match="band has shape"):
        residue_check("speed", W, W, H, 1e-3, 50.0, 10, 0.01, band=np.ones(10), band_factor=4.0)
    for cov, names, match in ((np.eye(6), None, "covariance"), (np.eye(5), tuple(TRUTH), r"\(p, p\)"),
                              (np.full((6, 6), np.nan), tuple(TRUTH), "finite"),
                              (np.eye(7), (*TRUTH, "T0"), r"names \['T0'\]")):
        with pytest.raises(EstimatorInputError, match=match):
            check_model(y["u"], y["i"], y["w"], H, TRUTH, FILTER, covariance=cov, names=names)
