"""The battery of bad inputs: scenario, campaign file, CSV, FMU archive, history file.

Each one is a real file on disk given to the real CLI; each asserts its exit status (2: bad input),
exactly one line on stderr naming the file (and the key or line where there is one) with what was
expected, no traceback, and that nothing hangs (a YAML bomb is refused in milliseconds).
"""
from __future__ import annotations

import sqlite3
import time
import zipfile
from pathlib import Path

import fmpy
import pytest
from faulty import MAP, build, compile_library

from feeddrive.cosim import recorded
from feeddrive.cosim.cli import main

GOOD = "name: t\nstep: 1.0e-4\nstop_time: 0.01\nplant: {fmu: builtin}\nnc:\n  program:\n    - rapid: {to: 0.01}\n"
BOMB = "".join(f"{k}: &{k} [" + ",".join([f"*{p}" if p else '"lol"' for _ in range(9)]) + "]\n"
               for p, k in zip([None, *"abcdefgh"], "abcdefghi"))
CSV = "time,u [V],i [A],w\n" + "".join(f"{k * 1e-3:.3f},{k % 7},{k % 5},{k % 3}\n" for k in range(40))


# -- scenarios: cosim run ----------------------------------------------------------------------------------
SCENARIOS = {  # id: (file content (str or bytes), expected text in the line; {f} is the file)
    "billion-laughs": (BOMB, "{f}:6: YAML aliases expand to more than 100000 values"),
    "recursive-alias": ("a: &a [*a]\n", "{f}:1: recursive YAML alias"),
    "deep-nesting": ("[" * 5000 + "]" * 5000, "{f}:1: YAML nested too deeply; expected at most 100 levels"),
    "deep-mapping": ("a:\n" + "".join(" " * k + "b:\n" for k in range(1, 150)), "nested too deeply"),
    "too-large": ("# " + "x" * (1 << 20) + "\n" + GOOD, "scenario file of 1048"),
    "not-utf8": (b"name: caf\xe9\n", "{f}:1: byte 0xe9 is not UTF-8; expected a UTF-8 scenario file"),
    "utf16": ("name: t\n".encode("utf-16"), "{f}:1: byte 0xff is not UTF-8"),
    "top-level-list": ("- name: t\n", "{f}"),
    "empty": ("", "{f}"),
    "syntax": ("name: t\nplant: {fmu: builtin\n", "{f}:3: invalid YAML"),
    "tab-indent": ("name: t\nplant:\n\tfmu: builtin\n", "{f}:3: a tab character (column 1): YAML indents with spaces"),
    "two-documents": (GOOD + "---\nname: u\n", "{f}:8: invalid YAML: but found another document"),
    "unhashable-key": ("name: t\n? [a, b]\n: 1\n", "{f}:2: invalid YAML: found unhashable key"),
    "unknown-key": (GOOD + "stepp: 1\n", "{f}:8: stepp: unknown key 'stepp'"),
    "negative-step": (GOOD.replace("1.0e-4", "-1.0e-4"), "{f}:2: step:"),
    "string-step": (GOOD.replace("1.0e-4", "fast"), "{f}:2: step:"),
    "timestamp-step": (GOOD.replace("1.0e-4", "2001-01-01"), "{f}:2: step:"),
    "huge-int-step": (GOOD.replace("1.0e-4", "1" + "0" * 400), "{f}:2: step:"),
    "nan-stop-time": (GOOD.replace("0.01\nplant", ".nan\nplant"), "{f}:3: stop_time:"),
    "program-not-list": (GOOD.split("nc:")[0] + "nc: {program: 3}\n", "{f}:5: nc.program"),
    "python-tag": ("name: !!python/object/apply:os.system [echo hi]\n", "{f}:1: invalid YAML"),
    "interface": (GOOD.replace("{fmu: builtin}", "{fmu: builtin, interface: xx}"), "{f}:4: plant.interface:"),
    "call-timeout": (GOOD.replace("{fmu: builtin}", "{fmu: builtin, call_timeout: 0}"), "{f}:4: plant.call_timeout:"),
    "fmu-missing": (GOOD.replace("{fmu: builtin}", "{fmu: nowhere.fmu}"), "{f}:4: plant.fmu: FMU file not found"),
}


def run_cli(argv: list[str], capfd) -> str:
    """The CLI's exit status must be 2 with one stderr line and no traceback, within 20 s; returns the line."""
    start = time.monotonic()
    status = main(argv)
    err = capfd.readouterr().err
    assert status == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert time.monotonic() - start < 20
    return err.strip()


@pytest.mark.parametrize("case", SCENARIOS, ids=list(SCENARIOS))
def test_bad_scenario(tmp_path, capfd, case):
    content, expected = SCENARIOS[case]
    path = tmp_path / "s.yaml"
    path.write_bytes(content.encode() if isinstance(content, str) else content)
    line = run_cli(["run", str(path), "--out", str(tmp_path / "out"), "--no-progress"], capfd)
    assert line.startswith("cosim run: error: ") and expected.format(f=path) in line, line


