"""When the run says that a model-check rejection comes from sampling a held-input plant (cosim/held_inputs.py).

The whole chain on a real held-input drive FMU is in test_vendor_drive.py; here the rule itself."""
from __future__ import annotations

from types import SimpleNamespace

from feeddrive.cosim.cli.run import summary
from feeddrive.cosim.held_inputs import held_input_note, sampling_bias_note

REJECTED = {"mismatch": {"passed": False, "test": "current size", "p_value": 0.0, "alpha": 0.01},
            "parameters": {"R": {"value": 0.46}}}
PASSED = {"mismatch": {"passed": True, "test": "current size"}}
MEAN = {"voltage": "mean", "current": "mean"}


def test_a_rejection_of_a_held_plant_sampled_once_per_step_is_explained():
    note = held_input_note("zoh", 1, MEAN, [PASSED, REJECTED, REJECTED])
    assert note.startswith("motions 2, 3: the model check rejects a plant that holds its inputs")
    assert "sampled once per recorded sample (plant.oversample 1)" in note and "not averaged" not in note


def test_instantaneous_samples_are_named_at_any_oversampling():
    note = held_input_note("zoh", 10, {"voltage": "instant", "current": "mean"}, [REJECTED])
    assert note.startswith("motion 1:") and "10 times per recorded sample" in note
    assert "voltage not averaged over it (sampling instant)" in note


def test_no_note_where_it_does_not_apply():
    assert held_input_note("foh", 1, MEAN, [REJECTED]) is None  # ramped inputs: no staircase
    assert held_input_note("zoh", 1, MEAN, [PASSED, {"error": "motion too short"}]) is None  # nothing rejected
    assert held_input_note("zoh", 4, MEAN, [REJECTED]) is None  # averaged: the rejection is the drive's
    assert held_input_note(None, 1, MEAN, [REJECTED]) is None  # a user's plant component


def test_the_console_prints_it_after_the_motions():
    report = {"scenario": "held", "stop_time_s": 1.0, "wall_time_s": 0.5, "steps": 10, "step_s": 0.1,
              "motions": [REJECTED], "held_inputs": held_input_note("zoh", 1, MEAN, [REJECTED])}
    text = summary(SimpleNamespace(report=report, signals={}, out_dir="runs/x", paths={"plots": []}))
    lines = text.splitlines()
    assert lines[1].startswith("  motion 1: model mismatch")
    assert any(line.startswith("  set-up: motion 1: the model check rejects a plant that holds") for line in lines)


def _motion(L: float, half: float) -> dict:
    return {"mismatch": {"passed": True}, "parameters": {"R": {"value": 0.6, "ci95": [0.599, 0.601]},
                                                         "L": {"value": L, "ci95": [L * (1 - half), L * (1 + half)]}}}


def test_the_discretisation_error_of_l_is_said_where_its_interval_would_not_hold_it():
    """-(h R / L)^2: 2.25 % at 1 ms for L / R = 6.7 ms, against a +-1.1 % interval (the 1 kHz tool change)."""
    note = sampling_bias_note("foh", 1e-3, 1, MEAN, [_motion(4e-3, 0.011)])
    assert note.startswith("motion 1: L may read about 2.2 % low (L = 4 mH, its 95 % interval ±1.1 %)")
    assert "(h R / L)^2 = 2.2 %" in note and "L / R = 6.7 ms" in note and "plant.oversample 1)" in note
    several = sampling_bias_note("foh", 5e-4, 1, {"voltage": "instant", "current": "mean"},
                                 [_motion(4e-3, 0.5), _motion(4e-3, 0.011), _motion(3.8e-3, 0.011)])
    assert several.startswith("motions 2, 3 (largest: motion 3): L may read about 0.62 % low")
    assert "plant.oversample 1, voltage sampling instant" in several


def test_no_discretisation_note_where_it_does_not_apply():
    assert sampling_bias_note("foh", 1e-4, 1, MEAN, [_motion(4e-3, 0.011)]) is None  # 0.02 %: within the interval
    assert sampling_bias_note("foh", 1e-3, 1, MEAN, [_motion(4e-3, 0.2)]) is None  # a wide interval holds it
    assert sampling_bias_note("foh", 1e-3, 4, MEAN, [_motion(4e-3, 0.011)]) is None  # averaged over 4 sub-steps
    assert sampling_bias_note("zoh", 1e-3, 1, MEAN, [_motion(4e-3, 0.011)]) is None  # another error (held_input_note)
    assert sampling_bias_note(None, 1e-3, 1, MEAN, [_motion(4e-3, 0.011)]) is None  # a user's plant component
    assert sampling_bias_note("foh", 1e-3, 1, MEAN, [{"parameters": {"R": {"value": 0.6}}}, {"error": "short"}]) is None
