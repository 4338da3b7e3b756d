"""The verdict of a motion (cosim/report/verdict.py) and the page's views of it (cosim/report/views.py):
precedence sensor fault > not estimated > model mismatch > diagnosis > drifting > healthy, a monitor's own
``verdict`` key used as it is, no ``nan`` where a quantity could not be computed, the budget on CPU time."""
from __future__ import annotations

import math

import pytest

from feeddrive.cosim.cli.monitor import table
from feeddrive.cosim.report import views
from feeddrive.cosim.report.verdict import motion_verdict

FAULT = {"sensor": "Im1", "kind": "gain+offset", "gain": 1.0299, "gain_ci95": [1.0297, 1.0301], "offset": 0.19996,
         "offset_ci95": [0.1975, 0.2024]}
PARAMS = {k: {"value": v, "std": 0.01 * v, "ci95": [0.98 * v, 1.02 * v], "unit": u}
          for k, v, u in (("R", 0.6, "Ohm"), ("Cd", 1.2, "N.m"))}
PASSED = {"test": "current independence", "statistic": 1.07, "p_value": 1.0, "alpha": 0.01, "passed": True,
          "checks": {"current": {"independence": {"statistic": 1.07, "df": [22.0, 132.0], "p_value": 0.38},
                                 "rms": 0.029, "noise_std": float("nan")}}}
WEAR = [{"fault": "bearing or slide-way wear", "parameters": ["Cd", "ft"], "evidence": []}]


def motion(**kw) -> dict:
    base = {"motion": 1, "start": 0.2, "end": 3.7, "validated": True, "measurements_valid": True, "parameters": PARAMS,
            "sensor_faults": [], "gain_ratio": 1.0, "relative_gain_error": 0.0, "residues": {}, "mismatch": PASSED,
            "diagnosis": [], "notes": [], "error": None, "processing_s": 2.6, "processing_cpu_s": 0.4}
    return base | kw


@pytest.mark.parametrize("changes, kind, text", [
    # the fault outranks everything: a validated, diagnosed, mismatched motion with a faulty sensor
    ({"sensor_faults": [FAULT], "diagnosis": WEAR, "mismatch": PASSED | {"passed": False},
      "residues": {"current": {"trusted": "Im2"}}}, "sensor fault",
     "sensor fault: Im1 gain 1.03, offset 0.2 A; parameters estimated from Im2"),
    ({"measurements_valid": False, "validated": False}, "sensor fault",
     "sensor fault: a redundant pair disagrees and the faulty sensor is unknown; parameters not validated"),
    ({"parameters": {}, "validated": False, "error": "not enough excitation of Jt"}, "not estimated",
     "not estimated: not enough excitation of Jt"),
    ({"sensor_faults": [FAULT], "parameters": {}, "validated": False, "error": "motion too short"}, "sensor fault",
     "sensor fault: Im1 gain 1.03, offset 0.2 A; not estimated: motion too short"),
    ({"mismatch": PASSED | {"passed": False, "test": "speed size", "p_value": 0.004}, "validated": False,
      "diagnosis": WEAR}, "model mismatch",
     "model mismatch: the speed size test rejects, adjusted p = 0.004 < alpha = 0.01; parameters not validated"),
    ({"diagnosis": WEAR + [{"fault": "lubrication", "parameters": ["Cd", "ft"]}]}, "diagnosis",
     "diagnosis: bearing or slide-way wear; lubrication (Cd, ft)"),
    ({"notes": ["healthy baseline: motion 2 of 3"]}, "healthy",
     "healthy: validated, no drift (healthy baseline: motion 2 of 3)"),
])
def test_precedence(changes, kind, text):
    v = motion_verdict(motion(**changes))
    assert (v["kind"], v["text"]) == (kind, text)
    assert (v["css"] == "healthy") == (kind == "healthy")  # only a healthy motion is green


def test_drifting_needs_the_parameter_colours():
    assert motion_verdict(motion(), {"R": "healthy", "Cd": "drifting"})["text"] == \
        "drifting: Cd beyond half the alarm band (no fault diagnosed)"
    assert motion_verdict(motion(), {"R": "healthy", "Cd": "healthy"})["kind"] == "healthy"
    # a diagnosis outranks a drift
    assert motion_verdict(motion(diagnosis=WEAR), {"Cd": "drifting"})["kind"] == "diagnosis"


