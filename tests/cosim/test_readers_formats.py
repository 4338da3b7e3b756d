"""The readers: one synthetic drive record saved as CSV, MATLAB v5 (matrix, transposed matrix, struct), MATLAB
v7.3 (HDF5), Parquet and a ``%``-header text log gives the same estimates to every printed digit; role-map
expressions that do not resolve are one line naming the file, the role and what exists."""
from __future__ import annotations

import datetime as dt
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import readers_data as rd  # noqa: E402

from feeddrive.cosim.cli import main  # noqa: E402
from feeddrive.cosim.errors import DataError  # noqa: E402
from feeddrive.cosim.readers import open_source  # noqa: E402
from feeddrive.cosim.recorded import load_recording, start_clock  # noqa: E402

#: format -> (writer, role map); every map names the same four signals
FORMATS = {
    "csv": (lambda p, d: rd.write_csv(p / "r.csv", d), ["time=time", "voltage=u", "current=i", "speed=w"]),
    "mat-matrix": (lambda p, d: rd.write_mat_matrix(p / "r.mat", d),
                   ["time=data[:,0]", "voltage=data[:,1]", "current=data[:,2]", "speed=data[:,3]"]),
    "mat-transposed": (lambda p, d: rd.write_mat_matrix(p / "r.mat", d, transposed=True),
                       ["time=data[:,0]", "voltage=data[:,1]", "current=data[:,2]", "speed=data[:,-1]"]),
    "mat-struct": (lambda p, d: rd.write_mat_struct(p / "r.mat", d),
                   ["time=rec.t", "voltage=rec.sig[:,0]", "current=rec.sig[:,1]", "speed=rec.sig[:,2]"]),
    "mat-v7.3": (lambda p, d: rd.write_mat73(p / "r.mat", d),
                 ["time=rec.t", "voltage=data[:,1]", "current=rec.sig[:,1]", "speed=data[:,3]"]),
    "parquet": (lambda p, d: rd.write_parquet(p / "r.parquet", d),
                ["time=time", "voltage=u", "current=i", "speed=w [rad/s]"]),
    "text-log": (lambda p, d: rd.write_text_log(p / "r.txt", d),
                 ["time=time", "voltage=Motor voltage", "current=col3", "speed=Motor speed"]),
}


@pytest.fixture(scope="module")
def data() -> dict:
    return rd.record()


@pytest.fixture(scope="module")
def csv_output(data, tmp_path_factory) -> str:
    path = rd.write_csv(tmp_path_factory.mktemp("csv") / "r.csv", data)
    return estimate(path, FORMATS["csv"][1])


def estimate(path: Path, role_map: list[str], *extra: str) -> str:
    import contextlib
    import io

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["estimate", str(path), "--map", *role_map, "--method", "ls", *extra])
    assert code == 0, err.getvalue()
    return out.getvalue()


@pytest.mark.parametrize("fmt", [f for f in FORMATS if f != "csv"])
def test_every_format_gives_the_csv_estimates_to_every_printed_digit(fmt, data, csv_output, tmp_path):
    writer, role_map = FORMATS[fmt]
    path = writer(tmp_path, data)
    rec = load_recording(path, dict(m.split("=", 1) for m in role_map))
    # the values themselves are the same float64 numbers, not merely close
    np.testing.assert_array_equal(rec.signals["voltage"], data["u"])
    np.testing.assert_array_equal(rec.signals["speed"], data["w"])
    assert rec.h == pytest.approx(5e-4, rel=1e-9) and rec.units["speed"] == ("rad/s" if fmt in (
        "csv", "parquet", "text-log") else "")
    out = estimate(path, role_map)
    assert out == csv_output
    assert out.count("95 % CI") == 6  # R, L, K, Jt, ft, Cd


def test_the_record_gives_the_model_within_the_iv_intervals(data, tmp_path):
    """The record itself is sound: IV's 95 % intervals (from the text log, the least exact-looking format)
    hold the model's parameters (LS is biased by the noise on the regressors: Jt 2 % low)."""
    from plant_data import TRUTH

    out = estimate(rd.write_text_log(tmp_path / "r.txt", data), FORMATS["text-log"][1], "--method", "iv")
    rows = [line.replace("[", " ").replace("]", " ").replace(",", " ").split() for line in out.splitlines()
            if "95 % CI" in line]
    assert {r[0] for r in rows} == {"R", "L", "K", "Jt", "ft", "Cd"}
    for r in rows:
        assert float(r[-2]) <= TRUTH[r[0]] <= float(r[-1]), r


