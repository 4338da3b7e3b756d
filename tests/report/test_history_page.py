"""``cosim history --html``: a 20-motion drift history over three days, recorded by two ``cosim monitor``
calls (the second with ``--out``: its report.json holds the diagnosis thresholds), drawn with its
healthy baseline and alarm band.

Plant data: the closed-loop CasADi model with redundant sensors of tests/estimator/test_validation.py.
Truth: Cd (paper Table I: wear, lubrication) healthy for motions 1-6, +3.75 % for 7-10 (significant,
beyond half the alarm band but below the 5 % minimum change: drifting, not a fault), +10 % for
11-15, then +20 % with ft +30 % for 16-20.
"""
from __future__ import annotations

import importlib.util
import json
import math
import os
import time
from pathlib import Path

import numpy as np
import pytest
from matplotlib.dates import ConciseDateFormatter

from feeddrive.cosim.cli import main
from feeddrive.cosim.trends import trend_figure
from feeddrive.estimator.history import History

_spec = importlib.util.spec_from_file_location("page_checks", Path(__file__).with_name("page_checks.py"))
checks = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(checks)
_spec = importlib.util.spec_from_file_location(
    "validation_plant", Path(__file__).parents[1] / "estimator" / "test_validation.py")
plant = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(plant)
H, CD, FT = plant.H, plant.NOMINAL["Cd"], plant.NOMINAL["ft"]
PLATEAU = 0.3  # s at full speed: a ~2.2 s round trip, long enough for the monitor (min_motion_s 1 s)
COLUMNS = (("u", "u"), ("u_ref", "u_ref"), ("Im1", "Im1"), ("Im2", "Im2"), ("w_tach", "w_tach"),
           ("theta_enc", "theta_enc"))
MAP = ["--map", "time=time", "--map", "state=state", "--map", "voltage=u", "--map", "voltage_ref=u_ref",
       "--map", "current1=Im1", "--map", "current2=Im2", "--map", "speed=w_tach", "--map", "position=theta_enc"]


def changes(k: int) -> tuple:
    """The plant's parameter changes at motion k (1-based): the drift of the module docstring."""
    if k <= 6:
        return ()
    if k <= 10:
        return (("Cd", 1.0375 * CD, 0.0),)
    if k <= 15:
        return (("Cd", 1.10 * CD, 0.0),)
    return (("Cd", 1.20 * CD, 0.0), ("ft", 1.30 * FT, 0.0))


