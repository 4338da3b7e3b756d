"""A quantity recorded with the opposite sign convention (estimator.sign_convention).

Records from the model's equations (tests/estimator/synthetic.py), 1 kHz, 40 dB: with one quantity negated
the estimate is physically impossible and flagged; the hint names that quantity, and the values it quotes
(the least squares fit with it negated back) are the truth within 5 %. A record whose flags no sign explains
(a friction that drives the axis) gets no hint.
"""
from __future__ import annotations

import pytest
from synthetic import ROUND_TRIP, TRUTH, record

from feeddrive.estimator import EstimationOptions, MotionData
from feeddrive.estimator.partial import estimate_parameters

H = 1e-3
D = record(ROUND_TRIP, H, snr_db=40, seed=3)


def quoted(hint: str) -> dict[str, float]:
    inside = hint.split("physically possible (")[1].split(")")[0]
    return {k: float(v) for k, v in (item.split() for item in inside.split(", "))}


@pytest.mark.parametrize(("negated", "quantity", "flagged"), [
    ("i", "current", {"R", "L", "Jt", "ft", "Cd"}),
    ("w", "speed", {"K"}),
    ("u", "voltage", {"R", "L", "K", "Jt", "ft", "Cd"}),
])
def test_a_reversed_quantity_is_named_and_the_flags_stand(negated, quantity, flagged):
    signals = {k: (-D[k] if k == negated else D[k]) for k in ("u", "i", "w")}
    est = estimate_parameters(MotionData(H, **signals), EstimationOptions(method="iv"))
    assert set(est.flags) == flagged  # the estimate is not changed: flagged, never validated
    assert est.hint.startswith(f"the {quantity}'s sign is the opposite of the model's convention")
    values = quoted(est.hint)
    assert set(values) == {"R", "L", "K", "Jt", "ft", "Cd"}
    for name, v in values.items():
        assert v == pytest.approx(TRUTH[name], rel=0.05), name
    assert est.to_dict()["hint"] == est.hint
    assert est.bounded == {}  # a bounded fit of reversed data would sit on its bounds (Jt 5e-18): not offered


def test_a_torque_against_the_speed_names_both_and_healthy_data_get_no_hint():
    torque = TRUTH["K"] * D["i"]
    est = estimate_parameters(MotionData(H, w=D["w"], torque=-torque), EstimationOptions(method="iv"))
    assert set(est.flags) == {"Jt", "ft", "Cd"}
    assert est.hint.startswith("the speed and the torque have opposite sign conventions")
    assert quoted(est.hint)["Jt"] == pytest.approx(TRUTH["Jt"], rel=0.05)
    fine = estimate_parameters(MotionData(H, w=D["w"], torque=torque), EstimationOptions(method="iv"))
    assert not fine.flags and fine.hint is None and "hint" not in fine.to_dict()


def test_flags_no_sign_explains_get_no_hint():
    # a dry friction that drives the axis (Cd < 0) with the others as they are: negating the current, the voltage
    # or the speed turns other parameters negative, so no single sign is the cause
    d = record(ROUND_TRIP, H, params={"Cd": -1.2}, snr_db=40, seed=4)
    est = estimate_parameters(MotionData(H, u=d["u"], i=d["i"], w=d["w"]), EstimationOptions(method="iv"))
    assert set(est.flags) == {"Cd"}
    assert est.hint is None


def test_a_current_without_voltage_says_what_to_state():
    """Not a sign, the same kind of help: without a voltage K is not estimated, and the refusal says what to give."""
    from feeddrive.estimator.errors import NotEnoughExcitation

    # a missing signal, not the motion's excitation: the message does not say "not enough excitation"
    with pytest.raises(NotEnoughExcitation, match=r"^cannot identify Jt, ft, Cd: mechanical equation is scaled by K, "
                                                  r"which is refused \(no voltage signal: map the "
                                                  r"voltage or state K \(--known K=VALUE, monitor.known\)\)"):
        estimate_parameters(MotionData(H, i=D["i"], w=D["w"]), EstimationOptions(method="iv"))
    est = estimate_parameters(MotionData(H, i=D["i"], w=D["w"]), EstimationOptions(method="iv", known={"K": TRUTH["K"]}))
    assert est.parameters["Jt"].value == pytest.approx(TRUTH["Jt"], rel=0.05)


def test_the_same_code_names_a_pmsm_current_measured_the_other_way():
    """Model-generic: a PMSM's dq currents negated together (a current chain counting the other way)."""
    from pmsm_data import H as HP
    from pmsm_data import add_noise, closed_loop

    from feeddrive.models.drives import drive_model

    d = add_noise(closed_loop(), 40, 0)
    sig = {k: (-d[k] if k in ("i_d", "i_q") else d[k]) for k in ("u_d", "u_q", "i_d", "i_q")}
    est = estimate_parameters(MotionData(HP, w=d["w"], signals=sig),
                              EstimationOptions(method="ls", model="pmsm", known={"p": 4}))
    assert set(est.flags) == {"R", "L_d", "L_q", "Jt", "ft", "Cd"}
    assert est.hint.startswith("the current's sign is the opposite of the model's convention")
    truth = drive_model("pmsm").nominal(("physical",))
    for name, v in quoted(est.hint).items():
        assert v == pytest.approx(truth[name], rel=0.05), name


def test_a_torque_offset_is_quoted_with_the_sign_each_negation_gives():
    """With a torque offset T0, negating the speed or the torque gives the same Jt, ft, Cd but T0 of opposite
    signs; the hint quoted whichever negation came first (the speed's: -0.3 N.m for a true +0.3), so its T0
    depended on the order of the signals. It now says both, each with its negation."""
    t0 = 0.3
    torque = TRUTH["K"] * D["i"] + t0
    est = estimate_parameters(MotionData(H, w=D["w"], torque=-torque), EstimationOptions(method="iv", offset=True))
    assert {"Jt", "ft", "Cd"} <= set(est.flags)
    assert est.hint.startswith("the speed and the torque have opposite sign conventions")
    inside = est.hint.split("physically possible (")[1].split("); map")[0]
    common, offset = inside.split("; ")
    values = {k: float(v) for k, v in (item.split() for item in common.split(", "))}
    assert set(values) == {"Jt", "ft", "Cd"}
    assert values["Jt"] == pytest.approx(TRUTH["Jt"], rel=0.05)
    words = offset.split()  # T0 <with the speed negated> , <with the torque negated>
    assert words[0] == "T0" and words[2:6] == ["with", "the", "speed", "negated,"] and words[-3:] == ["with", "the", "torque"]
    assert float(words[1]) == pytest.approx(-t0, rel=0.1) and float(words[6]) == pytest.approx(t0, rel=0.1)
