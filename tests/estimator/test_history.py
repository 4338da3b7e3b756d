"""The SQLite history: round trips, theta_{j-1} and baseline read-back, age logic, atomicity under SIGKILL."""
import json
import os
import signal
import sqlite3
import subprocess
import sys
import textwrap

import pytest

from feeddrive.estimator.errors import EstimatorInputError
from feeddrive.estimator.history import History

NAMES = ("R", "L", "K", "Jt", "ft", "Cd")


def result(k, validated=True, **extra):
    """A motion result whose numbers encode k, so read-backs can be checked exactly."""
    params = {n: {"value": (j + 1) + k / 1000, "std": 0.01 * (j + 1), "ci95": [(j + 1) + k / 1000 - 0.02,
                                                                             (j + 1) + k / 1000 + 0.02]}
              for j, n in enumerate(NAMES)}
    return {"motion": k, "start": 1.0 * k, "end": 1.0 * k + 0.5, "method": "iv", "validated": validated,
            "measurements_valid": True, "parameters": params, "gain_ratio": 0.9959,
            "sensor_faults": [{"sensor": "Im1", "kind": "offset", "gain": 1.0, "gain_ci95": [0.99, 1.01],
                               "offset": 0.22, "offset_ci95": [0.2, 0.24]}],
            "mismatch": {"test": "ljung-box", "statistic": 12.5, "p_value": 0.25, "passed": True},
            "diagnosis": [{"fault": "brush wear", "parameters": ["R"], "evidence": [{"parameter": "R", "z": 7.0}]}],
            "processing_s": 0.1, **extra}


def test_round_trip_and_read_back(tmp_path):
    db = tmp_path / "h.sqlite"
    with History(db) as h:
        ids = [h.record("X", result(1, diagnosis=[]), "s1", time=100.0), h.record("X", result(2, validated=False), "s1", time=110.0),
               h.record("Y", result(3), "s2", time=115.0), h.record("X", result(4), "s1", time=120.0)]
    assert ids == [1, 2, 3, 4]
    with History(db) as h:  # a second instance reads what the first wrote
        last = h.last_validated("X")
        assert last["id"] == 4 and last["motion"] == 4 and last["time"] == 120.0
        assert last["parameters"]["K"] == {"value": 3.004, "std": 0.03, "ci95": [2.984, 3.024]}
        assert [b["motion"] for b in h.baseline("X", 5)] == [1]  # motion 4 had a diagnosis: not healthy
        assert [b["motion"] for b in h.recent_validated("X", 1)] == [4]
        assert h.last_validated("Z") is None and h.axes() == ["X", "Y"]
        stored = h.motions("X")
        assert [m["motion"] for m in stored] == [1, 2, 4]
        assert stored[1]["validated"] is False and stored[0] == {**result(1, diagnosis=[]), "id": 1, "axis": "X",
                                                                   "scenario": "s1", "time": 100.0}
    con = sqlite3.connect(db)
    assert con.execute("SELECT COUNT(*) FROM parameters").fetchone()[0] == 4 * len(NAMES)
    assert con.execute("SELECT sensor, kind, offset, offset_low FROM sensor_faults WHERE motion_id = 2").fetchone() \
        == ("Im1", "offset", 0.22, 0.2)
    assert json.loads(con.execute("SELECT parameters FROM diagnoses WHERE motion_id = 3").fetchone()[0]) == ["R"]
    assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"


def test_baseline_skips_diagnosed_and_invalid_motions(tmp_path):
    """The healthy baseline is the first n validated motions WITHOUT a diagnosis; theta_{j-1} and the
    trend still see the diagnosed ones (they are validated)."""
    db = tmp_path / "h.sqlite"
    with History(db) as h:
        for k, kw in enumerate(({}, {"diagnosis": result(0)["diagnosis"]}, {"validated": False}, {}, {}), start=1):
            h.record("X", result(k, **({"diagnosis": []} | kw)), time=10.0 * k)
        h.record("Y", result(6, diagnosis=[]), time=60.0)
    with History(db) as h:  # read back by a new connection, as a monitor does at setup
        assert [b["motion"] for b in h.baseline("X", 2)] == [1, 4]
        assert [b["motion"] for b in h.baseline("X", 5)] == [1, 4, 5]
        assert h.baseline("X", 3)[1]["parameters"]["Cd"]["value"] == 6.004
        assert [b["motion"] for b in h.recent_validated("X", 3)] == [2, 4, 5]
        assert h.last_validated("X")["motion"] == 5 and [b["motion"] for b in h.baseline("Y", 3)] == [6]


