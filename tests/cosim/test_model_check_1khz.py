"""The healthy built-in axis recorded at 1 kHz passes the model check (it was rejected on every seed).

At 1 kHz the monitor's 100 Hz filter keeps a fifth of the band, and the current residue (filtered measured
current minus the current simulated from the filtered voltage and speed) carries the voltage sensor's noise
through 1 / (L s + R): 0.08 A for the 0.2 V default, more than the current sensor's own 0.05 A. The size test
compared the residue with the current sensor's noise alone: F = 2.3 to 3.4 on 20 of 20 seeds, "model mismatch"
on a healthy motor (`estimator.mismatch.input_noise_variance` now adds that share; 3 of 60 seeds rejected
after, by the current independence test: the instantaneous 1 kHz samples' own error, README "Known limitations")."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from feeddrive.cosim.run import run_scenario
from feeddrive.cosim.scenario import scenario_from_dict

EXAMPLES = Path(__file__).parents[2] / "examples"


@pytest.mark.parametrize("seed", [1, 2])
def test_a_healthy_axis_at_1_khz_passes_the_model_check(seed, tmp_path):
    data = yaml.safe_load((EXAMPLES / "tool_change.yaml").read_text())
    data |= {"step": 1.0e-3, "monitor": {"db": ":memory:"}}
    data["sensors"]["seed"] = seed
    result = run_scenario(scenario_from_dict(data, base_dir=EXAMPLES), tmp_path / "run", plots=False, page=False)
    (motion,) = result.report["motions"]
    check = motion["mismatch"]
    assert check["passed"] and motion["validated"], check["test"]
    current = check["checks"]["current"]
    # the null: the current sensor's 0.05 A and the 0.08 A the simulation passes from the 0.2 V voltage noise
    assert 0.09 < current["noise_std"] < 0.13, current["noise_std"]
    assert current["size"]["statistic"] < 1.0  # measured 0.56 to 0.85 over 20 seeds (2.3 to 3.4 before)
    assert abs(motion["parameters"]["R"]["value"] / 0.6 - 1) < 0.01  # and the estimate is the motor's
    # L is (h R / L)^2 low (the samples sit on the ramped command's corners; cosim/held_inputs.py), outside its
    # interval: the run says so and by how much (measured -2.2 % on seed 1; 10 kHz data decimated: within 0.2 %)
    ell = motion["parameters"]["L"]
    predicted = (1e-3 * 0.6 / 4e-3) ** 2
    assert abs(ell["value"] / 4e-3 - 1 + predicted) < 0.01, ell
    note = result.report["sampling_bias"]
    assert note.startswith("motion 1: L may read about 2.") and "plant.oversample: 4" in note, note
