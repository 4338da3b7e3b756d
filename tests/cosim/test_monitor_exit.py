"""``cosim monitor``'s exit status says whether anything was judged, and an axis at rest says so with its threshold.

It exited 0 when every motion was refused or none was found, and a user's script took that for a verdict; a
recording at rest was cut into motions of its sensor's noise, each "not estimated: every parameter refused".
Now: 0 when at least one motion is judged, ``NOTHING_JUDGED`` (3) with a last line saying why otherwise.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from feeddrive.cosim.cli import main as cosim
from feeddrive.cosim.cli.monitor import NOTHING_JUDGED, nothing_judged
from feeddrive.cosim.monitor import MonitorConfig, MonitorPipeline
from feeddrive.estimator.history import History
from feeddrive.estimator.segmentation import REST_SNR, at_rest, speed_noise

H = 1e-3
NOISE = 0.002  # rad/s rms of the speed at rest


def at_rest_csv(path, n=2000, seed=0):
    """u, i, w of an axis at rest: white noise only (0.01 V, 0.005 A, NOISE rad/s rms)."""
    rng = np.random.default_rng(seed)
    cols = np.column_stack([np.arange(n) * H, 0.01 * rng.standard_normal(n), 0.005 * rng.standard_normal(n),
                            NOISE * rng.standard_normal(n)])
    np.savetxt(path, cols, delimiter=",", header="t [s],u [V],i [A],w [rad/s]", comments="")
    return path


def monitor(capsys, *args):
    code = cosim(["monitor", *map(str, args), "--db", ":memory:"])
    out, err = capsys.readouterr()
    return code, out, err


def test_the_speed_noise_is_read_from_second_differences_and_a_ramp_does_not_raise_it():
    rng = np.random.default_rng(1)
    noise = NOISE * rng.standard_normal(20000)
    assert speed_noise(noise) == pytest.approx(NOISE, rel=0.03)
    ramp = np.concatenate([np.linspace(0, 70, 5000), np.full(10000, 70.0), np.linspace(70, 0, 5000)])
    assert speed_noise(ramp + noise) == pytest.approx(NOISE, rel=0.03)  # the ramp's corners are 4 samples of 20000
    assert at_rest(ramp + noise) is None
    why = at_rest(noise)
    assert why.startswith("no high-speed motion: nothing to judge (largest |speed| ")
    assert f"not above {REST_SNR * speed_noise(noise):.3g} rad/s: {REST_SNR:g} x the speed's noise" in why
    assert at_rest(np.zeros(100)) == "no high-speed motion: nothing to judge (the speed is 0 on all 100 samples)"
    assert at_rest(np.full(100, 0.5), threshold=1.0).endswith("speed_threshold)")


def test_a_recording_at_rest_is_nothing_judged_with_the_threshold_exit_3(tmp_path, capsys):
    data = at_rest_csv(tmp_path / "rest.csv")
    code, out, err = monitor(capsys, data, "--map", "time=t", "voltage=u", "current1=i", "speed=w",
                             "--out", tmp_path / "out", "--no-plots")
    assert code == NOTHING_JUDGED == 3 and not err
    last = out.strip().splitlines()[-1]
    assert last.startswith("nothing judged: no high-speed motion: nothing to judge (largest |speed| "), last
    assert "x the speed's noise" in last and "Traceback" not in out
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["motions"] == [] and report["nothing_judged"] == last
    # the page says it at the top, where "No high-speed motion was processed" gave no reason
    import html

    page = html.unescape((tmp_path / "out" / "report.html").read_text())
    assert f'<p class="error" id="nothing-judged">{last}</p>' in page and "No high-speed motion was processed" not in page
    # the whole record taken as one motion (--segment none): the motion says it, with --json on stdout
    code, out, err = monitor(capsys, data, "--map", "time=t", "voltage=u", "current1=i", "speed=w", "--segment",
                             "none", "--json")
    assert code == NOTHING_JUDGED
    (m,) = json.loads(out)["motions"]
    assert m["verdict"].startswith("not estimated: no high-speed motion: nothing to judge") and not m["parameters"]
    assert err.strip().startswith("nothing judged: motion 1: no high-speed motion")


def test_every_motion_refused_is_nothing_judged_with_each_reason(tmp_path, capsys):
    """A 0.5 s motion under min_motion_s = 1 s: exit 3 and the reason, not exit 0."""
    rng = np.random.default_rng(2)
    t = np.arange(500) * H
    w = 50 * np.sin(np.pi * t / t[-1]) + 0.01 * rng.standard_normal(t.size)
    path = tmp_path / "short.csv"
    np.savetxt(path, np.column_stack([t, 0.1 * w, 0.5 * np.cos(np.pi * t / t[-1]), w]), delimiter=",",
               header="t [s],u [V],i [A],w [rad/s]", comments="")
    code, out, _ = monitor(capsys, path, "--map", "time=t", "voltage=u", "current1=i", "speed=w", "--segment", "none")
    assert code == NOTHING_JUDGED
    assert out.strip().splitlines()[-1] == ("nothing judged: motion 1: motion of 0.499 s is shorter than min_motion_s "
                                            "= 1.0 s (a scenario's monitor.min_motion_s, cosim monitor's --min-motion)")


def test_a_motion_with_a_verdict_is_judged_even_without_parameters():
    refused = {"motion": 1, "error": "motion too short", "parameters": {}, "sensor_faults": []}
    fault = {"motion": 2, "error": "every parameter refused", "parameters": {}, "measurements_valid": False,
             "sensor_faults": [{"sensor": "Im1", "kind": "gain", "gain": 1.1, "offset": 0.0}]}
    assert nothing_judged([refused, fault]) == ""  # a sensor fault is a verdict
    assert nothing_judged([refused, dict(refused, motion=2)]) == (
        "nothing judged: none of the 2 motions could be estimated (motions 1, 2: motion too short)")


def test_the_pipeline_says_a_plant_held_still_has_no_motion():
    """The co-simulation's monitor on a motion whose plant did not move (NC state 1, speed at the sensors' noise)."""
    rng = np.random.default_rng(3)
    n = 3000
    signals = {"Im1": 0.01 * rng.standard_normal(n), "Im2": 0.01 * rng.standard_normal(n),
               "u": 0.05 * rng.standard_normal(n), "u_ref": 0.05 * rng.standard_normal(n),
               "w_tach": NOISE * rng.standard_normal(n), "w_enc": NOISE * rng.standard_normal(n)}
    with History(":memory:") as history:
        result = MonitorPipeline(MonitorConfig(), history, "X").process(signals, H, 0.0, 1, 0.0).result
    assert result["error"].startswith("no high-speed motion: nothing to judge (largest |speed| ")
    assert result["verdict"] == f"not estimated: {result['error']}" and not result["parameters"]


def test_cosim_estimate_on_a_recording_at_rest_says_why_in_one_line(tmp_path, capsys):
    """``cosim estimate`` keeps its documented exit 2 when no motion is found, now with the numbers."""
    data = at_rest_csv(tmp_path / "rest.csv")
    code = cosim(["estimate", str(data), "--map", "time=t", "voltage=u", "current=i", "speed=w"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.count("\n") == 0, err
    assert err.startswith(f"cosim estimate: error: {data}: no high-speed motion: nothing to judge (largest |speed| ")
    code = cosim(["estimate", str(data), "--map", "time=t", "voltage=u", "current=i", "speed=w", "--segment", "nc"])
    err = capsys.readouterr().err.strip()  # it said "segmentation 'nc' needs an NC state signal (role 'state')"
    assert code == 2 and err == ("cosim estimate: error: --segment nc: the NC state is not mapped; expected --map "
                                 "state=COLUMN (1 = rapid), or --segment auto (the speed profile) or none (the whole "
                                 "recording)")


def test_cosim_estimate_with_every_parameter_refused_exits_3_saying_so(tmp_path, capsys):
    """The whole record at rest as one motion (--segment none): each parameter refused with its reason, then the
    last line; it exited 0 like a result."""
    data = at_rest_csv(tmp_path / "rest.csv")
    code = cosim(["estimate", str(data), "--map", "time=t", "voltage=u", "current=i", "speed=w", "--segment", "none"])
    out = capsys.readouterr().out.strip().splitlines()
    assert code == 3 and "  Jt  refused: " in "\n".join(out)
    assert out[-1] == "nothing estimated: every parameter of the motion refused, each with its reason (above)"