def test_identification_age(tmp_path):
    with History(tmp_path / "h.sqlite") as h:
        age = h.age("X", now=50.0)
        assert (age.motions, age.seconds, age.last_validated_id) == (0, 0.0, None)
        h.record("X", result(1, validated=False), time=10.0)
        h.record("X", result(2, validated=False), time=20.0)
        age = h.age("X", now=50.0)
        assert (age.motions, age.seconds) == (2, 40.0) and age.too_old(1, 1e9) and not age.too_old(2, 1e9)
        h.record("X", result(3), time=30.0)
        h.record("X", result(4, validated=False), time=40.0)
        age = h.age("X", now=100.0)
        assert (age.motions, age.seconds, age.last_validated_id) == (1, 70.0, 3)
        assert age.too_old(5, 60.0) and not age.too_old(5, 70.0)


def test_a_failing_write_leaves_no_trace(tmp_path):
    with History(tmp_path / "h.sqlite") as h:
        h.record("X", result(1))
        bad = result(2)
        bad["sensor_faults"] = [{"sensor": "Im1"}]  # no kind: fails after the motion row was inserted
        with pytest.raises(KeyError):
            h.record("X", bad)
        assert [m["motion"] for m in h.motions()] == [1]
        h.record("X", result(3))  # the store stays usable
        assert [m["motion"] for m in h.motions()] == [1, 3]


def test_bad_database_paths_are_named(tmp_path):
    with pytest.raises(EstimatorInputError, match="does not exist"):
        History(tmp_path / "missing" / "h.sqlite")
    junk = tmp_path / "junk.sqlite"
    junk.write_bytes(b"this is not a database" * 100)
    with pytest.raises(EstimatorInputError, match="junk.sqlite"):
        History(junk)
    with History(tmp_path / "h.sqlite") as h, pytest.raises(EstimatorInputError, match="'parameters'"):
        h.record("X", {"validated": True})


WRITER = textwrap.dedent("""
    import sys
    from feeddrive.estimator.history import History
    sys.path.insert(0, {tests!r})
    from test_history import result
    h = History({db!r})
    k = 0
    while True:
        k += 1
        print("begin", k, flush=True)
        h.record("X", result(k, notes=["x" * 2_000_000]))   # 2 MB per motion: writes take a while
        print("done", k, flush=True)
""")


@pytest.mark.slow
def test_sigkill_during_writes_leaves_a_consistent_database(tmp_path):
    """A writer killed right after it announced a write: integrity_check ok, every stored motion complete,
    and the motion being written either entirely there or entirely absent. At least one of the rounds
    must have killed it mid-write (that motion absent), or the test proved nothing."""
    db = tmp_path / "h.sqlite"
    code = WRITER.format(tests=os.path.dirname(__file__), db=str(db))
    mid_write = 0
    for round_ in range(4):
        proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
        done = 0
        while True:  # let 1 + round_ writes complete, then kill as soon as the next one begins
            word, k = proc.stdout.readline().split()
            if word == "done":
                done += 1
            elif done > round_:
                break
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        proc.stdout.close()
        con = sqlite3.connect(db)
        assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        n = con.execute("SELECT COUNT(*) FROM motions").fetchone()[0]
        assert con.execute("SELECT COUNT(*) FROM parameters").fetchone()[0] == n * len(NAMES)
        assert con.execute("SELECT COUNT(*) FROM sensor_faults").fetchone()[0] == n
        assert con.execute("SELECT COUNT(*) FROM diagnoses").fetchone()[0] == n
        con.close()
        with History(db) as h:
            stored = [m["motion"] for m in h.motions()]  # in write order; each writer counts from 1
            for m in h.motions():
                assert len(m["notes"][0]) == 2_000_000
                assert m["parameters"] == result(m["motion"])["parameters"]
        assert stored[-1] in (int(k) - 1, int(k))  # the motion being written: all or nothing
        mid_write += stored[-1] == int(k) - 1
    assert mid_write >= 1
