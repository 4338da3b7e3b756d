"""Decimation of the filtered signals before the regressions (EstimationOptions.decimation, issue 26).

The low-passed signals carry the model on every D-th sample: the estimates on the decimated samples equal
those on every sample to a small fraction of their own intervals, the intervals keep their width (the
covariance is taken over blocks of the same duration), and the rate used is stated.
"""
from __future__ import annotations

import numpy as np
import pytest
from plant_data import TRUTH, H, add_noise, closed_loop

from feeddrive.estimator import EstimationOptions, EstimatorInputError, FilterSpec, MotionData, estimate_motion
from feeddrive.estimator.filtering import MAX_DECIMATED_PHASE, MIN_DECIMATED_SAMPLES, decimation_factor


@pytest.fixture(scope="module")
def noisy():
    return add_noise(closed_loop(), 30.0, seed=3)


@pytest.mark.parametrize(("cutoff", "h", "n", "expected"), [
    (50.0, 1e-4, 35000, 7),     # 2 pi 50 (2e-4 D) <= 0.5 rad: D <= 7.96
    (100.0, 1e-4, 35000, 3),    # D <= 3.98
    (100.0, 1.25e-4, 32000, 3),  # the PMSM's 8 kHz: D <= 3.18
    (50.0, 1e-3, 3500, 1),      # an NC's 1 ms: nothing to step over
    (50.0, 1e-4, 6000, 3),      # short: at least MIN_DECIMATED_SAMPLES kept
    (50.0, 1e-4, 3000, 1),      # shorter still: every sample
])
def test_the_factor_follows_the_halves_phase_and_the_record_length(cutoff, h, n, expected):
    d = decimation_factor(cutoff, h, n)
    assert d == expected
    assert d == 1 or 2 * np.pi * cutoff * 2 * h * d <= MAX_DECIMATED_PHASE
    assert d == 1 or n // d >= MIN_DECIMATED_SAMPLES
    assert decimation_factor(cutoff, h, n, 1) == 1 and decimation_factor(cutoff, h, n, 5) == 5


@pytest.mark.parametrize(("cutoff", "h", "n", "requested", "expected"), [
    (100.0, 1e-4, 35000, "auto", 5),     # 2 pi 100 (1e-4 D) <= 0.5 rad: D <= 7.96, lowered to a divisor of 200
    (50.0, 1e-4, 35000, "auto", 10),     # D <= 15.9: 10 of the 200-sample block
    (100.0, 1.25e-4, 32000, "auto", 5),  # 8 kHz: D <= 6.37, the block 160 samples
    (50.0, 1e-3, 3500, "auto", 1),       # an NC's 1 ms
    (100.0, 1e-4, 6000, "auto", 2),      # short: at least MIN_DECIMATED_SAMPLES kept (3, lowered)
    (100.0, 1e-4, 35000, 3, 2),          # a factor given: lowered to a divisor too
    (100.0, 1e-4, 35000, 1, 1),
])
def test_the_checks_factor_follows_their_own_phase_and_divides_the_blocks(cutoff, h, n, requested, expected):
    from feeddrive.estimator.filtering import check_rate_factor
    from feeddrive.estimator.residue_tests import block_samples

    d = check_rate_factor(cutoff, h, n, requested)
    assert d == expected
    assert block_samples(50.0, h) % d == 0
    assert requested != "auto" or d == 1 or (2 * np.pi * cutoff * h * d <= MAX_DECIMATED_PHASE
                                             and n // d >= MIN_DECIMATED_SAMPLES)


@pytest.mark.parametrize("bad", [0, -2, 2.5, "yes", True])
def test_a_bad_decimation_is_refused_naming_the_option(bad):
    with pytest.raises(EstimatorInputError, match="decimation"):
        EstimationOptions(decimation=bad)


def test_decimated_iv_equals_every_sample_within_a_fifth_of_its_interval(noisy):
    """30 dB white noise, 10 kHz, 50 Hz filter: D = 7. Each parameter moves by less than a fifth of its 95 %
    half-width (a tenth of a standard error: Cd moved most, 0.10 of it), the half-widths agree within 10 %,
    and the decimated intervals hold the truth."""
    data = MotionData(H, u=noisy["u"], i=noisy["i"], w=noisy["w"])
    full = estimate_motion(data, EstimationOptions(decimation=1))
    dec = estimate_motion(data, EstimationOptions())
    assert full.rate_hz == pytest.approx(1 / H) and dec.rate_hz == pytest.approx(1 / (7 * H))
    assert dec.to_dict()["rate_hz"] == pytest.approx(1 / (7 * H))
    for name, p in full.parameters.items():
        q = dec.parameters[name]
        half = (p.ci95[1] - p.ci95[0]) / 2
        assert abs(q.value - p.value) < 0.2 * half, name
        assert (q.ci95[1] - q.ci95[0]) / 2 == pytest.approx(half, rel=0.1), name
        assert q.ci95[0] <= TRUTH[name] <= q.ci95[1], name


def test_noise_free_decimated_estimate_within_a_twentieth_of_a_percent():
    """The noise-free round trip with a 100 Hz filter stepped over by D = 3 (auto) and D = 7 (forced, the halves'
    phase 0.88 rad): every parameter within 0.05 % of the truth by LS and IV."""
    d = closed_loop()
    data = MotionData(H, u=d["u"], i=d["i"], w=d["w"])
    for decimation in ("auto", 7):
        est = estimate_motion(data, EstimationOptions(filter=FilterSpec(100.0), decimation=decimation))
        for result in (est.ls, est.iv):
            err = {n: p.value / TRUTH[n] - 1 for n, p in result.parameters.items()}
            assert max(abs(e) for e in err.values()) < 5e-4, (decimation, result.method, err)
