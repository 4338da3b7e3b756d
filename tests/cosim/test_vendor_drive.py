"""A vendor-style drive FMU (held inputs, analog-style PI loops with a fast current loop, no reference filter,
rpm / mm interface): instantaneous voltage samples bias R and L by about -20 %; with the plant stepped 10 times
per 1e-4 s recording step and interval-mean sampling (the default) they are within 1 % on noise-free data,
and with the default sensor noise the 95 % intervals cover the truth over 10 seeds (at most the 3 misses in 60
that 95 % intervals make on average; measured 2: L of seed 4 and R of seed 8, the noise-free biases of R and
L being 0.00 % and -0.08 %, about one standard error of L)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from feeddrive.cosim.monitor import MonitorConfig, MonitorPipeline, centred_speed
from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import scenario_from_dict
from feeddrive.estimator.history import History

sys.path.insert(0, str(Path(__file__).parents[1] / "plants"))
from vendor_drive import ROLE_MAP, TRUTH, build_vendor_drive  # noqa: E402

EXAMPLE = Path(__file__).parents[2] / "examples" / "tool_change.yaml"
QUIET = {"noise": 0.0}
#: the sensors' default noise levels (std) of the channels the monitor uses
NOISE = {"Im1": 0.05, "Im2": 0.05, "u": 0.2, "u_ref": 0.2, "w_tach": 0.05}


@pytest.fixture(scope="module")
def vendor_fmu(tmp_path_factory) -> Path:
    return build_vendor_drive(tmp_path_factory.mktemp("vendor") / "VendorHeldDrive.fmu")


def run(fmu: Path, out: Path, oversample: int, sampling: str | None = None):
    data = yaml.safe_load(EXAMPLE.read_text())
    data["plant"] = {"fmu": str(fmu), "oversample": oversample, "map": ROLE_MAP}
    chan = QUIET | ({"sampling": sampling} if sampling else {})
    data["sensors"] = {"seed": 1, "current": [chan, chan], "voltage": chan, "voltage_ref": chan, "tachometer": chan,
                       "encoder": QUIET}
    data["monitor"] = {"db": ":memory:"}
    scenario = scenario_from_dict(data)
    return scenario, run_scenario(scenario, out, plots=False)


@pytest.fixture(scope="module")
def oversampled(vendor_fmu, tmp_path_factory):
    return run(vendor_fmu, tmp_path_factory.mktemp("m10"), 10)


def bias(motion: dict, name: str) -> float:
    return motion["parameters"][name]["value"] / TRUTH[name] - 1


def test_the_fmu_holds_its_inputs_and_instant_samples_are_biased(vendor_fmu, tmp_path):
    scenario, result = run(vendor_fmu, tmp_path, 1, "instant")
    assert scenario.plant.input_hold == "zoh"  # canInterpolateInputs="false"
    (motion,) = result.report["motions"]
    assert bias(motion, "R") < -0.10 and bias(motion, "L") < -0.10, motion["parameters"]  # measured -23 %
    # the model check rejects, and the run says that the set-up's sampling, not the drive, explains it
    assert motion["mismatch"]["passed"] is False
    note = result.report["held_inputs"]
    assert "plant.input_hold zoh" in note and "plant.oversample 1" in note and "sampling instant" in note, note
    assert "plant.oversample: 4 or more" in note


def test_oversampled_interval_means_give_r_and_l_within_one_percent(oversampled):
    scenario, result = oversampled
    assert scenario.monitor.config.sampling == {"voltage": "mean", "current": "mean", "speed": "mean"}
    assert result.report["components"]["sensors"]["oversample"] == 10
    (motion,) = result.report["motions"]
    for name in ("R", "L"):
        assert abs(bias(motion, name)) < 0.01, (name, motion["parameters"][name])  # measured -0.04 %, -0.07 %
    assert np.abs(result.signals["plant.speed"]).max() > 60  # a real rapid (rad/s, from rpm)
    assert "held_inputs" not in result.report  # oversampled interval means: no note (cosim/held_inputs.py)


def test_the_cis_cover_the_truth_with_the_default_noise_over_ten_seeds(oversampled):
    """The noise-free samples of the oversampled run plus the sensors' default white noise (one draw per
    recorded sample, as the sensors add it), through the monitor's pipeline: 10 seeds x 6 intervals."""
    scenario, result = oversampled
    sig, h = result.signals, scenario.step
    rows = sig["nc.state"] == 1  # the monitor's rows of the high-speed motion
    clean = {k: sig[f"sensors.{k}"][rows] for k in ("Im1", "Im2", "u", "u_ref", "w_tach", "w_enc", "theta_enc")}
    config = MonitorConfig(axis="X", sampling=scenario.monitor.config.sampling)
    misses = []
    for seed in range(10):
        rng = np.random.default_rng(seed)
        noisy = {k: x + NOISE[k] * rng.standard_normal(x.size) if k in NOISE else x.copy() for k, x in clean.items()}
        noisy["w_enc"] = centred_speed(noisy["theta_enc"], noisy["w_enc"], h, config.encoder_window_s)
        with History(":memory:") as history:
            trace = MonitorPipeline(config, history, "X").process(noisy, h, 0.0, 1, 0.0, "seed")
        params = trace.result["parameters"]
        assert params, trace.result["error"]
        for name, truth in TRUTH.items():
            lo, hi = params[name]["ci95"]
            if not lo <= truth <= hi:
                misses.append((seed, name, params[name]))
    assert len(misses) <= 3, misses  # 60 intervals at 95 %: 3 misses expected
