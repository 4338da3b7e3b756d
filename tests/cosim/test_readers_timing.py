"""Time stamps as loggers write them (dropped samples, jitter, no time column) and ``--pitch`` per column side.

A non-uniform record is refused with one line that names ``--resample`` and ``--split-gaps`` and the
measured gaps; ``--resample`` gives the undamaged record's estimates within their intervals; a gap over
MAXGAP is refused with its place; ``--split-gaps`` keeps the records apart. Nothing is resampled or split
without being asked, and what was done is said (stderr) and kept (JSON ``timing``).
"""
from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import readers_data as rd  # noqa: E402

from feeddrive.cosim.cli import main  # noqa: E402
from feeddrive.cosim.errors import DataError, InputError  # noqa: E402
from feeddrive.cosim.recorded import load_recording, motions, to_motor_side  # noqa: E402

MAP = ["--map", "time=time", "voltage=u", "current=i", "speed=w"]
#: samples dropped one by one (each leaves a 1 ms step in the 0.5 ms grid), spread over the record
DROPPED = np.arange(300, 7000, 167)


@pytest.fixture(scope="module")
def data() -> dict:
    return rd.record()


def damaged(d: dict, drop: np.ndarray) -> dict:
    keep = np.ones(len(d["t"]), bool)
    keep[drop] = False
    return {k: v[keep] for k, v in d.items()}


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_dropped_samples_are_refused_naming_both_options_and_the_gaps(data, tmp_path, capsys):
    path = rd.write_csv(tmp_path / "r.csv", damaged(data, DROPPED))
    code, out, err = run(capsys, "estimate", path, *MAP)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "is not uniformly sampled" in err and "--resample MAXGAP" in err and "--split-gaps" in err
    assert f"{len(DROPPED)} gaps (largest 0.001 s at t = " in err, err


def test_resampling_gives_the_undamaged_estimates_within_their_intervals(data, tmp_path, capsys):
    full = rd.write_csv(tmp_path / "full.csv", data)
    code, out, _ = run(capsys, "estimate", full, *MAP, "--json")
    assert code == 0
    ref = json.loads(out)
    assert ref["timing"]["gaps"] == 0 and ref["timing"]["action"] == "none"
    path = rd.write_csv(tmp_path / "r.csv", damaged(data, DROPPED))
    code, out, err = run(capsys, "estimate", path, *MAP, "--json", "--resample", "0.002")
    assert code == 0
    got = json.loads(out)
    assert got["timing"]["gaps"] == len(DROPPED) and got["timing"]["largest_gap_s"] == pytest.approx(1e-3)
    assert got["timing"]["action"].startswith("resampled onto the 0.0005 s grid by linear interpolation")
    assert "resampled onto the 0.0005 s grid" in err and f"{len(DROPPED)} gaps" in err  # said, not silent
    (seg_ref,), (seg,) = ref["segments"], got["segments"]
    for name, p in seg_ref["parameters"].items():
        lo, hi = p["ci95"]
        assert lo <= seg["parameters"][name]["value"] <= hi, name
    # the grid is the undamaged one: every kept sample is where it was, every dropped one interpolated
    rec = load_recording(path, {"time": "time", "speed": "w"}, resample=0.002)
    assert rec.n == len(data["t"]) and rec.h == pytest.approx(5e-4)
    kept = np.setdiff1d(np.arange(rec.n), DROPPED)
    np.testing.assert_allclose(rec.signals["speed"][kept], data["w"][kept], rtol=0, atol=1e-9)
    mid = 0.5 * (data["w"][DROPPED - 1] + data["w"][DROPPED + 1])
    np.testing.assert_allclose(rec.signals["speed"][DROPPED], mid, rtol=0, atol=1e-9)


def test_a_gap_over_maxgap_is_refused_with_its_place(data, tmp_path, capsys):
    drop = np.concatenate([DROPPED, np.arange(3500, 3510)])  # 11 samples in a row: a 5.5 ms gap
    path = rd.write_csv(tmp_path / "r.csv", damaged(data, drop))
    code, out, err = run(capsys, "estimate", path, *MAP, "--resample", "0.002")
    assert code == 2 and err.count("\n") == 1
    t = data["t"][3499]
    assert f"has a gap of 0.0055 s at t = {t:.6g} s" in err and "over --resample 0.002 s" in err, err
    assert "--split-gaps" in err


