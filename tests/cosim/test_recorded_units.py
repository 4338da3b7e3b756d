"""Units of recorded columns as users write them (audit 2): a percentage of a rated value is never taken on
trust, scaled or not."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from feeddrive.cosim.errors import DataError
from feeddrive.cosim.recorded import load_recording


@pytest.fixture
def percent_csv(tmp_path: Path) -> tuple[Path, np.ndarray]:
    """A drive's trace with its torque in % of a 0.5 N.m rating, as servo drives log it."""
    t = np.arange(200) * 1e-3
    torque = 0.5 * np.sin(2 * np.pi * 5 * t)  # N.m
    path = tmp_path / "drive.csv"
    np.savetxt(path, np.column_stack([t, 10 * np.cos(2 * np.pi * 5 * t), torque / 0.5 * 100]), delimiter=",",
               header="t [s],w [rad/s],T [%]", comments="", fmt="%.10g")
    return path, torque


def test_a_scaled_percentage_must_state_the_unit_of_the_scaled_values(percent_csv) -> None:
    """``torque=T*0.005`` on ``T [%]`` was taken with no unit ("'T [%]' states no unit ... taken as N.m"): the
    header does state one, and the scale converts it into another the map never named. Refused, naming the
    column and the fix, like a gear's scale on a m/s column; with the unit stated the values are the torque."""
    path, torque = percent_csv
    with pytest.raises(DataError, match=r"column 'T \[%\]' \(role torque\): the header says \[%\], not a unit of "
                                         r"torque.*--map 'torque=T\*0\.005 \[UNIT\]', e\.g\. \[N\.m\]"):
        load_recording(path, {"time": "t", "speed": "w", "torque": "T*0.005"})
    rec = load_recording(path, {"time": "t", "speed": "w", "torque": "T*0.005 [N.m]"})
    assert rec.units["torque"] == "N*m" and not rec.notes
    np.testing.assert_allclose(rec.signals["torque"], torque, rtol=1e-9, atol=1e-12)


def test_an_unscaled_percentage_is_refused_with_the_scale_it_needs(percent_csv) -> None:
    path, _ = percent_csv
    with pytest.raises(DataError, match=r"unit '%' is not a unit of role torque .*a fraction of a rated value needs "
                                         r"its scale: --map 'torque=COLUMN\*SCALE \[N\.m\]'"):
        load_recording(path, {"time": "t", "speed": "w", "torque": "T"})


def test_a_current_or_voltage_with_no_unit_anywhere_is_said_taken_as_a_or_v(tmp_path: Path) -> None:
    """The Quanser motor's current mapped as ``data[:,3]*1000`` (mA, no unit) gave R = 0.0095 Ohm, 1000 times the
    manual's 8.4 Ohm too small and physically possible, with not a word; only a position, speed or torque
    without a unit was said. Now every unit taken as SI is said; one stated is converted and not said."""
    path = tmp_path / "bench.csv"
    t = np.arange(20) * 1e-3
    np.savetxt(path, np.column_stack([t, 1 + t, 1e3 * (0.1 + t), t]), delimiter=",", header="t [s],u,i,w [rad/s]",
               comments="", fmt="%.10g")
    from feeddrive.cosim.recorded import assumed_units

    rec = load_recording(path, {"time": "t", "voltage": "u", "current1": "i", "speed": "w"})
    assert assumed_units(rec) == (
        "voltage: 'u' states no unit (not in the header, not in the map): taken as V; state it: "
        "--map 'voltage=u*SCALE [UNIT]' (e.g. mV)",
        "current1: 'i' states no unit (not in the header, not in the map): taken as A; state it: "
        "--map 'current1=i*SCALE [UNIT]' (e.g. mA)")
    rec = load_recording(path, {"time": "t", "voltage": "u [V]", "current1": "i [mA]", "speed": "w"})
    assert assumed_units(rec) == ()
    np.testing.assert_allclose(rec.signals["current1"], 0.1 + t, rtol=1e-12)


def test_a_name_that_fits_two_columns_is_refused_naming_both(tmp_path: Path) -> None:
    """A pandas copy of the current in mA beside the current in A (``I [A]``, ``I [mA]``): ``current1=I`` took the
    first one silently, whichever it was. Refused, naming both; each is taken when named whole."""
    path = tmp_path / "two.csv"
    t = np.arange(20) * 1e-3
    np.savetxt(path, np.column_stack([t, 0.1 + t, 1e3 * (0.1 + t)]), delimiter=",", header="t [s],I [A],I [mA]",
               comments="", fmt="%.10g")
    with pytest.raises(DataError, match=r"column 'I' \(role current1\) names 2 columns, 'I \[A\]', 'I \[mA\]'; "
                                         r"expected one: name it whole, e.g. --map 'current1=I \[A\]'"):
        load_recording(path, {"time": "t", "current1": "I"})
    for name in ("I [A]", "I [mA]", "I [mA]*0.001 [A]"):
        rec = load_recording(path, {"time": "t", "current1": name})
        np.testing.assert_allclose(rec.signals["current1"], 0.1 + t, rtol=1e-12, err_msg=name)


def test_a_pattern_or_a_folder_where_one_recording_is_expected_says_so(tmp_path: Path) -> None:
    """``cosim monitor 'run*.csv'`` said "run*.csv: no such file" while three files matched: the pattern is
    cosim estimate's; the monitor takes its recordings one at a time."""
    for k in range(3):
        (tmp_path / f"run{k}.csv").write_text("t [s],w [rad/s],T [N.m]\n0,0,0\n", encoding="utf-8")
    with pytest.raises(DataError, match=r"run\*\.csv: a file pattern \(3 files: .*run0\.csv, .*\); expected one "
                                         r"recording here: give each in turn, oldest first"):
        load_recording(tmp_path / "run*.csv", {"time": "t", "speed": "w"})
    with pytest.raises(DataError, match=r": is a folder; expected a recording file"):
        load_recording(tmp_path, {"time": "t", "speed": "w"})
