"""The servo sensors' sampling modes (cosim/sensors_servo.py), as the DC sensors': on an oversampled plant each
analogue channel is an instantaneous sample, the interval mean of the plant's sub-samples or a low-pass filter's
output; checked against the analytic interval means of known signals."""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.scenario import scenario_from_dict
from feeddrive.cosim.sensors_servo import OUTPUTS, ServoSensors

M, H = 10, 1.0e-4  # sub-samples per recorded sample, recording step [s]
HF = H / M
P, W, IQ = 4, 150.0, 5.0  # pole pairs, motor speed [rad/s], q current [A]: 95.5 Hz electrical
F_U, A_U = 400.0, 20.0  # u_q_ref = A_U sin(2 pi F_U t) [V]
QUIET = {"noise": 0.0}


def true_inputs(t: float) -> list[float]:
    """``INPUTS`` at time t: i_d = 0, i_q = IQ, theta = W t, u_q_ref a 400 Hz sine, the rest 0."""
    return [0.0, IQ, W * t, 0.0, A_U * math.sin(2 * math.pi * F_U * t), 0.0, 0.0, 0.0]


def run(config: dict, samples: int) -> list[list[float]]:
    """The component stepped as the master steps it (every plant step when ``fine_rate``, reading the plant's
    outputs at the step's end); its outputs after each recording step."""
    comp = ServoSensors("servo", config)
    ticks = M if comp.fine_rate else 1
    comp.setup(0.0, H / ticks, samples * ticks)
    out = []
    for n in range(samples * ticks):
        comp.set_inputs(true_inputs((n + 1) * H / ticks))
        comp.step(n)
        if (n + 1) % ticks == 0:
            out.append(list(comp.get_outputs()))
    return out


def test_interval_means_are_the_analytic_means_and_instants_the_instantaneous_values():
    """Phase U's current is ``-IQ sin(p W t)``, u_q_ref ``A sin(2 pi f t)``: with ``sampling: mean`` each sample
    is their exact mean over the recording interval (within 1e-6 of the amplitude; the instantaneous value differs
    by up to 7 % of it), with ``instant`` the value at the interval's end (1e-12)."""
    quiet = {"phases": [QUIET] * 3, "second": QUIET, "voltage": QUIET, "voltage_ref": QUIET,
             "pole_pairs": P, "oversample": M}
    mean = np.array(run(quiet, 40))
    inst_cfg = quiet | {k: [QUIET | {"sampling": "instant"}] * 3 if k == "phases" else QUIET | {"sampling": "instant"}
                        for k in ("phases", "second", "voltage", "voltage_ref")}
    assert not ServoSensors("servo", inst_cfg).fine_rate
    inst = np.array(run(inst_cfg, 40))
    a = H * np.arange(40)
    b = a + H
    we = P * W
    i_u_mean = IQ * (np.cos(we * b) - np.cos(we * a)) / (we * H)
    u_mean = A_U * (np.cos(2 * math.pi * F_U * a) - np.cos(2 * math.pi * F_U * b)) / (2 * math.pi * F_U * H)
    col = {name: k for k, name in enumerate(OUTPUTS)}
    assert np.max(np.abs(mean[:, col["I_U"]] - i_u_mean)) < 1e-6 * IQ
    assert np.max(np.abs(mean[:, col["u_q_ref"]] - u_mean)) < 1e-6 * A_U
    assert np.max(np.abs(inst[:, col["I_U"]] + IQ * np.sin(we * b))) < 1e-12 * IQ
    assert np.max(np.abs(inst[:, col["u_q_ref"]] - A_U * np.sin(2 * math.pi * F_U * b))) < 1e-12 * A_U
    assert np.max(np.abs(inst[:, col["u_q_ref"]] - u_mean)) > 0.07 * A_U  # the modes differ: the test can tell
    # the means of the three phases still sum to zero, and the second sensor on U is U's mean
    assert np.max(np.abs(mean[:, :3].sum(axis=1))) < 1e-9
    assert np.max(np.abs(mean[:, col["I_2"]] - mean[:, col["I_U"]])) < 1e-12
    # the encoder is latched at the recording instant in both modes
    assert np.array_equal(mean[:, col["theta_enc"]], inst[:, col["theta_enc"]])


def test_a_lowpass_channel_passes_a_constant_and_attenuates_above_its_cutoff():
    """``sampling: lowpass`` (2nd-order Butterworth at 1 kHz, run at the plant's step): the q current's phase
    currents at 95 Hz electrical pass with gain 0.99 or more; the 400 Hz u_q_ref, with its cut-off at 100 Hz, to
    about 1 / (1 + (f / fc)^4)^0.5 = 0.06."""
    lp = QUIET | {"sampling": "lowpass", "cutoff_hz": 1000.0}
    cfg = {"phases": [lp] * 3, "second": QUIET, "voltage": QUIET, "pole_pairs": P, "oversample": M,
           "voltage_ref": QUIET | {"sampling": "lowpass", "cutoff_hz": 100.0}}
    out = np.array(run(cfg, 400))[200:]  # settled
    col = {name: k for k, name in enumerate(OUTPUTS)}
    assert 0.99 * IQ < np.max(np.abs(out[:, col["I_U"]])) < 1.01 * IQ
    assert np.max(np.abs(out[:, col["u_q_ref"]])) == pytest.approx(A_U / math.sqrt(1 + (F_U / 100.0) ** 4), rel=0.1)


def test_the_scenario_hands_the_plants_oversampling_to_the_servo_sensors(tmp_path):
    """examples/pmsm_axis.yaml at plant.oversample 5: the servo sensors get oversample 5 and, by default, sample
    interval means at the plant's rate (the master steps them every plant step); a contradicting oversample in the
    servo's config is one line naming the key."""
    from pathlib import Path

    from feeddrive.cosim.master import Master

    examples = Path(__file__).resolve().parents[2] / "examples"
    data = yaml.safe_load((examples / "pmsm_axis.yaml").read_text())
    data["plant"]["oversample"] = 5
    data["stop_time"] = 0.01
    s = scenario_from_dict(data, base_dir=examples)
    (servo,) = [c for c in s.components if c.name == "servo"]
    assert servo.config["oversample"] == 5
    m = Master.from_scenario(s)
    try:
        assert m.rates["servo"] == 1 and m.components["servo"].fine_rate
    finally:
        m.terminate()
    data["components"] = [{"name": "servo", "class": "feeddrive.cosim.sensors_servo:ServoSensors",
                           "config": {"oversample": 2}, "inputs": {}}]
    with pytest.raises(ScenarioError, match=r"components\[0\]\.config\.oversample: 2 contradicts plant.oversample = 5"):
        scenario_from_dict(data, base_dir=examples)
