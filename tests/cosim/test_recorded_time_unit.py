"""A time column with no unit, checked against the data (audit 6): d(position)/dt must be the speed.

A DC-motor-like motion (4 s at 1 kHz, speed reversals; torque from the exact inverse dynamics plus noise, the
position the exact integral of the speed quantised by a 2^16-count encoder) written with its time in ms under a
bare ``t``: taken as seconds, Jt came out 1e6 times too large with exit 0 and a note. The position's derivative
is then 1e-3 x the speed, which only the ms explain: refused, naming the column, the gain and the fix.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from dc_motion import TRUTH, motor  # noqa: E402

from feeddrive.cosim.cli import main  # noqa: E402
from feeddrive.cosim.errors import DataError  # noqa: E402
from feeddrive.cosim.recorded import assumed_units, load_recording  # noqa: E402


def write(path: Path, d: dict[str, np.ndarray], time_scale: float, header: str) -> Path:
    np.savetxt(path, np.column_stack([d["t"] * time_scale, d["x"], d["w"], d["T"]]), delimiter=",", header=header,
               comments="", fmt="%.12g")
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    d, folder = motor(), tmp_path_factory.mktemp("time_unit")
    return {"ms": write(folder / "ms.csv", d, 1e3, "t,x [rad],w [rad/s],T [N.m]"),
            "s": write(folder / "s.csv", d, 1.0, "t,x [rad],w [rad/s],T [N.m]"),
            "bare": write(folder / "bare.csv", d, 1.0, "t,x,w,T [N.m]")}


MAP = ["--map", "position=x", "speed=w", "torque=T", "--segment", "none", "--method", "ls", "--json"]


def test_a_bare_time_in_ms_is_refused_naming_the_column_the_gain_and_the_fix(files, capsys) -> None:
    assert main(["estimate", str(files["ms"]), "--map", "time=t", *MAP]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err
    assert err.startswith(f"cosim estimate: error: {files['ms']}: column 't' states no unit and is taken as s, but "
                          "then the position's derivative is ")
    assert err.endswith(" x the speed: the time is in ms (--map 'time=t [ms]'); if the seconds are right (a gear "
                        "between the position and the speed), state them: --map 'time=t [s]'")
    gain = float(err.split("derivative is ")[1].split(" x ")[0])
    assert gain == pytest.approx(1e-3, rel=1e-3)  # as measured (noise, encoder counts): the ms, within 0.1 %
    assert main(["monitor", str(files["ms"]), "--map", "time=t", "position=x", "speed=w", "torque=T",
                 "--db", ":memory:", "--json"]) == 2  # the monitor reads through the same place
    assert "the time is in ms (--map 'time=t [ms]')" in capsys.readouterr().err


def test_a_bare_time_in_s_is_confirmed_by_the_data_in_the_note(files, capsys) -> None:
    assert main(["estimate", str(files["s"]), "--map", "time=t", *MAP]) == 0
    out, err = capsys.readouterr()
    (note,) = [n for n in json.loads(out)["unit_assumptions"] if n.startswith("time:")]
    assert note.startswith("time: 't' states no unit (not in the header, not in the map): taken as s: the position's "
                           "derivative matches the speed within ")
    assert float(note.split("within ")[1].split(" %")[0]) < 0.5 and note.endswith("--map 'time=t [s]'")
    assert note in err


def test_a_stated_ms_gives_the_parameters_of_the_time_in_s(files, capsys) -> None:
    def parameters(path: Path, time: str) -> dict[str, float]:
        assert main(["estimate", str(path), "--map", time, *MAP]) == 0
        out = json.loads(capsys.readouterr().out)
        assert not any(n.startswith("time:") for n in out.get("unit_assumptions", []))
        return {k: p["value"] for k, p in out["segments"][0]["parameters"].items()}

    in_ms, in_s = parameters(files["ms"], "time=t [ms]"), parameters(files["s"], "time=t [s]")
    assert in_ms == pytest.approx(in_s, rel=1e-6)
    assert in_s == pytest.approx(TRUTH, rel=0.03)


def test_a_bare_speed_in_rpm_is_the_speeds_unit_not_the_times(files) -> None:
    """With the speed's unit unstated too, a gain of 2 pi / 60 is a speed in rpm taken for rad/s (K and ft 9.55
    times off): the line says which unit, never the time's."""
    d = motor(n=1000)
    path = files["bare"].with_name("rpm.csv")
    np.savetxt(path, np.column_stack([d["t"], d["x"], d["w"] * 60 / (2 * math.pi), d["T"]]), delimiter=",",
               header="t,x [rad],w,T [N.m]", comments="", fmt="%.12g")
    rec = load_recording(path, {"time": "t", "position": "x", "speed": "w"})
    with pytest.raises(DataError, match=r"position's derivative is 0\.10\d+ x the speed: the speed is in rpm "
                                        r"\(--map 'speed=w \[rpm\]'\)$"):
        assumed_units(rec)


