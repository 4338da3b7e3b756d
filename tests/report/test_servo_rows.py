"""The servo drive's redundancy checks of a PMSM motion on report.html: one row per check, a fault in red."""
from __future__ import annotations

from feeddrive.cosim.report import views

HEALTHY = {
    "phase_current_sum": {"faulty": False, "phase": None, "offset": 0.0011, "offset_ci95": [-0.0002, 0.0024]},
    "phase_sensor_pair": {"gain_ratio": 1.00017, "valid": True},
    "dq_current_consistency": {"gain": 0.99976, "gain_ci95": [0.99936, 1.00017], "faulty": False},
    "voltage_reference_check": {"u_loss": 4.777, "u_loss_ci95": [4.70, 4.85], "valid": True},
    "lost_motion": {"value_mm": 0.01995, "ci95_mm": [0.0199, 0.0200], "detected": True},
}


def test_each_check_is_a_row_with_its_interval_and_decision():
    rows = views.servo_rows({"servo_checks": HEALTHY})
    assert [r["check"] for r in rows] == ["phase currents", "second sensor on phase U",
                                         "i_q against Park(I_U, I_V, I_W)",
                                         "voltage references against terminal voltages",
                                         "motor encoder against linear scale"]
    by = {r["check"]: r for r in rows}
    assert by["i_q against Park(I_U, I_V, I_W)"]["figure"] == "gain 0.9998 [0.9994, 1]"
    assert by["voltage references against terminal voltages"]["figure"] == "dead-time loss 4.777 [4.7, 4.85] V per leg"
    assert by["motor encoder against linear scale"]["bad"] and by["motor encoder against linear scale"]["decision"] == \
        "lost motion detected"
    assert not any(r["bad"] for r in rows[:4])
    # the second sensor's phase as the check states it (report.json phase_sensor_pair.phase)
    on_v = HEALTHY | {"phase_sensor_pair": {"phase": "V", "gain_ratio": 1.0, "valid": True}}
    assert views.servo_rows({"servo_checks": on_v})[1]["what"].startswith("I_V against I_2")


def test_a_faulty_phase_is_named_and_nothing_is_nan():
    checks = HEALTHY | {"phase_current_sum": {"faulty": True, "phase": "V", "offset": float("nan")},
                        "dq_current_consistency": {"gain": 0.7071, "gain_ci95": [0.7068, 0.7074], "faulty": True}}
    rows = {r["check"]: r for r in views.servo_rows({"servo_checks": checks})}
    assert rows["phase currents"]["bad"] and rows["phase currents"]["decision"] == "fault on phase V"
    assert rows["phase currents"]["figure"] == "offset not computed"
    assert rows["i_q against Park(I_U, I_V, I_W)"]["decision"] == "mis-scaled current"
    assert views.servo_rows({}) == [] and views.servo_rows({"servo_checks": None}) == []


def test_a_check_that_did_not_run_is_a_row_with_its_reason():
    """A recording without a q current or a voltage sensor: those checks are rows saying why, not judged."""
    checks = {k: HEALTHY[k] for k in ("phase_current_sum", "lost_motion")}
    why = {"dq_current_consistency": "not checked: the q current is the Park transform of the phase currents",
           "phase_sensor_pair": "not checked: no I_2", "current": "not checked: no Im2"}
    rows = views.servo_rows({"servo_checks": checks, "not_checked": why})
    assert [r["check"] for r in rows] == ["phase currents", "motor encoder against linear scale",
                                         "second sensor on one phase", "i_q against Park(I_U, I_V, I_W)"]
    assert rows[3]["skipped"] and not rows[3]["bad"] and rows[3]["decision"] == why["dq_current_consistency"]


def test_the_residue_check_is_a_table_of_its_equations_at_the_adjusted_level():
    adequacy = {"verdict": "model mismatch", "p_value": 3e-9, "alpha": 0.01, "reason": "mechanical: offset",
                "equations": {"electrical": {"output": "u", "p_value": 0.41, "statistic": 0.95, "df": [3, 40],
                                             "terms": ["offset (constant)"], "strongest": "offset (constant)"},
                              "mechanical": {"output": "i", "p_value": 1e-9, "statistic": 31.0, "df": [6, 37],
                                             "terms": ["offset (constant)"], "strongest": "offset (constant)"},
                              "other": {"output": "x", "p_value": float("nan"), "reason": "not determined: Jt"}}}
    view = views.residue_check({"adequacy": adequacy})
    assert view["bad"] and view["level"] == "alpha 0.01 / 3 equations = 0.00333 (Bonferroni)"
    rows = {r["equation"]: r for r in view["rows"]}
    assert rows["electrical (u)"]["decision"] == "pass" and rows["electrical (u)"]["df"] == "3, 40"
    assert rows["mechanical (i)"]["decision"] == "reject: mismatch" and rows["mechanical (i)"]["bad"]
    assert rows["other (x)"]["decision"] == "not determined: Jt" and rows["other (x)"]["p"] == "not computed"
    assert views.residue_check({}) is None


def test_a_significant_but_immaterial_lack_of_fit_is_not_a_red_reject_under_an_adequate_verdict():
    """report.html showed 'Residue check: adequate' above an electrical row 'reject: mismatch' (p 9e-35 on a
    lack of fit of 0.085 % of u): the verdict was right (immaterial below 1 %), the row said the opposite."""
    adequacy = {"verdict": "adequate", "p_value": 1.85e-34, "alpha": 0.01,
                "equations": {"electrical": {"output": "u", "p_value": 9.27e-35, "statistic": 60.0, "df": [3, 27],
                                             "terms": ["offset (constant)"], "effect": 0.00085},
                              "mechanical": {"output": "i", "p_value": 2.8e-26, "statistic": 40.0, "df": [6, 24],
                                             "terms": ["offset (constant)"], "effect": 0.02}}}
    rows = {r["equation"]: r for r in views.residue_check({"adequacy": adequacy})["rows"]}
    assert rows["electrical (u)"]["decision"] == ("significant but immaterial: 0.085 % of the u signal unexplained "
                                                  "(< 1 %)") and not rows["electrical (u)"]["bad"]
    assert rows["mechanical (i)"]["decision"] == "reject: mismatch" and rows["mechanical (i)"]["bad"]  # 2 %: material
