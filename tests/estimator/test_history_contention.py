"""The history store under contention and on a failing disk: two writers at once both store every
motion; a full database refuses one motion in one line and keeps every motion stored before it."""
from __future__ import annotations

import multiprocessing
import os
import sqlite3

import pytest

from feeddrive.estimator.errors import HistoryError
from feeddrive.estimator.history import History

N = 40


def motion(k: int, writer: int) -> dict:
    return {"motion": k, "validated": True, "parameters": {"R": {"value": 0.6 + 1e-3 * writer, "ci95": [0.59, 0.61]},
                                                           "K": {"value": 1.05, "ci95": [1.04, 1.06]}},
            "sensor_faults": [], "diagnosis": []}


def writer(path: str, w: int, start: multiprocessing.synchronize.Event) -> None:
    start.wait()
    with History(path) as h:
        for k in range(N):
            h.record("X", motion(k, w), scenario=f"writer-{w}")


def test_two_concurrent_writers_store_every_motion(tmp_path):
    path = str(tmp_path / "history.sqlite")
    ctx = multiprocessing.get_context("fork")
    start = ctx.Event()
    procs = [ctx.Process(target=writer, args=(path, w, start)) for w in (1, 2)]
    for p in procs:
        p.start()
    start.set()  # both open the (not yet existing) file and write at the same moment
    for p in procs:
        p.join(60)
    assert [p.exitcode for p in procs] == [0, 0]
    with sqlite3.connect(path) as db:
        assert db.execute("PRAGMA integrity_check").fetchone() == ("ok",)
        rows = db.execute("SELECT scenario, motion FROM motions ORDER BY scenario, motion").fetchall()
        r = dict(db.execute("SELECT m.scenario, AVG(p.value) FROM parameters p JOIN motions m ON m.id = p.motion_id "
                            "WHERE p.name = 'R' GROUP BY m.scenario").fetchall())
    assert rows == [(f"writer-{w}", k) for w in (1, 2) for k in range(N)]
    assert r == {"writer-1": pytest.approx(0.601, abs=1e-12), "writer-2": pytest.approx(0.602, abs=1e-12)}


def test_full_database_refuses_one_motion_and_keeps_the_others(tmp_path):
    path = tmp_path / "history.sqlite"
    with History(path) as h:
        for k in range(3):
            h.record("X", motion(k, 1))
        pages = h._db.execute("PRAGMA page_count").fetchone()[0]
        h._db.execute(f"PRAGMA max_page_count = {pages}")  # SQLite's own SQLITE_FULL, as on a full disk
        big = motion(3, 1) | {"notes": ["x" * 200_000]}
        with pytest.raises(HistoryError) as info:
            h.record("X", big)
        text = str(info.value)
        assert text.startswith(f"history database {path}: motion 3 not stored: database or disk is full")
        assert "the motions stored before are kept" in text and "\n" not in text
        assert [m["motion"] for m in h.motions("X")] == [0, 1, 2]
        h.record("X", motion(4, 1))  # the store is still usable for a motion that fits
    with sqlite3.connect(path) as db:
        assert db.execute("PRAGMA integrity_check").fetchone() == ("ok",)


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes read-only files")
def test_read_only_history_is_one_line(tmp_path):
    path = tmp_path / "history.sqlite"
    with History(path) as h:
        h.record("X", motion(0, 1))
    path.chmod(0o444)
    tmp_path.chmod(0o555)
    try:
        with pytest.raises(HistoryError, match=r"readonly database; expected a writable file and folder"), \
                History(path) as h:
            h.record("X", motion(1, 1))
    finally:
        tmp_path.chmod(0o755)
        path.chmod(0o644)
    with History(path) as h:
        assert [m["motion"] for m in h.motions("X")] == [0]
