"""The monitor's memory: one SQLite file holding every motion's result (paper Fig. 4: "stored").

Each motion is written in ONE transaction (the motion row, its parameters, sensor faults and
diagnoses), with the journal in WAL mode and ``synchronous=FULL``: a process killed in the middle of
a write (SIGKILL, power loss after fsync) leaves the database consistent, without a half-written
motion; the next connection rolls the incomplete transaction back.

Times. ``time`` is the machine clock at the end of the motion [s since the Unix epoch]; the
co-simulation monitor uses the wall-clock start of the run plus the simulated time, so runs on the
same axis line up. ``start``/``end`` are the motion's times within its run or recording [s].

The motion result (``record``) is the monitor's per-motion dict::

    {"motion", "start", "end", "method", "validated", "measurements_valid",
     "parameters": {name: {"value", "std", "ci95": [lo, hi]}},
     "sensor_faults": [{"sensor", "kind", "gain", "gain_ci95", "offset", "offset_ci95"}],
     "gain_ratio", "mismatch": {"test", "statistic", "p_value", "passed"} or None,
     "diagnosis": [{"fault", "parameters", "evidence"}], "processing_s", "notes", "error"}

Only ``parameters`` and ``validated`` are required; the whole dict is also kept as JSON.
"""
from __future__ import annotations

import json
import sqlite3
import time as _time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from feeddrive.estimator.errors import EstimatorInputError, HistoryError

SCHEMA_VERSION = 1
#: how long a writer waits for another one's transaction (SQLite's busy timeout) [s]
BUSY_TIMEOUT_S = 30.0
#: attempts of a transaction that still finds the database locked after the busy timeout
RETRIES = 3
_MAGIC = b"SQLite format 3\x00"


def _retry(fn: Any) -> Any:
    """``fn()``, again (up to ``RETRIES`` times, after a short pause) while SQLite says locked or busy."""
    for attempt in range(RETRIES):
        try:
            return fn()
        except sqlite3.OperationalError as exc:
            if attempt == RETRIES - 1 or not any(w in str(exc) for w in ("locked", "busy")):
                raise
            _time.sleep(0.05 * (attempt + 1))
    return None  # pragma: no cover - the loop returns or raises


def _why(exc: sqlite3.DatabaseError) -> str:
    """SQLite's reason, with what a user can do about it."""
    text = str(exc)
    if "readonly" in text or "read-only" in text:
        return f"{text}; expected a writable file and folder"
    if "full" in text:
        return f"{text}; free some space or choose another monitor.db"
    if "not a database" in text or "malformed" in text:
        return f"{text}; the file is not overwritten: expected a history written by the monitor, or a new file name"
    return text