def recording(path: Path, motions: range, end_time: float) -> Path:
    """A Parquet table of the given motions (NC state 1) between idle stretches, modified at ``end_time``.

    Parquet, not CSV: the ~250 000 rows of a 10-motion part took ~3 s of CPU to write as text and as much to
    read back in each ``cosim monitor`` call; the CSV reader is tested on its own (tests/cosim/test_readers_*)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    idle = np.zeros((500, len(COLUMNS)))
    blocks, state = [], []
    for k in motions:
        m = plant.measure(plant.plant_motion(changes(k), PLATEAU), seed=100 + k)
        blocks += [idle, np.column_stack([m[s] for _, s in COLUMNS])]
        state += [0] * len(idle) + [1] * len(m["Im1"])
    blocks.append(idle)
    state += [0] * len(idle)
    data = np.vstack(blocks)
    table = {"time": np.arange(len(state)) * H} | {c: data[:, j] for j, (c, _) in enumerate(COLUMNS)}
    pq.write_table(pa.table(table | {"state": np.array(state, dtype=np.int8)}), path)
    os.utime(path, (end_time, end_time))  # the machine clock of cosim monitor: the file's modification time
    return path


@pytest.fixture(scope="module")
def drift(tmp_path_factory) -> dict:
    """Two ``cosim monitor --out`` calls three days apart on one history, then ``cosim history --html``."""
    work = tmp_path_factory.mktemp("drift")
    db, now = work / "history.sqlite", time.time()
    # the first call's results are read back from the history (the same dicts as its report.json would hold),
    # so that only the second one draws its figures
    rec = recording(work / "part1.parquet", range(1, 11), now - 3 * 86400)
    assert main(["monitor", str(rec), *MAP, "--db", str(db)]) == 0
    rec = recording(work / "part2.parquet", range(11, 21), now)
    # the figures of the last 2 motions (the default keeps 5: the page embeds whatever the report lists)
    assert main(["monitor", str(rec), *MAP, "--db", str(db), "--out", str(work / "out"), "--keep-traces", "2"]) == 0
    report = json.loads((work / "out" / "report.json").read_text(encoding="utf-8"))
    with History(db) as history:
        first = history.motions("X")[:10]
    page = work / "axis_X.html"
    assert main(["history", "--db", str(db), "--axis", "X", "--html", str(page)]) == 0
    return {"work": work, "db": db, "report": report, "motions": first + report["motions"], "page": page}


def test_monitor_page(drift):
    out, report = drift["work"] / "out", drift["report"]
    root = checks.parse(out / "report.html")
    checks.assert_self_contained(out / "report.html", root)
    images = checks.embedded_images(root)
    assert len(images) == 5  # the last 2 motions (--keep-traces): residues and correlations; the trends
    assert sorted(images) == sorted((out / p).read_bytes() for p in report["files"]["plots"])
    assert len(report["motions"]) == 10 and all(m["validated"] for m in report["motions"])
    for m in report["motions"]:
        rows = root.find(f".//table[@id='parameters-{m['motion']}']").findall(".//tr[@data-parameter]")
        assert {r.get("data-parameter"): float(r.get("data-value")) for r in rows} == {
            k: p["value"] for k, p in m["parameters"].items()}
        assert {r.get("data-parameter"): r.get("class") for r in rows}["Cd"] == "diagnosed"


def test_history_page_alarm_band_is_the_diagnosis_thresholds_of_report_json(drift):
    root = checks.parse(drift["page"])
    checks.assert_self_contained(drift["page"], root)
    assert len(checks.embedded_images(root)) == 2  # against calendar time and against motion number
    data = json.loads(root.find(".//script[@id='trend-data']").text)
    motions = drift["motions"]
    assert [m["motion"] for m in motions] == list(range(1, 11)) * 2
    final = drift["report"]["diagnosis_thresholds"]
    assert data["thresholds"]["baseline"] == final["baseline"] and data["thresholds"]["z_crit"] == final["z_crit"]
    assert final["z_crit"] == pytest.approx(3.2905, abs=1e-4) and final["baseline_learnt"] == 3
    for name in ("R", "L", "K", "Jt", "ft", "Cd"):
        s = data["trends"][name]
        assert s["number"] == list(range(1, 21))
        for j, m in enumerate(motions):
            p = m["parameters"][name]
            ref = m.get("drift_reference") or final  # the first motion had no reference: today's baseline
            b = ref["baseline"][name]
            half = max(ref["z_crit"] * math.hypot(p["std"], b["std"]), ref["min_relative"][name] * abs(b["value"]))
            assert s["reference"][j] == pytest.approx(b["value"], rel=1e-12)
            assert [s["band_low"][j], s["band_high"][j]] == pytest.approx([b["value"] - half, b["value"] + half],
                                                                          rel=1e-12)
            outside = not s["band_low"][j] <= s["value"][j] <= s["band_high"][j]
            # the band is exactly the diagnosis' test: outside it <=> diagnosed (first motion: nothing to test)
            assert s["diagnosed"][j] == (outside and m.get("drift_reference") is not None), (name, j + 1)
    # the motions' table colours each value as the band does: Cd +3.75 % (7-10) is drifting, not diagnosed
    table = root.find(".//table[@id='history']")
    colour = [{td.get("data-parameter"): td.get("class") for td in tr.findall("td[@data-parameter]")}
              for tr in table.iter("tr") if tr.find("td") is not None]
    assert [c["Cd"] for c in colour] == ["num healthy"] * 6 + ["num drifting"] * 4 + ["num diagnosed"] * 10
    assert {c["R"] for c in colour} == {c["K"] for c in colour} == {"num healthy"}
    diagnosed = [k for k, m in enumerate(motions, 1) if m["diagnosis"]]
    assert diagnosed == list(range(11, 21))  # +3.75 % is significant but below 5 %: not a fault
    cd = data["trends"]["Cd"]
    assert all(cd["diagnosed"][k - 1] for k in diagnosed)
    for k, truth in ((8, 0.0375), (13, 0.10), (18, 0.20)):
        assert cd["value"][k - 1] / cd["reference"][k - 1] - 1 == pytest.approx(truth, abs=0.01)
    assert all(data["trends"]["ft"]["diagnosed"][k - 1] for k in range(16, 21))
    # every diagnosis is listed with its evidence, at the machine time it occurred
    with History(drift["db"]) as history:
        when = {str(m["id"]): m["time"] for m in history.motions("X")}
    tables = root.findall(".//table[@class='diagnosis']")
    assert len(tables) == len({t.get("data-motion-id") for t in tables}) == 10
    for t, m in zip(tables, motions[10:]):
        caption = "".join(t.find("caption").itertext())
        assert caption.startswith(time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(when[t.get("data-motion-id")])))
        assert t.get("data-faults") == "; ".join(d["fault"] for d in m["diagnosis"]) and t.get("data-faults") in caption
        shown = {r.get("data-parameter"): checks.numbers(checks.cells(r)[3])[0] / 100
                 for r in t.findall(".//tr[@data-parameter]")}
        assert shown == pytest.approx({e["parameter"]: e["relative_change"]
                                       for d in m["diagnosis"] for e in d["evidence"]}, rel=1e-2)


def test_history_spanning_days_is_plotted_against_dates(drift):
    with History(drift["db"]) as history:
        motions = history.motions("X")
    span = motions[-1]["time"] - motions[0]["time"]
    assert 2.9 * 86400 < span < 3.1 * 86400
    fig = trend_figure(motions, "axis X", drift["report"]["diagnosis_thresholds"])
    try:
        bottom = fig.axes[4:]  # R, Jt / L, ft / K, Cd: the bottom row carries the time axis
        assert all(isinstance(ax.xaxis.get_major_formatter(), ConciseDateFormatter) for ax in bottom)
        assert [ax.get_xlabel() for ax in bottom] == ["machine time (UTC)"] * 2
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)
    text = "".join(checks.parse(drift["page"]).itertext())
    assert "Parameter trends against machine time (UTC)" in text and "Parameter trends against motion number" in text


def test_bad_requests_are_one_line_errors_before_anything_is_written(drift, capsys):
    work = drift["work"]
    capsys.readouterr()
    # an existing report is not replaced without --overwrite, and the history is not touched
    assert main(["monitor", str(work / "part2.parquet"), *MAP, "--db", str(work / "other.sqlite"),
                 "--out", str(work / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--out" in err and "--overwrite" in err and not (work / "other.sqlite").exists()
    before = drift["page"].read_bytes()
    assert main(["history", "--db", str(drift["db"]), "--html", str(drift["page"])]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and str(drift["page"]) in err and drift["page"].read_bytes() == before
    assert main(["history", "--db", str(work / "missing.sqlite"), "--html", str(work / "x.html")]) == 2
    assert "does not exist" in capsys.readouterr().err and not (work / "x.html").exists()