def test_the_monitors_own_verdict_wins():
    m = motion(verdict="model mismatch: written by the monitor")
    assert motion_verdict(m) == {"kind": "model mismatch", "text": "model mismatch: written by the monitor",
                                 "css": "bad"}
    m = motion(verdict={"kind": "sensor fault", "text": "sensor fault: w_enc offset 0.3 rad/s"})
    assert motion_verdict(m)["css"] == "bad" and motion_verdict(m)["text"] == "sensor fault: w_enc offset 0.3 rad/s"


def test_model_check_table_names_the_adjusted_level():
    mm = {"test": "speed peak", "statistic": 6.1, "p_value": 0.003, "alpha": 0.01, "passed": False,
          "checks": {"current": {"independence": {"statistic": 1.0, "df": [22.0, 130.0], "p_value": 0.4},
                                 "size": {"statistic": 0.3, "df": [159.0, 34879.0], "p_value": 1.0},
                                 "rms": 0.03, "noise_std": 0.05},
                     "speed": {"independence": {"statistic": 0.6, "df": [11.0, 105.0], "p_value": 0.8},
                               "peak": {"statistic": 6.1, "df": [142.0, 52.54], "p_value": 0.0006},
                               "size": {"statistic": 0.02, "df": [122.0, 34879.0], "p_value": 1.0},
                               "rms": 0.007, "noise_std": None}}}
    c = views.model_check(mm)
    assert c["level"].startswith("alpha/m = 0.01/5 = 0.002 per test (Bonferroni")
    assert [r["key"] for r in c["rows"]] == ["current independence", "current size", "speed independence",
                                             "speed peak", "speed size"]
    assert [r["decision"] for r in c["rows"]] == ["pass"] * 3 + ["reject: mismatch", "pass"]
    assert c["rows"][3]["df"] == "142, 52.54" and c["rows"][3]["symbol"] == "max |z| (MAD units)"
    assert "min(1, 5 p) = 0.003 < alpha = 0.01" in c["summary"]
    assert c["sizes"][1]["noise"].startswith("not checked: no confirmed redundant speed sensor pair")
    assert views.model_check(None) is None


def test_no_nan_where_nothing_was_computed():
    m = motion(gain_ratio=math.nan, relative_gain_error=math.nan,
               residues={"speed": {"kind": "none", "gain_diff": math.nan, "offset": 0.001, "offset_ci95": [0, 0.002],
                                   "noise_std": math.nan, "trusted": None, "valid": True}})
    assert views.gain_ratio(m) == ("not checked: one current sensor",) * 2
    (row,) = views.residue_rows(m)
    assert row["gain_diff"] == "not computed" and row["noise"] == "not computed" and row["offset"].endswith("rad/s")
    text = table([m])
    assert "nan" not in text.lower() and "gain ratio a1/a2: not checked (one current sensor)" in text
    assert text.splitlines()[0] == "motion 1: healthy: validated, no drift"


def test_residue_row_of_a_faulty_sensor_is_not_valid():
    m = motion(sensor_faults=[FAULT], residues={"current": {"kind": "gain+offset", "gain_diff": 0.0295,
                                                            "offset": 0.198, "noise_std": 0.07, "trusted": "Im2",
                                                            "valid": True}})
    (row,) = views.residue_rows(m)
    assert row["valid"] == "no" and row["faults"] == "Im1 gain 1.03, offset 0.2 A" and row["trusted"] == "Im2"


def test_budget_is_judged_on_cpu_time():
    busy = views.processing(motion(processing_s=2.6, processing_cpu_s=1.4), 2.0)
    assert busy["within"] is True and busy["text"].startswith("1.4 s CPU time (2.6 s wall time) against the budget")
    slow = views.processing(motion(processing_s=2.6, processing_cpu_s=2.5), 2.0)
    assert slow["within"] is False and slow["text"].endswith("over budget (CPU time)")
    old = motion(processing_s=2.6)  # a history row from before processing_cpu_s: wall time, labelled, not judged
    del old["processing_cpu_s"]
    wall = views.processing(old, 2.0)
    assert wall["within"] is None and "wall time" in wall["text"] and "OVER" not in wall["text"].upper()


def test_an_underflowed_p_value_is_not_written_as_zero():
    """A rejection so strong that its tail probability underflows to 0.0 reads 'p < 1e-300', not 'p = 0'."""
    from feeddrive.cosim.report.verdict import verdict_line
    from feeddrive.estimator.adequacy import AdequacyResult

    m = {"parameters": {"R": {"value": 0.46}},
         "mismatch": {"passed": False, "test": "current size", "p_value": 0.0, "alpha": 0.01}}
    assert verdict_line(m) == ("model mismatch: the current size test rejects, adjusted p < 1e-300 < alpha = 0.01; "
                               "parameters not validated")
    m["mismatch"]["p_value"] = 1.4e-20
    assert "adjusted p = 1.4e-20 < alpha" in verdict_line(m)
    line = AdequacyResult("model mismatch", 0.0, 0.01, "the electrical equation lacks a term").line()
    assert "(p < 1e-300 < alpha = 0.01)" in line