def test_scenario_path_errors(tmp_path, capfd):
    for path, expected in ((tmp_path / "none.yaml", "cannot read scenario file"), (tmp_path, "cannot read scenario file")):
        assert expected in run_cli(["run", str(path), "--no-progress"], capfd)


# -- campaign files: cosim campaign -------------------------------------------------------------------------
CAMPAIGNS = {
    "billion-laughs": (BOMB, "{f}:6: YAML aliases expand to more than 100000 values"),
    "not-utf8": (b"name: caf\xe9\n", "{f}:1: byte 0xe9 is not UTF-8; expected a UTF-8 campaign file"),
    "too-large": ("# " + "x" * (1 << 20) + "\nname: c\n", "campaign file of 1048"),
    "unknown-key": ("name: c\nbase: s.yaml\nrepeats: 2\n", "{f}:3: repeats: unknown key"),
    "timeout": ("name: c\nbase: s.yaml\ntimeout: -1\n", "{f}:3: timeout: Input should be greater than 0"),
    "base-missing": ("name: c\nbase: nothing.yaml\n", "{f}:2: base: scenario file nothing.yaml not found"),
    "base-bomb": ("name: c\nbase: bomb.yaml\n", "bomb.yaml:6: YAML aliases expand to more than 100000 values"),
    "syntax": ("name: c\nbase: [s.yaml\n", "{f}:3: invalid YAML"),
}


@pytest.mark.parametrize("case", CAMPAIGNS, ids=list(CAMPAIGNS))
def test_bad_campaign_file(tmp_path, capfd, case):
    content, expected = CAMPAIGNS[case]
    (tmp_path / "s.yaml").write_text(GOOD)
    (tmp_path / "bomb.yaml").write_text(BOMB)
    path = tmp_path / "c.yaml"
    path.write_bytes(content.encode() if isinstance(content, str) else content)
    line = run_cli(["campaign", str(path), "--out", str(tmp_path / "out"), "--no-plots"], capfd)
    assert line.startswith("cosim campaign: error: ") and expected.format(f=path) in line, line


def test_bad_campaign_timeout_option(tmp_path, capfd):
    (tmp_path / "s.yaml").write_text(GOOD)
    (tmp_path / "c.yaml").write_text("name: c\nbase: s.yaml\n")
    line = run_cli(["campaign", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "o"), "--timeout", "0"], capfd)
    assert "--timeout: expected a number of seconds > 0, got 0.0" in line


# -- CSV recordings: cosim estimate --------------------------------------------------------------------------
CSVS = {
    "huge-field": ('time,u\n"' + "x" * 200_000 + '",1\n', "{f}: line 2: field larger than field limit"),
    "not-utf8": (CSV.replace("time", "t\xefme").encode("latin-1"), "{f}: line 1: byte 0xef is not UTF-8"),
    "empty": ("", "{f}: empty file, expected a header row"),
    "missing-column": (CSV.replace("w\n", "v\n", 1), "{f}: column 'w' (role speed) not found"),
    "text-cell": (CSV.replace("0.005,5", "0.005,five"), "{f}: column 'u [V]' row 7: 'five' is not a number"),
    "nan-cell": (CSV.replace("0.005,5", "0.005,nan"), "{f}: column 'u [V]' row 7: 'nan' is not a finite number"),
    "nul-byte": (CSV.replace("0.005,5", "0.005,\0"), "{f}: column 'u [V]' row 7"),
    "time-backwards": (CSV.replace("0.005,", "0.001,"), "{f}: column 'time' is not strictly increasing at row 7"),
    "too-large": (CSV, "bytes; expected a CSV file of at most 100 bytes"),
}


@pytest.mark.parametrize("case", CSVS, ids=list(CSVS))
def test_bad_csv(tmp_path, capfd, monkeypatch, case):
    content, expected = CSVS[case]
    if case == "too-large":
        monkeypatch.setattr(recorded, "MAX_BYTES", 100)
    path = tmp_path / "r.csv"
    path.write_bytes(content.encode() if isinstance(content, str) else content)
    line = run_cli(["estimate", str(path), "--map", "time=time", "--map", "voltage=u", "--map", "current=i",
                    "--map", "speed=w"], capfd)
    assert line.startswith("cosim estimate: error: ") and expected.format(f=path) in line, line


# -- FMU archives: cosim run with a vendor FMU --------------------------------------------------------------
@pytest.fixture(scope="module")
def library(tmp_path_factory) -> Path:
    return compile_library(tmp_path_factory.mktemp("lib"))


def _not_a_zip(out: Path, lib: Path) -> None:
    out.write_text("this is not a zip file\n")


def _no_description(out: Path, lib: Path) -> None:
    build(out, description=False, library=lib)


