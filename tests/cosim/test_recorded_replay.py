"""A run's own signals.csv replayed (``cosim monitor``/``cosim estimate``): dated by the run, not by the file.

The motions of a replay were dated by the file's modification time taken as the end of the recording: a copy,
a pandas round trip or a ``touch`` moved them in the history. signals.meta.json carries the machine time of the
run's first row (``start_utc``), which dates them whatever the file's modification time.
"""
from __future__ import annotations

import datetime as dt
import json
import os
from pathlib import Path

import numpy as np
import pytest

from feeddrive.cosim.errors import InputError
from feeddrive.cosim.recorded import load_recording, start_clock
from feeddrive.cosim.recorder import Sampling, sidecar_path, write_sampling_sidecar

RUN_START = dt.datetime(2026, 3, 1, 8, 30, 15, 250000, tzinfo=dt.timezone.utc).timestamp()


def run_signals(folder: Path) -> Path:
    """A run's signals.csv (0.1 ms rows from t = 0) and its sidecar, written as ``cosim run`` writes them; the
    file's modification time a day after the run, as a later copy would have it."""
    path = folder / "signals.csv"
    t = np.arange(50) * 1e-4
    np.savetxt(path, np.column_stack([t, np.sin(t), np.cos(t)]), delimiter=",",
               header="time [s],sensors.w_tach [rad/s],sensors.Im1 [A]", comments="", fmt="%.10g")
    write_sampling_sidecar(path, 1e-4, {"sensors.w_tach": Sampling("instant", 1e4)}, start=RUN_START)
    os.utime(path, (RUN_START + 86400, RUN_START + 86400))
    return path


def test_a_runs_signals_are_dated_by_the_runs_start_not_the_files_time(tmp_path: Path) -> None:
    path = run_signals(tmp_path)
    rec = load_recording(path, {"time": "time", "speed": "sensors.w_tach", "current1": "sensors.Im1"})
    clock, source = start_clock(rec)
    assert clock == pytest.approx(RUN_START, abs=1e-6)  # the file's time would give a day later, minus 4.9 ms
    assert source == f"start_utc of {sidecar_path(path)} (the machine time of the run's first row)"
    assert start_clock(rec, "2024-01-01T00:00:00Z")[0] == dt.datetime(2024, 1, 1, tzinfo=dt.timezone.utc).timestamp()


def test_a_sidecar_without_the_start_or_with_a_wrong_one(tmp_path: Path) -> None:
    """An earlier version's sidecar (no start_utc) leaves the file's time, said so; an unreadable one is one line
    naming the file and the key."""
    path = run_signals(tmp_path)
    side = sidecar_path(path)
    doc = json.loads(side.read_text())
    side.write_text(json.dumps({k: v for k, v in doc.items() if k != "start_utc"}))
    rec = load_recording(path, {"time": "time", "speed": "sensors.w_tach"})
    clock, source = start_clock(rec)
    assert clock == pytest.approx(RUN_START + 86400 - 49e-4, abs=1e-6) and source.startswith("file modification")
    side.write_text(json.dumps(doc | {"start_utc": "2026-03-01 08:30"}))
    with pytest.raises(InputError, match=r"signals.meta.json: start_utc '2026-03-01 08:30': expected an ISO 8601 "
                                         r"time with its zone"):
        start_clock(rec)