@pytest.mark.parametrize("expr, message", [
    ("rec.sig[:,3]", r"role speed: 'rec\.sig\[:,3\]': index 3 out of range for 'rec\.sig' of shape \(7241, 3\)"),
    ("recc.sig[:,0]", r"role speed: no variable 'recc'; variables are rec \(struct\)$"),
    ("rec.speed", r"role speed: 'rec' has no field 'speed'; its fields are t, sig, name$"),
    ("rec.sig", r"role speed: 'rec\.sig' has shape \(7241, 3\); expected one column, e\.g\. rec\.sig\[:,0\]"),
    ("rec.sig[:,0", r"role speed: 'rec\.sig\[:,0': cannot read '\[:,0' after 'rec\.sig'"),
    ("rec.sig[:,x]", r"role speed: 'rec\.sig\[:,x\]': index \[:,x\] is not a list of integers or ':'"),
    ("rec.name", r"role speed: 'rec\.name' holds text, expected numbers"),
    ("rec", r"role speed: 'rec' is a struct; name one of its fields \(t, sig, name\)"),
    ("7up", r"role speed: '7up' is not a variable expression"),
])
@pytest.mark.parametrize("version", ["v5", "v7.3"])
def test_a_role_that_does_not_resolve_is_one_line_naming_the_file_role_and_what_exists(
        data, tmp_path, capsys, expr, message, version):
    path = (rd.write_mat_struct if version == "v5" else rd.write_mat73)(tmp_path / "r.mat", data)
    code = main(["estimate", str(path), "--map", "time=rec.t", "voltage=rec.sig[:,0]", f"speed={expr}"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    if version == "v7.3" and "variables are" in message:  # the v7.3 file also holds `data`
        message = message.replace(r"rec \(struct\)$", r"data \(7241, 4\), rec \(struct\)$")
    if version == "v7.3":  # HDF5 lists a group's members by name
        message = message.replace("t, sig, name", "name, sig, t")
    assert err.startswith(f"cosim estimate: error: {path}: ")
    import re

    assert re.search(message, err.strip()), err


def test_a_transposed_matrix_is_read_samples_first_and_info_says_it_was_stored_so(data, tmp_path, capsys):
    path = rd.write_mat_matrix(tmp_path / "r.mat", data, transposed=True)
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "MATLAB v5-v7" in out
    assert "time: data[:,0]: 7241 samples, median step 0.0005 s (2000 Hz)" in out and "no gaps" in out
    row = next(line.split() for line in out.splitlines() if line.split()[:1] == ["data"])
    assert row == ["data", "7241", "x", "4", "float64", "stored", "4", "x", "7241"]
    assert next(line.split() for line in out.splitlines() if line.split()[:1] == ["J"])[1:] == ["scalar", "float64"]


def test_text_log_columns_are_named_from_the_comment_lines_with_their_units(data, tmp_path):
    source = open_source(rd.write_text_log(tmp_path / "r.log", data))
    assert [(v.name, v.unit) for v in source.variables()] == [
        ("time", "sec"), ("Motor voltage", "V"), ("Motor current", "A"), ("Motor speed", "rad/s")]
    np.testing.assert_array_equal(source.resolve("col4", "speed").values, data["w"])
    # a log without numbered comments: col1..colN
    plain = tmp_path / "plain.txt"
    plain.write_text("# bench log\n" + "\n".join(f"{t!r} {u!r}" for t, u in zip(data["t"].tolist(), data["u"].tolist())) + "\n")
    assert [v.name for v in open_source(plain).variables()] == ["col1", "col2"]
    rec = load_recording(plain, {"time": "col1", "voltage": "col2"})
    assert rec.h == pytest.approx(5e-4, rel=1e-9) and rec.units["voltage"] == ""


def test_a_ragged_text_log_names_the_line(tmp_path):
    path = tmp_path / "r.txt"
    path.write_text("% 1 time\n% 2 u [V]\n0 1\n0.1 2\n0.2\n", encoding="utf-8")
    with pytest.raises(DataError, match=r"r\.txt: line 5: 1 fields, expected 2 as in the first data line"):
        open_source(path)


def test_parquet_timestamps_are_the_recordings_calendar_time(data, tmp_path):
    start = dt.datetime(2026, 3, 1, 10, 0, tzinfo=dt.timezone.utc).timestamp()
    path = rd.write_parquet(tmp_path / "r.parquet", data, timestamps=start)
    rec = load_recording(path, {"time": "time", "voltage": "u", "current": "i [A]"})
    assert rec.clock == pytest.approx(start, abs=1e-6) and rec.t0 == 0.0
    assert rec.h == pytest.approx(5e-4, rel=1e-6) and rec.units == {"voltage": "V", "current": "A"}
    clock, source = start_clock(rec)
    assert clock == pytest.approx(start, abs=1e-6) and source.startswith("time stamps of column 'time'")
    # --start-time wins, and says so
    clock, source = start_clock(rec, "2026-03-01T11:00:00+01:00")
    assert clock == pytest.approx(start, abs=1e-6) and source == "--start-time 2026-03-01T11:00:00+01:00"


def test_without_calendar_time_the_start_is_the_file_time_and_says_so(data, tmp_path):
    import os

    path = rd.write_csv(tmp_path / "r.csv", data)
    os.utime(path, (1.7e9, 1.7e9))
    rec = load_recording(path, {"time": "time", "voltage": "u"})
    clock, source = start_clock(rec)
    assert clock == pytest.approx(1.7e9 - data["t"][-1], abs=1e-6)
    assert source.startswith(f"file modification time of {path} (taken as the end of the recording")


def test_a_struct_array_is_indexed_then_its_field_named(data, tmp_path, capsys):
    """MATLAB ``rec(2).u`` is ``rec[1].u`` (0-based, as every index in a role map)."""
    import scipy.io

    n = 2000
    runs = np.array([{"t": data["t"][:n], "u": data["u"][:n]}, {"t": data["t"][:n], "u": -data["u"][:n]}],
                    dtype=object)
    path = tmp_path / "runs.mat"
    scipy.io.savemat(path, {"rec": runs})
    rec = load_recording(path, {"time": "rec[1].t", "voltage": "rec[1].u"})
    np.testing.assert_array_equal(rec.signals["voltage"], -data["u"][:n])
    assert main(["info", str(path)]) == 0
    row = next(" ".join(line.split()) for line in capsys.readouterr().out.splitlines() if line.split()[:1] == ["rec"])
    assert row == "rec 2 struct array rec[k].FIELD, fields: t, u"
    with pytest.raises(DataError, match=r"role voltage: 'rec' is a struct array of shape \(2,\); index it first, e\.g\. rec\[0\]\.u"):
        load_recording(path, {"time": "rec[0].t", "voltage": "rec.u"})


@pytest.mark.parametrize("name, content, message", [
    ("g.mat", b"garbage\x00\x01", "not a readable MATLAB file"),
    ("h.mat", b"MATLAB 5.0 MAT-file, garbage", "not a readable MATLAB file"),
    ("e.mat", b"", "not a readable MATLAB file"),
    ("p.parquet", b"PAR1 garbage", "not a readable Parquet file"),
    ("c.txt", b"% only\n% comments\n", "no data lines (only comments or empty)"),
    ("n.txt", b"0 1\n0.1 nan\n" + b"".join(b"%d 1\n" % k for k in range(2, 20)), "'col2' sample 1: nan is not a finite"),
])
@pytest.mark.parametrize("command", ["info", "estimate"])
def test_an_unreadable_file_of_each_format_is_one_line(tmp_path, capsys, name, content, message, command):
    path = tmp_path / name
    path.write_bytes(content)
    argv = [command, str(path)] + (["--map", "time=col1", "voltage=col2"] if command == "estimate" else [])
    code = main(argv)
    err = capsys.readouterr().err
    if name == "n.txt" and command == "info":  # listing a NaN is fine; estimating from it is not
        assert code == 0
        return
    assert code == 2 and err.count("\n") == 1 and message in err and str(path) in err, err


@pytest.mark.parametrize("expr, message", [
    ("a3", r"'a3' has shape \(30, 2, 2\); expected one column"),
    ("b[0]", r"'b\[0\]' is a single value; expected a signal"),
    ("b[::0]", r"'b\[::0\]': slice step cannot be zero"),
    ("c", r"'c' holds complex128, expected numbers"),
    ("cell", r"'cell' holds cells or a struct array"),
])
def test_matrices_of_the_wrong_kind_are_named(tmp_path, expr, message):
    import scipy.io

    path = tmp_path / "z.mat"
    scipy.io.savemat(path, {"c": np.ones(30) + 1j, "a3": np.ones((30, 2, 2)), "b": np.ones(30, bool),
                            "cell": np.array([np.ones(3), "x"], dtype=object)})
    with pytest.raises(DataError, match=rf"z\.mat: role voltage: {message}"):
        load_recording(path, {"voltage": expr}, 0.1)


def test_iso_time_stamps_in_a_csv_give_the_step_and_the_calendar_time(data, tmp_path, capsys):
    start = dt.datetime(2026, 3, 1, 10, 0, tzinfo=dt.timezone.utc)
    stamps = [(start + dt.timedelta(microseconds=round(t * 1e6))).isoformat() for t in data["t"][:400].tolist()]
    path = tmp_path / "iso.csv"
    path.write_text("time,u [V]\n" + "".join(f"{s},{u!r}\n" for s, u in zip(stamps, data["u"][:400].tolist())),
                    encoding="utf-8")
    rec = load_recording(path, {"time": "time", "voltage": "u"})
    assert rec.h == pytest.approx(5e-4, rel=1e-9) and rec.clock == pytest.approx(start.timestamp(), abs=1e-6)
    assert rec.t0 == 0.0 and start_clock(rec)[0] == pytest.approx(start.timestamp(), abs=1e-6)
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "time: time (calendar time stamps): 400 samples, median step 0.0005 s (2000 Hz)" in out
    bad = tmp_path / "bad.csv"
    bad.write_text(path.read_text(encoding="utf-8").replace(stamps[7], "soon"), encoding="utf-8")
    with pytest.raises(DataError, match=r"column 'time' row 9: 'soon' is not an ISO 8601 time stamp"):
        load_recording(bad, {"time": "time", "voltage": "u"})