def test_the_monitor_consoles_residue_check_line_does_not_write_p_zero():
    """`cosim monitor`'s line for the residue model check: an underflowed p reads 'p < 1e-300' (it read 'p = 0')."""
    from feeddrive.cosim.cli.monitor import adequacy_line

    a = {"verdict": "model mismatch", "p_value": 0.0, "alpha": 0.01, "reason": "the electrical equation lacks a term"}
    assert adequacy_line(a) == ("model check (own residue): MODEL MISMATCH (p < 1e-300 at alpha = 0.01): "
                                "the electrical equation lacks a term")
    assert "(p = 0.0234 at alpha" in adequacy_line(a | {"p_value": 0.0234})


@pytest.mark.parametrize("changes, kind, text", [
    ({"diagnosis": [{"fault": "demagnetisation", "parameters": ["psi_f"], "evidence": []}]}, "diagnosis",
     "diagnosis: demagnetisation (psi_f)"),
    ({"diagnosis": [{"fault": "unexplained drift", "parameters": ["Cd", "ft"], "evidence": []}]}, "drifting",
     "drifting: unexplained drift of Cd, ft (no Table I fault matches)"),
    ({}, "healthy", "healthy: validated, no drift"),
    ({"sensor_faults": [FAULT]}, "sensor fault", "sensor fault: Im1 gain 1.03, offset 0.2 A; parameters estimated"),
    ({"validated": False, "notes": ["not validated: Jt refused"]}, "not validated", "not validated: Jt refused"),
])
def test_the_monitors_words_give_the_pages_kind(changes, kind, text):
    """The word the monitor writes (report.json ``verdict``, cosim/monitor_checks.motion_verdict) gives the page's
    kind, colour and detail: a PMSM motion the monitor called ``diagnosed`` (demagnetisation) was shown as a grey
    "diagnosed" badge without its fault, the colour of a motion not judged."""
    from feeddrive.cosim.monitor_checks import motion_verdict as monitor_word
    from feeddrive.cosim.report.verdict import UNEXPLAINED
    from feeddrive.estimator.diagnosis import UNEXPLAINED as ESTIMATOR_UNEXPLAINED

    assert UNEXPLAINED == ESTIMATOR_UNEXPLAINED
    m = motion(**changes)
    m["verdict"] = monitor_word(m, mismatch=False)
    v = motion_verdict(m)
    assert (v["kind"], v["text"]) == (kind, text)
    assert v["css"] == {"diagnosis": "diagnosed", "drifting": "drifting", "healthy": "healthy",
                        "sensor fault": "bad", "not validated": "not-judged"}[kind]


def test_a_mismatch_the_residue_check_decided_says_its_p_value_and_reason():
    """Without a redundant pair the motion's own residue check decides (estimator/adequacy.py); its mismatch was
    shown as a bare "model mismatch", with neither p-value nor the equation that failed."""
    adequacy = {"verdict": "model mismatch", "p_value": 2.1e-7, "alpha": 0.01,
                "reason": "the mechanical equation lacks a term: position-dependent torque (gravity) P1"}
    m = motion(mismatch=None, adequacy=adequacy, validated=False, verdict="model mismatch")
    assert motion_verdict(m) == {
        "kind": "model mismatch", "css": "bad",
        "text": "model mismatch: the residue check rejects, adjusted p = 2.1e-07 < alpha = 0.01: the mechanical "
                "equation lacks a term: position-dependent torque (gravity) P1; parameters not validated"}
    # an adequate residue check does not make a mismatch
    assert motion_verdict(motion(mismatch=None, adequacy=adequacy | {"verdict": "adequate"}))["kind"] == "healthy"


def test_a_torque_pairs_fault_has_its_unit():
    """The torque / torque_ref pair (cosim monitor --map torque_ref=...): its offset was printed without a unit."""
    fault = {"sensor": "torque or torque_ref", "kind": "gain", "gain": 0.8226, "offset": 0.00836}
    assert motion_verdict(motion(sensor_faults=[fault]))["text"].startswith(
        "sensor fault: torque or torque_ref gain 0.8226, offset 0.00836 N.m")