def test_split_gaps_keeps_the_records_apart(data, tmp_path, capsys):
    path = rd.write_csv(tmp_path / "r.csv", damaged(data, np.arange(3600, 3800)))  # 0.1 s lost mid-record
    rec = load_recording(path, {"time": "time", "speed": "w"}, split_gaps=True)
    assert rec.bounds() == [(0, 3600), (3600, len(data["t"]) - 200)]
    assert rec.time(3599) == pytest.approx(data["t"][3599]) and rec.time(3600) == pytest.approx(data["t"][3800])
    args = argparse.Namespace(segment="none")
    assert [(s.start, s.stop) for s in motions(args, rec, rec.signals["speed"], None)] == rec.bounds()
    assert rec.timing["action"] == "split at 1 gap into 2 records" and rec.timing["records"] == 2
    # the CLI: each record's motions are estimated on their own, with their own times
    code, out, err = run(capsys, "estimate", path, *MAP, "--split-gaps", "--segment", "none", "--json",
                         "--method", "ls")
    starts = [s["start"] for s in json.loads(out)["segments"]]
    assert code == 0 and starts == pytest.approx([0.0, data["t"][3800]], abs=1e-9)
    assert "split at 1 gap into 2 records" in err


def test_jitter_alone_is_refused_and_resampled_on_request(data, tmp_path, capsys):
    jittered = dict(data)
    rng = np.random.default_rng(3)
    jittered["t"] = data["t"] + rng.uniform(-0.03, 0.03, data["t"].size) * 5e-4  # +-3 % of the step
    path = rd.write_csv(tmp_path / "r.csv", jittered)
    with pytest.raises(DataError, match=r"not uniformly sampled \(7241 samples, median step .* jitter [56]\.\d+ %, "
                                         r"no gaps\)"):
        load_recording(path, {"time": "time", "speed": "w"})
    with pytest.raises(DataError, match=r"jitters by [56]\.\d+ % of its step .* add --resample MAXGAP"):
        load_recording(path, {"time": "time", "speed": "w"}, split_gaps=True)
    rec = load_recording(path, {"time": "time", "speed": "w"}, resample=1e-3)
    assert rec.h == pytest.approx(5e-4, rel=1e-3) and abs(rec.n - data["t"].size) <= 1


def test_without_a_time_column_the_rate_is_asked_for(data, tmp_path, capsys):
    path = tmp_path / "r.csv"
    np.savetxt(path, np.column_stack([data["u"], data["w"]]), delimiter=",", header="u [V],w [rad/s]",
               comments="", fmt="%.17g")
    code, _, err = run(capsys, "estimate", path, "--map", "voltage=u", "speed=w")
    assert code == 2 and err.count("\n") == 1
    assert "no time column (role time)" in err and "--rate HZ or --dt SECONDS" in err
    for option in (["--rate", "2000"], ["--dt", "0.0005"], ["--sample-time", "0.0005"]):
        parser = argparse.ArgumentParser()
        from feeddrive.cosim.cli.estimate import add_arguments

        add_arguments(parser)
        args = parser.parse_args([str(path), "--map", "voltage=u", "speed=w", *option])
        from feeddrive.cosim.recorded import read_recording

        rec = read_recording(args, {"voltage": "u", "speed": "w"})
        assert rec.h == pytest.approx(5e-4, rel=1e-12) and rec.n == data["t"].size
        assert rec.timing["source"] == "--rate/--dt"
    with pytest.raises(SystemExit) as exit_:  # one or the other
        main(["estimate", str(path), "--map", "voltage=u", "--rate", "10", "--dt", "0.1"])
    assert exit_.value.code == 2 and "not allowed with argument" in capsys.readouterr().err


# -- --pitch: table-side columns only (issue 23 item 1) ---------------------------------------------------


PITCH = 0.02  # m per screw turn