ARCHIVES = {
    "not-a-zip": (_not_a_zip, "not an FMU (a zip file with a modelDescription.xml)"),
    "no-model-description": (_no_description, "not an FMU (a zip file with a modelDescription.xml)"),
    "fmi-1.0": (lambda out, lib: build(out, fmi_version="1.0", library=lib), "is an FMI 1.0 FMU; expected FMI 2.0 or 3.0"),
    "fmi-4.0": (lambda out, lib: build(out, fmi_version="4.0", library=lib), "is an FMI 4.0 FMU; expected FMI 2.0 or 3.0"),
    "no-binary-for-platform": (lambda out, lib: build(out, platform="aarch64-darwin", library=lib),
                               f"no binary for this platform: expected binaries/{fmpy.platform}/faulty"),
    "dot-dot-entry": (lambda out, lib: build(out, library=lib, extra={"resources/../../evil.txt": b"x"}),
                      "archive entry 'resources/../../evil.txt' points outside the FMU"),
    "absolute-entry": (lambda out, lib: build(out, library=lib, extra={"/tmp/evil.txt": b"x"}),
                       "points outside the FMU"),
}


@pytest.mark.parametrize("case", ARCHIVES, ids=list(ARCHIVES))
def test_bad_fmu_archive(tmp_path, capfd, library, case):
    make, expected = ARCHIVES[case]
    fmu = tmp_path / "Vendor.fmu"
    make(fmu, library)
    if case == "absolute-entry":  # zipfile strips a leading "/" when writing: write the raw name
        with zipfile.ZipFile(fmu) as z:
            assert any(n.lstrip("/") == "tmp/evil.txt" for n in z.namelist())
        _raw_absolute_entry(fmu)
    map_text = "{" + ", ".join(f"{r}: {{var: {e['var']}}}" for r, e in MAP.items()) + "}"
    path = tmp_path / "s.yaml"
    path.write_text(GOOD.replace("{fmu: builtin}", f"{{fmu: Vendor.fmu, map: {map_text}}}"))
    line = run_cli(["run", str(path), "--out", str(tmp_path / "out"), "--no-progress"], capfd)
    assert line.startswith(f"cosim run: error: {path}:4: plant.fmu: ") and expected in line, line
    assert not (tmp_path / "evil.txt").exists() and not Path("/tmp/evil.txt").exists()


def _raw_absolute_entry(fmu: Path) -> None:
    """Rename the entry ``tmp/evil.txt`` to ``/tmp/evil.txt`` in the zip's headers (same length + 1: rebuild)."""
    with zipfile.ZipFile(fmu) as z:
        items = [(i, z.read(i.filename)) for i in z.infolist()]
    with zipfile.ZipFile(fmu, "w") as z:
        for info, data in items:
            if info.filename == "tmp/evil.txt":
                info = zipfile.ZipInfo("/tmp/evil.txt")
                info.filename = "/tmp/evil.txt"  # set after construction: ZipInfo keeps it as given
            z.writestr(info, data)


# -- history files: cosim history and cosim run --------------------------------------------------------------
def _text_file(path: Path) -> None:
    path.write_text("axis,R\nX,0.6\n")


def _corrupt_sqlite(path: Path) -> None:
    with sqlite3.connect(path) as db:
        db.execute("CREATE TABLE t (x)")
        db.executemany("INSERT INTO t VALUES (?)", [(k,) for k in range(2000)])
    data = bytearray(path.read_bytes())
    data[100:4096] = b"\xa5" * (4096 - 100)  # the header page's b-tree is garbage, the magic kept
    path.write_bytes(bytes(data))


HISTORIES = {
    "text-file": (_text_file, "not an SQLite file"),
    "corrupt-sqlite": (_corrupt_sqlite, "malformed"),
    "directory": (lambda p: p.mkdir(), "history database"),
}


@pytest.mark.parametrize("command", ["history", "run"])
@pytest.mark.parametrize("case", HISTORIES, ids=list(HISTORIES))
def test_bad_history_file_is_one_line_and_never_overwritten(tmp_path, capfd, feeddrive_fmu, case, command):
    make, expected = HISTORIES[case]
    db = tmp_path / "history.sqlite"
    make(db)
    before = db.read_bytes() if db.is_file() else None
    if command == "history":
        argv = ["history", "--db", str(db)]
    else:
        path = tmp_path / "s.yaml"
        path.write_text(GOOD + f"monitor: {{db: {db}}}\n")
        argv = ["run", str(path), "--out", str(tmp_path / "out"), "--no-progress"]
    line = run_cli(argv, capfd)
    assert str(db) in line and expected in line, line
    if before is not None:
        assert db.read_bytes() == before  # never overwritten, not even its header


def test_missing_history_folder(tmp_path, capfd):
    line = run_cli(["history", "--db", str(tmp_path / "no" / "h.sqlite")], capfd)
    assert "folder" in line and "does not exist" in line


def test_the_battery_has_at_least_40_cases():
    n = len(SCENARIOS) + 1 + len(CAMPAIGNS) + 1 + len(CSVS) + len(ARCHIVES) + 2 * len(HISTORIES) + 1
    assert n >= 40, n
