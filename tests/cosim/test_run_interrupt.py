"""Ctrl-C during ``cosim run``: what the run has is kept (standards: a failed run keeps its results up to the
failure). The supervising parent killed the run's child at once (SIGKILL), so an interrupted run left signals.csv
and no report.json, no report.html, no word of the motions already judged."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from feeddrive.cosim.supervise import last_recorded_time

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.mark.slow
def test_ctrl_c_keeps_the_motions_judged_and_the_signals_recorded(tmp_path, feeddrive_fmu):
    # two tool changes (motion 1 ends at 3.69 s); Ctrl-C once the second has started, as a terminal sends it: to
    # the whole process group (the command, its supervised child and its drawing processes)
    # started as from a terminal, which delivers Ctrl-C: an ignored SIGINT is inherited (a run started ignoring it,
    # nohup or &, ignores it too, by design), and an xdist worker may ignore it, depending on the tests it ran before
    handler = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        proc = subprocess.Popen([sys.executable, "-m", "feeddrive.cosim", "run",
                                 str(EXAMPLES / "current_sensor_fault.yaml"), "--no-progress", "--no-plots", "--out",
                                 "run"], cwd=tmp_path, start_new_session=True, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, env=os.environ | {"OPENBLAS_NUM_THREADS": "1"})
    finally:
        signal.signal(signal.SIGINT, handler)
    csv = tmp_path / "run" / "signals.csv"
    deadline = time.monotonic() + 120
    while (last_recorded_time(csv) or 0.0) < 4.2 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert proc.poll() is None, "the run ended before it could be interrupted"
    os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    until = last_recorded_time(csv)
    assert proc.returncode == 130 and err.strip().splitlines()[-1] == (
        f"cosim run: interrupted at t={until:.6g} s; signals.csv up to then, report.json (1 motion judged) in run"), err
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    assert report["status"] == "interrupted" and 4.2 <= until < 7.9
    assert report["recorded_until_s"] == pytest.approx(until) and report["error"].startswith("interrupted")
    # motion 1, judged before the interruption, is in the report as the monitor wrote it: Im1's injected
    # fault starts with motion 2 (current_sensor_fault.yaml), so motion 1 is validated and healthy
    (m,) = report["motions"]
    assert m["validated"] is True and not m["sensor_faults"] and m["parameters"]["R"]["value"] == pytest.approx(0.6, rel=0.01)
    t = np.loadtxt(csv, delimiter=",", skiprows=1, usecols=0)
    np.testing.assert_allclose(np.diff(t), 1e-4, rtol=1e-6)  # every row up to the last complete block
    page = (tmp_path / "run" / "report.html").read_text()
    assert 'id="status">interrupted<' in page and "interrupted (Ctrl-C / SIGINT) at t=" in page
    # motion 2 had started (at 4.19 s): never judged, and said so
    assert report["components"]["monitor"]["unfinished_motion"] == 2
    assert "motion 2: not judged: the run was interrupted inside it at" in page