def test_without_a_speed_or_with_a_stated_time_nothing_is_checked(files) -> None:
    rec = load_recording(files["ms"], {"time": "t [ms]", "position": "x", "speed": "w"})
    assert assumed_units(rec) == ()  # stated: never second-guessed here
    (note,) = assumed_units(load_recording(files["ms"], {"time": "t", "position": "x"}))
    assert note.endswith("taken as s (a step of 1 s, 1 Hz); state it: --map 'time=t [UNIT]' (e.g. ms)")


def test_a_gain_no_unit_explains_is_added_to_the_note(files) -> None:
    """A gear of 2 between the encoder and the tachometer: no unit says 2, so the seconds stay assumed, with the
    gain measured (the monitor judges a sensor's gain; here the time's unit is the question)."""
    d = motor(n=1000)
    path = files["bare"].with_name("gear.csv")
    np.savetxt(path, np.column_stack([d["t"], 2 * d["x"], d["w"], d["T"]]), delimiter=",",
               header="t,x [rad],w [rad/s],T [N.m]", comments="", fmt="%.12g")
    (note,) = assumed_units(load_recording(path, {"time": "t", "position": "x", "speed": "w"}))
    assert note.startswith("time: 't' states no unit (not in the header, not in the map): taken as s (a step of ")
    gain = float(note.split("derivative is ")[1].split(" x ")[0])
    assert gain == pytest.approx(2.0, rel=2e-3)
    assert note.endswith("x the speed (no time unit explains it: a gear between the two, or a sensor's gain?)")


def test_with_the_time_stated_a_bare_speed_in_rpm_is_refused_and_units_that_agree_are_said(files) -> None:
    """The time's unit stated (or --rate), the speed's not: a speed in rpm was taken for rad/s (K and ft 9.55 times
    off) with only a note that it was taken so; the same d(position)/dt = speed check tells."""
    d = motor(n=1000)
    path = files["bare"].with_name("rpm-stated-time.csv")
    np.savetxt(path, np.column_stack([d["t"], d["x"], d["w"] * 60 / (2 * math.pi), d["T"]]), delimiter=",",
               header="t [s],x [rad],w,T [N.m]", comments="", fmt="%.12g")
    with pytest.raises(DataError, match=r": speed 'w' states no unit, and the position's derivative is 0\.10\d+ x the "
                                        r"speed: the speed is in rpm \(--map 'speed=w \[rpm\]'\)$"):
        assumed_units(load_recording(path, {"time": "t", "position": "x", "speed": "w"}))
    notes = assumed_units(load_recording(files["bare"], {"time": "t [s]", "position": "x", "speed": "w"}))
    assert notes[0].startswith("position 'x' and speed 'w': the units taken agree: the position's derivative "
                               "matches the speed within ")
    assert [n.split(":")[0] for n in notes[1:]] == ["position", "speed"]  # each still said taken as rad, rad/s