_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS motions (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    axis TEXT NOT NULL,
    scenario TEXT NOT NULL,
    motion INTEGER,
    time REAL NOT NULL,
    start REAL,
    "end" REAL,
    validated INTEGER NOT NULL,
    measurements_valid INTEGER,
    method TEXT,
    gain_ratio REAL,
    mismatch_test TEXT,
    mismatch_statistic REAL,
    mismatch_p_value REAL,
    mismatch_passed INTEGER,
    processing_s REAL,
    result TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS motions_axis ON motions (axis, validated, id);
CREATE TABLE IF NOT EXISTS parameters (
    motion_id INTEGER NOT NULL REFERENCES motions (id) ON DELETE CASCADE,
    name TEXT NOT NULL, value REAL NOT NULL, std REAL, ci_low REAL, ci_high REAL, method TEXT,
    PRIMARY KEY (motion_id, name)
);
CREATE TABLE IF NOT EXISTS sensor_faults (
    motion_id INTEGER NOT NULL REFERENCES motions (id) ON DELETE CASCADE,
    sensor TEXT NOT NULL, kind TEXT NOT NULL,
    gain REAL, gain_low REAL, gain_high REAL, offset REAL, offset_low REAL, offset_high REAL
);
CREATE TABLE IF NOT EXISTS diagnoses (
    motion_id INTEGER NOT NULL REFERENCES motions (id) ON DELETE CASCADE,
    fault TEXT NOT NULL, parameters TEXT NOT NULL, evidence TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS diagnoses_motion ON diagnoses (motion_id);
"""


@dataclass(frozen=True)
class IdentificationAge:
    """How long the axis has gone without a validated identification.

    Attributes
    ----------
    motions : int
        Motions recorded after the last validated one (all motions when none is validated).
    seconds : float
        ``now`` minus the time of the last validated motion (of the first motion when none is).
    last_validated_id : int or None
    """

    motions: int
    seconds: float
    last_validated_id: int | None

    def too_old(self, max_motions: int, max_seconds: float) -> bool:
        """True when more than ``max_motions`` motions or ``max_seconds`` s passed without one."""
        return self.motions > max_motions or self.seconds > max_seconds


class History:
    """SQLite history of one or more axes.

    Parameters
    ----------
    path : str or Path
        Database file (created with its folder's existence required); ``":memory:"`` for a
        throw-away store.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = str(path)
        if self.path != ":memory:":
            parent = Path(self.path).expanduser().resolve().parent
            if not parent.is_dir():
                raise EstimatorInputError(f"history database {self.path}: folder {parent} does not exist")
        if self.path != ":memory:" and Path(self.path).is_file():
            with open(self.path, "rb") as f:
                head = f.read(16)
            if head and head != _MAGIC:  # never let SQLite touch (or a retry overwrite) a foreign file
                raise HistoryError(f"history database {self.path}: not an SQLite file (it starts with "
                                   f"{head[:8]!r}); expected a history written by the monitor, or a new file name")
        try:
            # check_same_thread off: an FMU's calls come from its master's worker threads (libcosim), one at a time
            self._db = sqlite3.connect(self.path, isolation_level=None, timeout=BUSY_TIMEOUT_S,
                                       check_same_thread=False)
            _retry(lambda: self._db.execute("PRAGMA journal_mode=WAL"))
            self._db.execute("PRAGMA synchronous=FULL")
            self._db.execute("PRAGMA foreign_keys=ON")
            _retry(self._create)
        except sqlite3.DatabaseError as exc:
            raise HistoryError(f"history database {self.path}: {_why(exc)}") from None

    def _create(self) -> None:
        with self._transaction():
            for stmt in _SCHEMA.split(";"):
                if stmt.strip():
                    self._db.execute(stmt)
            row = self._db.execute("SELECT value FROM meta WHERE key = 'schema_version'").fetchone()
            if row is None:
                self._db.execute("INSERT INTO meta VALUES ('schema_version', ?)", (str(SCHEMA_VERSION),))
            elif int(row[0]) != SCHEMA_VERSION:
                raise EstimatorInputError(
                    f"history database {self.path}: schema version {row[0]}, this program reads {SCHEMA_VERSION}")

    # -- writing -------------------------------------------------------------------
    @contextmanager
    def _transaction(self) -> Iterator[None]:
        self._db.execute("BEGIN IMMEDIATE")
        try:
            yield
            self._db.execute("COMMIT")  # may fail too (disk full): then roll back as well
        except BaseException:
            if self._db.in_transaction:
                self._db.execute("ROLLBACK")
            raise

    def record(self, axis: str, result: Mapping[str, Any], scenario: str = "", time: float | None = None) -> int:
        """Store one motion's result in one transaction.

        Parameters
        ----------
        axis : str
            Machine/axis id.
        result : mapping
            The per-motion result (module docstring); ``parameters`` and ``validated`` are required.
        scenario : str
            Scenario name or recording file.
        time : float, optional
            Machine clock at the end of the motion [s since the epoch]; default now.

        Returns
        -------
        int
            The motion's id in the database.
        """
        if not axis:
            raise EstimatorInputError("history: axis id must be a non-empty string")
        for key in ("parameters", "validated"):
            if key not in result:
                raise EstimatorInputError(f"history: motion result has no {key!r}")
        try:
            return _retry(lambda: self._record(axis, result, scenario, time))
        except sqlite3.DatabaseError as exc:
            raise HistoryError(f"history database {self.path}: motion {result.get('motion')} not stored: "
                               f"{_why(exc)}; the motions stored before are kept") from None

    def _record(self, axis: str, result: Mapping[str, Any], scenario: str, time: float | None) -> int:
        mismatch = result.get("mismatch") or {}
        payload = json.dumps(result, default=_jsonable, allow_nan=True)
        with self._transaction():
            cur = self._db.execute(
                'INSERT INTO motions (axis, scenario, motion, time, start, "end", validated, measurements_valid, '
                "method, gain_ratio, mismatch_test, mismatch_statistic, mismatch_p_value, mismatch_passed, "
                "processing_s, result) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (axis, scenario, result.get("motion"), _time.time() if time is None else float(time),
                 result.get("start"), result.get("end"), int(bool(result["validated"])),
                 _flag(result.get("measurements_valid")), result.get("method"), _num(result.get("gain_ratio")),
                 mismatch.get("test"), _num(mismatch.get("statistic")), _num(mismatch.get("p_value")),
                 _flag(mismatch.get("passed")), _num(result.get("processing_s")), payload))
            mid = cur.lastrowid
            self._db.executemany(
                "INSERT INTO parameters VALUES (?, ?, ?, ?, ?, ?, ?)",
                [(mid, name, float(p["value"]), _num(p.get("std")), *_pair(p.get("ci95")), result.get("method"))
                 for name, p in result["parameters"].items()])
            self._db.executemany(
                "INSERT INTO sensor_faults VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                [(mid, f["sensor"], f["kind"], _num(f.get("gain")), *_pair(f.get("gain_ci95")),
                  _num(f.get("offset")), *_pair(f.get("offset_ci95"))) for f in result.get("sensor_faults", ())])
            self._db.executemany(
                "INSERT INTO diagnoses VALUES (?, ?, ?, ?)",
                [(mid, d["fault"], json.dumps(list(d["parameters"])),
                  json.dumps(d.get("evidence", []), default=_jsonable))
                 for d in result.get("diagnosis", ())])
        return int(mid)

    # -- reading -------------------------------------------------------------------
    def _parameters(self, motion_ids: list[int]) -> dict[int, dict[str, dict]]:
        out: dict[int, dict[str, dict]] = {m: {} for m in motion_ids}
        if not motion_ids:
            return out
        marks = ",".join("?" * len(motion_ids))
        # the unit is kept in the motion's JSON (no schema change): a parameter reads back as it was stored
        for mid, name, value, std, lo, hi, unit in self._db.execute(
                "SELECT p.motion_id, p.name, p.value, p.std, p.ci_low, p.ci_high, "
                "json_extract(m.result, '$.parameters.\"' || p.name || '\".unit') FROM parameters p "
                f"JOIN motions m ON m.id = p.motion_id WHERE p.motion_id IN ({marks})", motion_ids):
            out[mid][name] = {"value": value, "std": std, "ci95": [lo, hi]} | ({"unit": unit} if unit else {})
        return out

    def _validated(self, axis: str, order: str, n: int | None, healthy: bool = False) -> list[dict]:
        limit = "" if n is None else f" LIMIT {int(n)}"
        undiagnosed = " AND NOT EXISTS (SELECT 1 FROM diagnoses WHERE motion_id = motions.id)" if healthy else ""
        rows = self._db.execute(
            f'SELECT id, motion, time, start, "end", method FROM motions WHERE axis = ? AND validated = 1'
            f"{undiagnosed} ORDER BY id {order}{limit}", (axis,)).fetchall()
        params = self._parameters([r[0] for r in rows])
        return [{"id": r[0], "motion": r[1], "time": r[2], "start": r[3], "end": r[4], "method": r[5],
                 "parameters": params[r[0]]} for r in rows]

    def last_validated(self, axis: str) -> dict | None:
        """theta_{j-1}: the newest validated motion of ``axis`` (``{"id", "time", "parameters", ...}``) or None."""
        rows = self._validated(axis, "DESC", 1)
        return rows[0] if rows else None

    def baseline(self, axis: str, n: int) -> list[dict]:
        """The healthy baseline: the first ``n`` validated motions of ``axis`` that had no diagnosis, oldest
        first (fewer when fewer exist). A motion diagnosed while the baseline was being built is skipped."""
        return self._validated(axis, "ASC", n, healthy=True)

    def recent_validated(self, axis: str, n: int) -> list[dict]:
        """The last ``n`` validated motions of ``axis``, oldest first."""
        return self._validated(axis, "DESC", n)[::-1]

    def age(self, axis: str, now: float) -> IdentificationAge:
        """Motions and seconds since the last validated identification of ``axis``; ``now`` [s since epoch]."""
        last = self._db.execute("SELECT id, time FROM motions WHERE axis = ? AND validated = 1 "
                                "ORDER BY id DESC LIMIT 1", (axis,)).fetchone()
        if last is None:
            n, first = self._db.execute("SELECT COUNT(*), MIN(time) FROM motions WHERE axis = ?", (axis,)).fetchone()
            return IdentificationAge(int(n), 0.0 if first is None else now - first, None)
        (n,) = self._db.execute("SELECT COUNT(*) FROM motions WHERE axis = ? AND id > ?", (axis, last[0])).fetchone()
        return IdentificationAge(int(n), now - last[1], int(last[0]))

    def motions(self, axis: str | None = None) -> list[dict]:
        """Every stored motion (of ``axis``, or all), oldest first, as the stored result dicts plus
        ``id``, ``axis``, ``scenario`` and ``time``."""
        where, args = ("WHERE axis = ?", (axis,)) if axis else ("", ())
        rows = self._db.execute(f"SELECT id, axis, scenario, time, result FROM motions {where} ORDER BY id", args)
        return [{**json.loads(r[4]), "id": r[0], "axis": r[1], "scenario": r[2], "time": r[3]} for r in rows]

    def stored_at(self, axis: str, times: list[float], tol: float = 1e-3) -> list[tuple[int, float]]:
        """``(id, time)`` of the stored motions of ``axis`` whose time is within ``tol`` seconds of one of
        ``times`` (a recording replayed into the same history: its motions' machine times repeat)."""
        out = []
        for t in times:
            out += self._db.execute("SELECT id, time FROM motions WHERE axis = ? AND time BETWEEN ? AND ? ORDER BY id",
                                    (axis, float(t) - tol, float(t) + tol)).fetchall()
        return [(int(i), float(t)) for i, t in out]

    def axes(self) -> list[str]:
        return [r[0] for r in self._db.execute("SELECT DISTINCT axis FROM motions ORDER BY axis")]

    def close(self) -> None:
        self._db.close()

    def __enter__(self) -> History:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _num(x: Any) -> float | None:
    return None if x is None else float(x)


def _flag(x: Any) -> int | None:
    return None if x is None else int(bool(x))


def _pair(x: Any) -> tuple[float | None, float | None]:
    return (None, None) if x is None else (float(x[0]), float(x[1]))


def _jsonable(x: Any) -> Any:
    if hasattr(x, "tolist"):
        return x.tolist()
    if hasattr(x, "to_dict"):
        return x.to_dict()
    raise TypeError(f"history: {type(x).__name__} is not JSON-serialisable")
