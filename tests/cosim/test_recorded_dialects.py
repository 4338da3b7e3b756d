"""Recorded CSV files as people export them: separators, decimal comma, BOM, units in headers, bad numbers.

Every dialect is read back to the exact values written (a round trip); every bad number is one
``DataError`` line naming the file, the column and the row, and exit status 2 from the CLI.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pytest

from feeddrive.cosim.cli import main
from feeddrive.cosim.cli.estimate import ROLES
from feeddrive.cosim.errors import DataError, InputError
from feeddrive.cosim.recorded import (
    add_recording_arguments,
    assumed_units,
    load_recording,
    mapped_roles,
    to_motor_side,
)

N = 20
T = np.arange(N) * 1e-3
U = np.round(10 * np.sin(np.arange(N)), 6)


def write(path: Path, header: list[str], sep: str = ",", decimal: str = ".", bom: bool = False,
          column=None) -> Path:
    col = U if column is None else column
    rows = [sep.join(header)] + [sep.join(f"{v}".replace(".", decimal) for v in (t, u)) for t, u in zip(T, col)]
    path.write_text(("\ufeff" if bom else "") + "\n".join(rows) + "\n", encoding="utf-8")
    return path


@pytest.mark.parametrize(("sep", "decimal", "bom"), [
    (",", ".", False), (";", ",", False), ("\t", ".", False), ("\t", ",", True), (";", ".", True), (",", ".", True),
])
def test_each_dialect_is_detected_and_read_back_exactly(tmp_path, sep, decimal, bom):
    path = write(tmp_path / "d.csv", ["t [s]", "u [V]"], sep, decimal, bom)
    rec = load_recording(path, {"time": "t", "voltage": "u"})
    assert rec.h == pytest.approx(1e-3, rel=1e-9) and rec.columns == {"voltage": "u [V]"}
    np.testing.assert_array_equal(rec.signals["voltage"], U)


def test_delimiter_and_decimal_can_be_given(tmp_path):
    # given rather than detected; a wrong separator names the one used
    path = write(tmp_path / "d.csv", ["t [s]", "u [V]"], ";", ",")
    rec = load_recording(path, {"time": "t", "voltage": "u"}, delimiter=";", decimal=",")
    np.testing.assert_array_equal(rec.signals["voltage"], U)
    with pytest.raises(DataError, match=r"column 't' \(role time\) not found; columns are \['t \[s\];u \[V\]'\] \(separator ','"):
        load_recording(path, {"time": "t", "voltage": "u"}, delimiter=",")


@pytest.mark.parametrize(("unit", "role", "factor", "si"), [
    ("mm", "position", 1e-3, "m"), ("rpm", "speed", 2 * math.pi / 60, "rad/s"), ("mA", "current", 1e-3, "A"),
    ("deg", "position", math.pi / 180, "rad"), ("kN", "torque", 1e3, "N"), ("N.m", "torque", 1.0, "N*m"),
    ("mm/s", "speed", 1e-3, "m/s"), ("ms", "time", 1e-3, "s"),
])
def test_header_units_are_converted_to_si(tmp_path, unit, role, factor, si):
    path = write(tmp_path / "d.csv", ["t [s]" if role != "time" else "t [ms]", f"y [{unit}]"],
                 column=U if role != "time" else U)
    if role == "time":  # time in ms: 1e-3 "ms" steps are 1e-6 s
        rec = load_recording(write(tmp_path / "t.csv", ["t [ms]", "u [V]"]), {"time": "t", "voltage": "u"})
        assert rec.h == pytest.approx(1e-6, rel=1e-9)
        return
    rec = load_recording(path, {"time": "t", role: "y"})
    np.testing.assert_allclose(rec.signals[role], U * factor, rtol=1e-15)
    assert rec.units[role] == si


def test_a_scale_that_agrees_with_the_header_unit_keeps_it(tmp_path):
    path = write(tmp_path / "d.csv", ["t [s]", "x [mm]"])
    rec = load_recording(path, {"time": "t", "position": "x*0.0010002"})  # a rounded constant: within 1e-3
    np.testing.assert_allclose(rec.signals["position"], U * 0.0010002, rtol=1e-15)
    assert rec.units["position"] == "m" and rec.side == "table"


def test_a_scale_that_contradicts_the_header_unit_is_refused_naming_the_fix(tmp_path):
    """REGBOT's wheel speed [m/s] times gear/radius (325.9) is the motor's speed in rad/s: the header's unit no
    longer says it, and taking it on trust printed K in N/A (a linear axis) for a rotary motor."""
    path = write(tmp_path / "d.csv", ["t [s]", "v [m/s]"])
    with pytest.raises(DataError, match=r"column 'v \[m/s\]' \(role speed\): the header says \[m/s\] \(1 x to m/s\) "
                                        r"but the map's scale is 325\.9, .*state it: --map 'speed=v\*325\.9 \[UNIT\]'"):
        load_recording(path, {"time": "t", "speed": "v*325.9"})


@pytest.mark.parametrize("stated, side, factor", [("rad/s", "motor", 325.9), ("rpm", "motor", 325.9 * np.pi / 30),
                                                  ("mm/s", "table", 325.9e-3)])
def test_a_stated_unit_decides_the_scaled_values_unit_and_side(tmp_path, stated, side, factor):
    path = write(tmp_path / "d.csv", ["t [s]", "v [m/s]"])
    rec = load_recording(path, {"time": "t", "speed": f"v * 325.9 [{stated}]"})
    np.testing.assert_allclose(rec.signals["speed"], U * factor, rtol=1e-14)
    assert rec.side == side and rec.columns["speed"] == "v [m/s]"


def test_a_stated_unit_of_the_wrong_kind_or_empty_is_refused(tmp_path):
    path = write(tmp_path / "d.csv", ["t [s]", "v [m/s]"])
    with pytest.raises(DataError, match=r"stated unit \[A\]: unit 'A' is not a unit of role speed"):
        load_recording(path, {"time": "t", "speed": "v*2 [A]"})
    with pytest.raises(InputError, match=r"empty unit in \[ \]"):
        load_recording(path, {"time": "t", "speed": "v*2 []"})


def test_a_mechanical_column_with_no_unit_anywhere_is_said_taken_as_the_sides_unit(tmp_path):
    path = tmp_path / "d.csv"
    path.write_text("t [s],v,x [mm]\n" + "".join(f"{t},{u},{u}\n" for t, u in zip(T, U)), encoding="utf-8")
    alone = load_recording(path, {"time": "t", "speed": "v*0.001"})
    assert assumed_units(alone) == ("speed: 'v' states no unit (not in the header, not in the map): taken as rad/s "
                                    "(motor side); state it: --map 'speed=v*SCALE [UNIT]'",)
    beside = load_recording(path, {"time": "t", "speed": "v", "position": "x"})  # the position says: table side
    assert assumed_units(beside) == ("speed: 'v' states no unit (not in the header, not in the map): taken as m/s "
                                     "(table side); state it: --map 'speed=v*SCALE [UNIT]'",)
    assert assumed_units(load_recording(path, {"time": "t", "speed": "v*1 [rad/s]"})) == ()


def test_a_unit_of_the_wrong_kind_is_refused(tmp_path):
    path = write(tmp_path / "d.csv", ["t [s]", "x [kg]"])
    with pytest.raises(DataError, match=r"column 'x \[kg\]' \(role position\): unit 'kg' is not a unit of role "
                                        r"position \(expected one convertible to rad or m\)"):
        load_recording(path, {"time": "t", "position": "x"})


@pytest.mark.parametrize(("cell", "what"), [
    ("1e300", "out of range"), ("-1e300", "out of range"), ("1e400", "not a finite number"),
    ("inf", "not a finite number"), ("nan", "not a finite number"), ("-Infinity", "not a finite number"),
])
def test_bad_numbers_name_the_column_and_row(tmp_path, capsys, cell, what):
    col = U.astype(object)
    col[7] = cell
    path = tmp_path / "bad.csv"
    rows = ["t,u [V]"] + [f"{t},{u}" for t, u in zip(T, col)]
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    with pytest.raises(DataError, match=rf"^{path}: column 'u \[V\]' row 9: '{cell}' is {what}"):
        load_recording(path, {"time": "t", "voltage": "u"})
    assert main(["estimate", str(path), "--map", "time=t", "voltage=u"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "row 9" in err and "Traceback" not in err


def test_a_decimal_comma_in_a_comma_file_is_named(tmp_path):
    path = tmp_path / "c.csv"
    path.write_text("t,u\n" + "".join(f"{t},{u}\n" for t, u in zip(T, U)) + '0.02,"1,5"\n', encoding="utf-8")
    with pytest.raises(DataError, match=r"row 22: '1,5' is not a number \(decimal comma\? use --decimal ,\)"):
        load_recording(path, {"time": "t", "voltage": "u"})


def test_map_takes_several_pairs(tmp_path, capsys):
    path = tmp_path / "d.csv"
    path.write_text("t,a,b\n" + "".join(f"{t},{u},{2 * u}\n" for t, u in zip(T, U)), encoding="utf-8")
    parser = argparse.ArgumentParser()
    add_recording_arguments(parser, ROLES, 50.0)
    args = parser.parse_args([str(path), "--map", "time=t", "voltage=a", "--map", "current=b*0.5"])
    assert mapped_roles(args, ROLES) == {"time": "t", "voltage": "a", "current": "b*0.5"}
    rec = load_recording(path, mapped_roles(args, ROLES))
    np.testing.assert_allclose(rec.signals["current"], U, rtol=1e-15)


def test_monitor_refuses_a_table_side_position_without_a_pitch(tmp_path, capsys):
    path = tmp_path / "lin.csv"
    path.write_text("t [s],u [V],i [A],x [mm]\n" + "".join(f"{t},{u},{u / 2},{t * 100}\n" for t, u in zip(T, U)),
                    encoding="utf-8")
    assert main(["monitor", str(path), "--map", "time=t", "voltage=u", "current1=i", "position=x",
                 "--db", ":memory:"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "table side" in err and "--pitch" in err
    # with the pitch, the table position [m] becomes the motor angle [rad]: 2 pi ratio / pitch per m
    rec = load_recording(path, {"time": "t", "position": "x"})
    args = argparse.Namespace(pitch=0.01, ratio=2.0)
    motor = to_motor_side(rec, args)
    np.testing.assert_allclose(motor.signals["position"], T * 0.1 * 2 * math.pi * 2 / 0.01, rtol=1e-12)
    assert motor.side == "motor"


def test_a_unit_stated_without_a_scale_converts_a_bare_column_and_must_agree_with_a_header(tmp_path):
    """``w [rpm]`` on a column headed ``w`` used to find the column and drop the unit (values taken as rad/s)."""
    bare = tmp_path / "bare.csv"
    bare.write_text("t [s],w\n" + "".join(f"{t},{u}\n" for t, u in zip(T, U)), encoding="utf-8")
    rec = load_recording(bare, {"time": "t", "speed": "w [rpm]"})
    np.testing.assert_allclose(rec.signals["speed"], U * np.pi / 30, rtol=1e-14)
    assert rec.units["speed"] == "rad/s" and assumed_units(rec) == ()
    headed = write(tmp_path / "headed.csv", ["t [s]", "w [rpm]"])
    np.testing.assert_allclose(load_recording(headed, {"time": "t", "speed": "w [rpm]"}).signals["speed"],
                               U * np.pi / 30, rtol=1e-14)
    with pytest.raises(DataError, match=r"the header says \[rpm\], the map states \[rad/s\]; expected one unit"):
        load_recording(headed, {"time": "t", "speed": "w [rad/s]"})


def test_pandas_decimal_comma_with_the_default_separator_is_read_from_its_quotes(tmp_path):
    """``df.to_csv(decimal=",")`` keeps the ',' separator and quotes every number ("0,5"). It was refused with
    "(decimal comma? use --decimal ,)", and --decimal , then with "the decimal mark and the separator are both
    ','": a dead end. The quotes make it unambiguous; a quoted "1,234" beside "0.5" stays a thousands mark."""
    path = tmp_path / "pandas.csv"
    path.write_text('t [s],v [m/s]\n' + "".join(f'"{t:.3f}","{float(u)!r}"\n'.replace(".", ",") for t, u in zip(T, U)),
                    encoding="utf-8")
    rec = load_recording(path, {"time": "t", "speed": "v"})
    np.testing.assert_allclose(rec.signals["speed"], U, rtol=1e-14)
    assert rec.h == pytest.approx(T[1] - T[0])
    mixed = tmp_path / "mixed.csv"
    mixed.write_text('t [s],v [m/s],n\n' + "".join(f'{float(t)!r},{float(u)!r},"1,234"\n' for t, u in zip(T, U)), encoding="utf-8")
    rec = load_recording(mixed, {"time": "t", "speed": "v"})
    np.testing.assert_allclose(rec.signals["speed"], U, rtol=1e-14)
