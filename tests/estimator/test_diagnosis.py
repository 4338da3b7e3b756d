"""Diagnosis (paper Table I) on sequences of validated estimates with known drifts.

Estimates are the true values plus Gaussian estimation noise of a stated relative standard error
(0.5 %, about what the IV estimator gives on one 3.5 s motion of the plant), reported with that std.
"""
import numpy as np
import pytest

from feeddrive.estimator.diagnosis import UNEXPLAINED, DiagnosisOptions, diagnose, drifts, make_baseline
from feeddrive.estimator.errors import EstimatorInputError
from feeddrive.models import feed_drive

TRUE = {k: v for k, v in feed_drive().nominal(("physical",)).items() if k != "T0"}
REL_STD = 0.005
WEAR = {"bearing or slide-way wear", "lack or ageing of lubricating oil"}


def estimates(truth_per_motion, seed):
    rng = np.random.default_rng(seed)
    return [{k: {"value": v * (1 + REL_STD * rng.standard_normal()), "std": REL_STD * v} for k, v in t.items()}
            for t in truth_per_motion]


def run(sets, n_baseline=3):
    """Diagnose each motion after the baseline, as the monitor does."""
    base = make_baseline(sets[:n_baseline])
    return [diagnose(sets[j], base, sets[j - 1], sets[:j]) for j in range(n_baseline, len(sets))]


@pytest.mark.parametrize("seed", range(10))
def test_friction_drift_is_wear_or_lubrication_at_the_right_motion(seed):
    """Cd and ft rise 2 % per motion from motion 5: no alarm while the drift is <= 3 %, alarm from 8 %."""
    drift = [max(0, j - 4) * 0.02 for j in range(20)]
    truth = [{**TRUE, "Cd": TRUE["Cd"] * (1 + d), "ft": TRUE["ft"] * (1 + d)} for d in drift]
    results = run(estimates(truth, seed))
    for d, diag in zip(drift[3:], results):
        faults = {x.fault for x in diag}
        if d <= 0.03:
            assert faults == set(), (d, faults)
        elif d >= 0.08:
            assert faults == WEAR, (d, faults)
            for x in diag:
                assert x.parameters == ("Cd", "ft")
                for ev in x.evidence:
                    assert ev.relative_change == pytest.approx(d, abs=0.03)
                    assert ev.z_baseline > DiagnosisOptions().z_crit
                    assert ev.trend_per_motion == pytest.approx(0.02, abs=0.01)


def test_inertia_step_is_a_missing_work_piece():
    truth = [dict(TRUE, Jt=TRUE["Jt"] * (0.7 if j >= 10 else 1.0)) for j in range(16)]
    results = run(estimates(truth, 1))
    for j, diag in enumerate(results, start=3):
        if j < 10:
            assert diag == []
        else:
            assert [x.fault for x in diag] == ["missing work-piece or work-piece holder"]
            ev = diag[0].evidence[0]
            assert ev.parameter == "Jt" and ev.relative_change == pytest.approx(-0.3, abs=0.02)
            # a sudden change: significant against the last validated set only at the step
            assert (abs(ev.z_last) > 10) == (j == 10)


def test_table_i_mapping_and_dominance():
    base = {k: (v, 0.001 * v) for k, v in TRUE.items()}

    def faults(**change):
        cur = {k: (v * change.get(k, 1.0), 0.001 * v) for k, v in TRUE.items()}
        return {d.fault: d.parameters for d in diagnose(cur, base)}

    # K and L measured to 0.1 % and steady: heating (R, L, K) is contradicted, brush wear is not
    assert faults(R=1.2) == {"brush wear": ("R",)}
    assert faults(R=1.2, K=0.9) == {"motor heating": ("K", "R")}
    # R steady: demagnetisation, not heating
    assert faults(K=0.9) == {"demagnetisation": ("K",)}
    assert faults(L=1.2, K=0.9) == {"demagnetisation": ("K", "L")}
    # K rising is against heating's direction: brush wear alone explains R, K is unexplained
    assert faults(R=1.2, K=1.1) == {"brush wear": ("R",), UNEXPLAINED: ("K",)}
    assert faults(Jt=1.3) == {UNEXPLAINED: ("Jt",)}  # more inertia is not a missing work-piece
    assert faults(Cd=0.8) == {UNEXPLAINED: ("Cd",)}
    assert faults(R=1.02) == {}  # significant (20 standard errors) but below 5 %


def test_an_imprecise_steady_parameter_contradicts_nothing():
    """With R known only to 5 % (a 5 % change would be 0.7 standard errors), a steady R cannot rule
    out motor heating: K down stays ambiguous between heating and demagnetisation."""
    base = {k: (v, (0.05 if k == "R" else 0.001) * v) for k, v in TRUE.items()}
    cur = {k: (v * (0.9 if k == "K" else 1.0), (0.05 if k == "R" else 0.001) * v) for k, v in TRUE.items()}
    assert {d.fault for d in diagnose(cur, base)} == {"motor heating", "demagnetisation"}


def test_drift_evidence_numbers():
    cur = {"Cd": {"value": 1.5, "std": 0.03}}
    d, = drifts(cur, {"Cd": (1.2, 0.04)}, last={"Cd": (1.45, 0.03)}, recent=[{"Cd": (1.3, 0.03)}, {"Cd": (1.4, 0.03)}])
    assert d.relative_change == pytest.approx(0.25)
    assert d.z_baseline == pytest.approx(0.3 / 0.05)
    assert d.z_last == pytest.approx(0.05 / np.hypot(0.03, 0.03))
    assert d.trend_per_motion == pytest.approx(0.1 / 1.2)
    assert d.significant


def test_baseline_is_the_mean_with_an_honest_std():
    sets = [{"R": (0.60, 0.001)}, {"R": (0.62, 0.001)}, {"R": (0.61, 0.001)}]
    (value, std), = make_baseline(sets).values()
    assert value == pytest.approx(0.61)
    assert std == pytest.approx(0.01 / np.sqrt(3))  # the scatter dominates the tiny standard errors
    (_, std), = make_baseline([{"R": (0.6, 0.003)}, {"R": (0.6, 0.004)}]).values()
    assert std == pytest.approx(0.005 / 2)


def test_bad_input_is_named():
    with pytest.raises(EstimatorInputError, match="'Cd'"):
        diagnose({"Cd": {"value": 1.0, "std": float("nan")}}, {"Cd": (1.0, 0.1)})
    with pytest.raises(EstimatorInputError, match="no parameter sets"):
        make_baseline([])
    with pytest.raises(EstimatorInputError, match="alpha"):
        DiagnosisOptions(alpha=0.0)


def test_baseline_and_drifts_with_a_refused_parameter():
    """A motion that refused L (monitor, one parameter at a time) still counts for R; L from the others."""
    base = make_baseline([{"R": (0.6, 0.003), "L": (0.004, 1e-5)}, {"R": (0.62, 0.003)}])
    assert base["L"] == (0.004, 1e-5) and base["R"][0] == pytest.approx(0.61)
    d = {x.parameter: x for x in drifts({"R": (0.9, 0.003)}, base)}
    assert set(d) == {"R"} and d["R"].significant and d["R"].relative_change == pytest.approx(0.9 / 0.61 - 1)
