"""Issue 12's campaign figures, with fewer runs (the full campaigns are examples/campaign_check_*.yaml).

Each test runs the example campaign itself (``run_campaign``, 2 worker processes) with fewer
repetitions (its first runs: the same seed), and reads its figures with examples/model_check_figures.py. The
bounds are binomial: with n motions and a true rate at the target, the chance that a healthy check
fails the assertion is stated next to each bound.
"""
from __future__ import annotations

import runpy
from pathlib import Path

import pytest
from scipy.stats import binom

from feeddrive.cosim.campaign import load_campaign, run_campaign

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def FIGURES(out: Path) -> dict:  # noqa: N802 -- the script's function, loaded when used (it imports statsmodels)
    return runpy.run_path(str(EXAMPLES / "model_check_figures.py"))["figures"](out)

pytestmark = pytest.mark.slow


def campaign_figures(tmp_path: Path, name: str, repetitions: int, **base_update) -> dict:
    """The first ``repetitions`` runs of examples/campaign_check_<name>.yaml (its own seed), and their figures."""
    campaign = load_campaign(EXAMPLES / f"campaign_check_{name}.yaml")
    base = campaign.base_scenario()
    for key, value in base_update.items():
        base[key] = value | {k: v for k, v in base.get(key, {}).items() if k not in value}
    campaign = campaign.model_copy(update={"repetitions": repetitions, "base": base})
    result = run_campaign(campaign, tmp_path / name, workers=2, plots=False)
    assert not result.failed, [r.get("error") for r in result.failed]
    return FIGURES(tmp_path / name)


def coverage_ok(figures: dict, floor: float) -> None:
    """Every parameter's CI coverage at least ``floor`` (L too: before each parameter had its own degrees
    of freedom, estimator.motion.parameter_covariance, L covered 87 % on the vendor campaign and 17 of 24
    on another seed of the built-in one)."""
    assert set(figures["coverage"]) == {"R", "L", "K", "Jt", "ft", "Cd"}
    low = {k: v for k, v in figures["coverage"].items() if v < floor}
    assert not low, f"CI coverage below {floor:.0%}: {low}"


def test_healthy_builtin_false_alarms_and_coverage(tmp_path):
    """12 healthy motions, 0.02-0.3 m/s: at most 1 rejected at alpha 1 % (P(X >= 2 | p=0.02) = 2.3 %);
    every parameter's 95 % CI covers the truth in at least 8 of 12 (a 90 % coverage falls below that with
    P = 0.4 %). The 100-motion campaign is examples/campaign_check_healthy.yaml."""
    fig = campaign_figures(tmp_path, "healthy", 12)
    assert fig["motions"] == 12
    assert fig["rejected"] <= 1, fig
    assert binom.sf(1, 12, 0.02) < 0.025 and binom.cdf(7, 12, 0.9) < 0.005
    coverage_ok(fig, 8 / 12)


def test_healthy_vendor_false_alarms_and_coverage(tmp_path, built_once):
    """8 healthy motions of the vendor-style FMU (held inputs, analog PI loops, other names and
    units): at most 1 rejected (P(X >= 2 | p=0.02) = 1.0 %), coverage at least 5 of 8 for every parameter
    (P = 0.5 % at a true 90 %)."""
    build = runpy.run_path(str(EXAMPLES / "vendor_fmu" / "build_vendor_fmu.py"))
    fmu = built_once("VendorDrive", lambda folder: build["main"](["--out", str(folder / "VendorDrive.fmu")]))
    fig = campaign_figures(tmp_path, "vendor", 8, plant={"fmu": str(fmu)})
    assert fig["motions"] == 8
    assert fig["rejected"] <= 1, fig
    assert binom.sf(1, 8, 0.02) < 0.011 and binom.cdf(4, 8, 0.9) < 0.006
    coverage_ok(fig, 5 / 8)


def test_backlash_and_cd_step_are_detected(tmp_path):
    """4 motions with backlash 0.02 / 0.06 rad (sweep) and 4 with a Cd +10 % step inside the motion, all
    rejected (the examples' full campaigns: 30 of 30 each, README "Limits")."""
    backlash = campaign_figures(tmp_path, "backlash", 2)
    assert backlash["motions"] == 4
    assert backlash["rejected"] >= 4, backlash
    step = campaign_figures(tmp_path, "cd_step", 4)
    assert step["motions"] == 4
    assert step["rejected"] >= 4, step


@pytest.mark.parametrize("v_max, accel", [(0.03, 1.0), (0.045, 0.3)])
def test_backlash_on_a_slow_motion_is_a_speed_peak(tmp_path, v_max, accel):
    """Backlash 0.02 rad on a slow tool change (the six misses of the first campaign were all below
    0.05 m/s): the gap crossing leaves a transient of ~0.1 s in ~10 s of motion, which the averaging
    tests can miss (at 0.03 m/s, 1 m/s^2 their p-values were above 0.75) and the peak test sees; the
    same motion without backlash passes."""
    from feeddrive.cosim.campaign.schema import set_key
    from feeddrive.cosim.run import run_scenario
    from feeddrive.cosim.scenario import scenario_from_dict

    campaign = load_campaign(EXAMPLES / "campaign_check_backlash.yaml")
    outcome = {}
    for gap in (0.0, 0.02):
        base = campaign.base_scenario()
        set_key(base, "plant.parameters.backlash", gap)
        set_key(base, "nc.program[1].tool_change.v_max", v_max)
        set_key(base, "nc.program[1].tool_change.accel", accel)
        set_key(base, "sensors.seed", 5)
        run = run_scenario(scenario_from_dict(base, base_dir=campaign.base_dir), tmp_path / f"gap{gap}", plots=False)
        (motion,) = run.report["motions"]
        outcome[gap] = motion["mismatch"]
    assert outcome[0.0]["passed"], outcome[0.0]["checks"]
    assert not outcome[0.02]["passed"] and outcome[0.02]["p_value"] < 1e-6
    # the peak test sees it whichever test decided (at 0.045 m/s, 0.3 m/s^2 the independence test also does)
    assert outcome[0.02]["checks"]["speed"]["peak"]["p_value"] < 1e-4, outcome[0.02]["checks"]["speed"]