@pytest.fixture(scope="module")
def linear(data, tmp_path_factory) -> Path:
    """Motor speed [rad/s] from the tachometer and the table position [m] from a linear scale."""
    from plant_data import add_noise, closed_loop

    d = add_noise(closed_loop(), 40.0, seed=7)
    x = d["theta"][::rd.STEP] * PITCH / (2 * math.pi)
    path = tmp_path_factory.mktemp("lin") / "lin.csv"
    np.savetxt(path, np.column_stack([data["t"], data["u"], data["i"], data["w"], x]), delimiter=",",
               header="time [s],u [V],i [A],w [rad/s],x [m]", comments="", fmt="%.17g")
    return path


def test_pitch_scales_the_table_position_and_not_the_motor_speed(linear, data):
    rec = load_recording(linear, {"time": "time", "speed": "w", "position": "x"})
    motor = to_motor_side(rec, argparse.Namespace(pitch=PITCH, ratio=1.0))
    np.testing.assert_array_equal(motor.signals["speed"], data["w"])  # rad/s: motor side, untouched
    np.testing.assert_allclose(motor.signals["position"], rec.signals["position"] * 2 * math.pi / PITCH, rtol=1e-15)
    assert motor.side == "motor" and motor.units == {"speed": "rad/s", "position": "rad"}
    # the converted position differentiates to the speed column, not to 314 times it
    w_enc = np.gradient(motor.signals["position"], rec.h)
    gain = np.dot(w_enc, data["w"]) / np.dot(data["w"], data["w"])
    assert gain == pytest.approx(1.0, abs=0.01)


def test_mixed_sides_without_pitch_are_refused_naming_the_columns(linear):
    rec = load_recording(linear, {"time": "time", "speed": "w", "position": "x"})
    with pytest.raises(InputError, match=r"'x \[m\]' \(role position, m\) on the table side but 'w \[rad/s\]' "
                                         r"\(role speed, rad/s\) on the motor side; give --pitch"):
        to_motor_side(rec, argparse.Namespace(pitch=None, ratio=1.0))


def test_monitor_with_pitch_sees_no_false_tachometer_gain(linear, capsys):
    code, out, err = run(capsys, "monitor", linear, "--map", "time=time", "voltage=u", "current1=i", "speed=w",
                         "position=x", "--pitch", PITCH, "--db", ":memory:", "--json")
    assert code == 0, err
    report = json.loads(out)
    (motion,) = report["motions"]
    assert not [f for f in motion["sensor_faults"] if f["sensor"] in ("w_tach", "w_enc")], motion["sensor_faults"]
    assert report["time_source"].startswith(f"file modification time of {linear}")
    assert report["timing"]["rate_hz"] == pytest.approx(2000.0)


def test_monitor_dates_the_motions_from_start_time_and_says_so(linear, tmp_path, capsys):
    from feeddrive.estimator.history import History

    db = tmp_path / "h.sqlite"
    code, out, err = run(capsys, "monitor", linear, "--map", "time=time", "voltage=u", "current1=i", "speed=w",
                         "position=x", "--pitch", PITCH, "--db", db, "--start-time", "2026-03-01T10:00:00Z")
    assert code == 0, err
    assert out.startswith("time: --start-time 2026-03-01T10:00:00Z\n")
    start = dt.datetime(2026, 3, 1, 10, tzinfo=dt.timezone.utc).timestamp()
    with History(str(db)) as history:
        (motion,) = history.motions("X")
    assert motion["time"] == pytest.approx(start + motion["end"], abs=1e-6)  # the clock at the motion's end


def test_speed_from_position_is_differentiated_within_each_record(data, tmp_path):
    """No spike where a gap joins two records: d/dt stays within each record."""
    d = damaged(dict(data, w=np.cumsum(data["w"]) * 5e-4), np.arange(2000, 2200))  # at 70 rad/s: 7 rad lost
    path = rd.write_csv(tmp_path / "r.csv", d, header="time [s],u [V],i [A],theta [rad]")
    rec = load_recording(path, {"time": "time", "position": "theta"}, split_gaps=True)
    w = rec.gradient(rec.signals["position"])
    assert np.max(np.abs(w)) < 1.2 * np.max(np.abs(data["w"]))
    whole = np.gradient(rec.signals["position"], rec.h)  # across the gap: the 0.1 s of travel in one step
    assert np.max(np.abs(whole)) > 50 * np.max(np.abs(data["w"]))
