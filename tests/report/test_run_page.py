"""report.html of ``cosim run``: a healthy tool change, then the worn axis (paper Table I: Cd +50 %,
ft +75 %) on the same history, as a user runs the examples; and a run that fails.

The page must parse as HTML5 without error, load nothing from outside the file, embed every figure of
report.json, show report.json's parameter values, and show the worn axis's diagnosis with its evidence.
"""
from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest
from matplotlib.container import ErrorbarContainer
from matplotlib.dates import ConciseDateFormatter

from feeddrive.cosim.cli import main
from feeddrive.cosim.report import write_run_page
from feeddrive.cosim.trends import trend_figure, trend_series

_spec = importlib.util.spec_from_file_location("page_checks", Path(__file__).with_name("page_checks.py"))
checks = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(checks)
WEAR = {"bearing or slide-way wear", "lack or ageing of lubricating oil"}
#: worn_axis.yaml against tool_change.yaml: Cd 1.8 / 1.2, ft 0.035 / 0.02
TRUE_CHANGE = {"Cd": 0.5, "ft": 0.75}


@pytest.fixture(scope="module")
def runs(example_runs) -> dict[str, Path]:
    """``cosim run`` of tool_change.yaml then worn_axis.yaml into runs/ (one history, runs/history.sqlite): the
    session's runs of the examples (tests/conftest.py), read only."""
    return {name: example_runs["out"][name] for name in ("tool_change", "worn_axis")}


def load(run: Path) -> tuple[dict, object]:
    report = json.loads((run / "report.json").read_text(encoding="utf-8"))
    return report, checks.parse(run / "report.html")


@pytest.mark.parametrize("name", ["tool_change", "worn_axis"])
def test_page_parses_is_self_contained_and_embeds_every_figure(runs, name):
    report, root = load(runs[name])
    checks.assert_self_contained(runs[name] / "report.html", root)
    images = checks.embedded_images(root)
    plots = report["files"]["plots"]
    # profiles, currents, monitor motion, residue-input correlation, trends
    assert len(plots) == 5 and len(images) == len(plots)
    assert sorted(images) == sorted((runs[name] / p).read_bytes() for p in plots)
    assert report["files"]["page"] == "report.html"
    summary = {"".join(tr.find("th").itertext()): checks.cells(tr)[0]
               for tr in root.iter("tr") if tr.find("th") is not None and len(tr.findall("td")) == 1}
    assert summary["plant sha256"] == report["plant"]["sha256"] and summary["scenario"] == report["scenario"]
    assert summary["casadi"] == report["versions"]["casadi"]
    assert root.find(".//span[@id='status']").text == "ok"


@pytest.mark.parametrize("name", ["tool_change", "worn_axis"])
def test_parameter_table_equals_report_json(runs, name):
    report, root = load(runs[name])
    (motion,) = report["motions"]
    table = root.find(f".//table[@id='parameters-{motion['motion']}']")
    rows = table.findall(".//tr[@data-parameter]")
    assert [r.get("data-parameter") for r in rows] == list(motion["parameters"]) == ["R", "L", "K", "Jt", "ft", "Cd"]
    for row in rows:
        p = motion["parameters"][row.get("data-parameter")]
        assert float(row.get("data-value")) == p["value"]  # the exact value, not a rounding of it
        name_, unit, value, ci, std = checks.cells(row)[:5]
        assert unit == dict(R="Ohm", L="H", K="N.m/A", Jt="kg.m2", ft="N.m.s/rad", Cd="N.m")[name_]
        assert checks.numbers(value)[0] == pytest.approx(p["value"], rel=1e-5)
        assert checks.numbers(ci) == pytest.approx(p["ci95"], rel=1e-5)
        assert checks.numbers(std)[0] == pytest.approx(p["std"], rel=1e-2)


def test_worn_axis_diagnosis_is_shown_with_its_evidence(runs):
    report, root = load(runs["worn_axis"])
    (motion,) = report["motions"]
    assert motion["validated"] and {d["fault"] for d in motion["diagnosis"]} == WEAR
    (table,) = root.findall(".//table[@class='diagnosis']")
    assert set(table.get("data-faults").split("; ")) == WEAR
    evidence = {}  # wear and lubrication point at the same drifts: shown once, with both faults
    for diagnosis in motion["diagnosis"]:
        assert diagnosis["parameters"] == ["Cd", "ft"]
        for ev in diagnosis["evidence"]:
            assert evidence.setdefault(ev["parameter"], ev) == ev
    rows = table.findall(".//tr[@data-parameter]")
    assert [r.get("data-parameter") for r in rows] == ["Cd", "ft"]
    for row in rows:
        ev = evidence[row.get("data-parameter")]
        text = checks.cells(row)
        value, baseline, change, z_base = (checks.numbers(c)[0] for c in text[1:5])
        assert value == pytest.approx(ev["value"], rel=1e-5)
        assert baseline == pytest.approx(ev["baseline"], rel=1e-5)
        assert change / 100 == pytest.approx(ev["relative_change"], rel=1e-2)
        assert change / 100 == pytest.approx(TRUE_CHANGE[ev["parameter"]], abs=0.03)  # the injected wear
        assert z_base == pytest.approx(ev["z_baseline"], rel=1e-2) and z_base > 3.29
        assert set(text[-1].split("; ")) == WEAR
    status = {r.get("data-parameter"): r.get("class") for r in root.findall(".//table[@class='parameters']//tr")
              if r.get("data-parameter")}
    assert status == {"R": "healthy", "L": "healthy", "K": "healthy", "Jt": "healthy", "ft": "diagnosed",
                      "Cd": "diagnosed"}
    # the healthy run's page: everything healthy, the baseline being learnt from it
    _, healthy = load(runs["tool_change"])
    assert {r.get("class") for r in healthy.findall(".//table[@class='parameters']//tr") if r.get("data-parameter")
            } == {"healthy"}
    text = "".join(root.itertext())
    # judged on the monitor's CPU time; the wall time, which grows with the host's load, only shown
    assert motion["within_budget"] == (motion["processing_cpu_s"] <= 2.0)
    assert (f"{motion['processing_cpu_s']:.3g} s CPU time ({motion['processing_s']:.3g} s wall time) against the "
            "budget of 2 s") in text and "OVER BUDGET" not in text


def test_failed_run_still_gets_its_page(tmp_path, feeddrive_fmu, capsys):
    scenario = tmp_path / "broken.yaml"
    # L = 0 is refused when the scenario is read (outside the FMU's declared range, exit 2): an L in its range but
    # so small that the current's state overflows in the next step fails the run
    scenario.write_text("name: broken\nstep: 1.0e-4\nstop_time: 0.01\nplant: {fmu: builtin}\n"
                        "nc:\n  program:\n    - rapid: {to: 0.05}\n"
                        "events:\n  - {time: 0.005, target: plant.L, value: 1.0e-300}\nmonitor: {db: ':memory:'}\n")
    assert main(["run", str(scenario), "--no-progress", "--out", str(tmp_path / "out")]) == 1
    report, root = load(tmp_path / "out")
    checks.assert_self_contained(tmp_path / "out" / "report.html", root)
    assert report["status"] == "failed" and root.find(".//span[@id='status']").text == "failed"
    assert "".join(root.find(".//p[@id='error']").itertext()) == report["error"]
    assert "the state became non-finite in [0.005, 0.0051] s" in report["error"]
    # the statuses of a supervised run (a crashed or hung child process) render the same way
    for status in ("crashed", "hung"):
        write_run_page(tmp_path / "out", report | {"status": status, "error": f"child process {status}"})
        root = checks.parse(tmp_path / "out" / "report.html")
        assert root.find(".//span[@id='status']").get("class") == f"badge {status}"


def test_units_and_model_check_come_from_report_json(runs, tmp_path):
    """A report whose parameters carry a ``unit`` shows it; the model check is a table of its tests, with the
    Bonferroni level alpha/m named and a decision per test."""
    report, _ = load(runs["worn_axis"])
    motion = report["motions"][0]
    motion["parameters"]["K"]["unit"] = "V.s/rad"  # the same constant, seen from the voltage equation
    motion.pop("verdict", None)  # the run's own verdict is of its own check, not of the mismatch made up here
    motion["mismatch"] = {"test": "speed size", "statistic": 3.5, "p_value": 0.004, "alpha": 0.01, "passed": False,
                          "rule": "Bonferroni over 2 tests",
                          "checks": {"current": {"independence": {"statistic": 1.2, "df": [22.0, 130.0],
                                                                  "p_value": 0.25},
                                                 "rms": 0.03, "noise_std": None},
                                     "speed": {"size": {"statistic": 3.5, "df": [120.0, 34000.0], "p_value": 0.002},
                                               "rms": 0.09, "noise_std": 0.05}}}
    (tmp_path / "plots").mkdir()
    write_run_page(tmp_path, report | {"files": {"plots": []}})
    root = checks.parse(tmp_path / "report.html")
    k_row = root.find(".//tr[@data-parameter='K']")
    assert checks.cells(k_row)[1] == "V.s/rad"
    table = root.find(f".//table[@id='model-check-{motion['motion']}']")
    rows = {r.get("data-test"): checks.cells(r) for r in table.iter("tr") if r.get("data-test")}
    assert list(rows) == ["current independence", "speed size"]
    test, statistic, df, p, threshold, decision = rows["current independence"]
    assert test == "current residue independent of past inputs" and checks.numbers(statistic) == [1.2]
    assert checks.numbers(df) == [22, 130] and float(p) == 0.25 and float(threshold) == 0.005 and decision == "pass"
    assert rows["speed size"][-1] == "reject: mismatch" and float(rows["speed size"][4]) == 0.005
    text = " ".join("".join(root.itertext()).split())
    assert "alpha/m = 0.01/2 = 0.005 per test (Bonferroni" in text
    assert "Bonferroni-adjusted p = min(1, 2 p) = 0.004 < alpha = 0.01" in text
    assert "not checked: no confirmed redundant current sensor pair" in text and "nan" not in text.lower().split()
    # the verdict, first line of the motion: a mismatch outranks the diagnosis
    verdict = root.find(f".//span[@id='verdict-{motion['motion']}']")
    assert verdict.get("data-kind") == "model mismatch" and "bad" in verdict.get("class")
    assert verdict.text.startswith("model mismatch: the speed size test rejects")


def test_single_motion_trend_reads_well(runs):
    """One motion: integer motion axis, no offset notation, units, its CI, the baseline and the alarm band."""
    report, _ = load(runs["tool_change"])
    thresholds = report["components"]["monitor"]["diagnosis_thresholds"]
    fig = trend_figure(report["motions"], "axis X", thresholds)
    try:
        axes = [ax for ax in fig.axes if ax.get_visible()]
        assert len(axes) == 6
        series = trend_series(report["motions"], thresholds)
        fig.canvas.draw()  # tick labels and offsets are only set when drawn
        for ax in axes:
            name = ax.get_ylabel().split(" [")[0]
            assert ax.get_ylabel().endswith("]") and "[?]" not in ax.get_ylabel()
            assert ax.yaxis.get_major_formatter().get_offset() == ""
            assert all(float(t).is_integer() for t in ax.get_xticks() if ax.get_xlim()[0] <= t <= ax.get_xlim()[1])
            (bars,) = [c for c in ax.containers if isinstance(c, ErrorbarContainer)]
            segment = bars.lines[2][0].get_segments()[0]  # the CI of the one motion
            p = report["motions"][0]["parameters"][name]
            assert [segment[0][1], segment[1][1]] == pytest.approx(p["ci95"], rel=1e-12)
            s = series[name]
            half = max(thresholds["z_crit"] * math.hypot(p["std"], thresholds["baseline"][name]["std"]),
                       thresholds["min_relative"][name] * abs(thresholds["baseline"][name]["value"]))
            assert s["band_high"][0] - s["reference"][0] == pytest.approx(half, rel=1e-12)
            band = [ln for ln in ax.lines if ln.get_linestyle() == "--"]
            assert {round(float(np.nanmax(ln.get_ydata())), 12) for ln in band} == {
                round(s["band_low"][0], 12), round(s["band_high"][0], 12)}
        labels = set(fig.legends[0].texts and [t.get_text() for t in fig.legends[0].texts])
        assert {"healthy baseline", "alarm threshold", "validated estimate, 95 % CI"} <= labels
        assert not isinstance(axes[-1].xaxis.get_major_formatter(), ConciseDateFormatter)
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)


def test_a_nominal_baseline_is_said_on_the_run_page_and_the_history_page(example_runs, tmp_path):
    """worn_axis.yaml is judged against its nominal parameters (``monitor.baseline: nominal``). Its run page said
    "the mean of the first 3 validated motions without a diagnosis; 0 learnt so far", and its axis's history page
    "not learnt yet" in every baseline cell, beside two parameters diagnosed against the nominal values."""
    import shutil

    report, root = load(example_runs["out"]["worn_axis"])
    nominal = report["components"]["monitor"]["diagnosis_thresholds"]["baseline"]
    assert nominal["Cd"] == {"value": 1.2, "std": 0.0} and nominal["ft"] == {"value": 0.02, "std": 0.0}
    for page in (root, None):
        if page is None:  # the history page of the axis, from a copy of the examples' history
            db = tmp_path / "history.sqlite"
            shutil.copy(example_runs["work"] / "runs" / "history.sqlite", db)
            assert main(["history", str(db), "--axis", "worn-X", "--html", str(tmp_path / "h.html")]) == 0
            page = checks.parse(tmp_path / "h.html")
        source = page.find(".//*[@id='baseline-source']")
        assert source is not None and "nominal parameters" in "".join(source.itertext())
        text = "".join(page.itertext())
        assert "learnt so far" not in text and "not learnt yet" not in text
        table = page.find(".//*[@id='baseline']")
        rows = {c[0]: c for c in map(checks.cells, table.iter("tr")) if c}
        assert checks.numbers(rows["Cd"][2]) == [1.2] and checks.numbers(rows["ft"][2]) == [0.02]


def test_a_faulty_sensors_offset_has_its_unit(example_runs):
    """current_sensor_fault.yaml (Im1: gain 1.03, offset 0.2 A): the faulty-sensor table gave the offset and its
    interval without a unit."""
    _, root = load(example_runs["out"]["current_sensor_fault"])
    (table,) = [t for t in root.iter("table") if t.get("class") == "sensor-faults"]
    (row,) = [c for c in map(checks.cells, table.iter("tr")) if c]
    assert row[0] == "Im1" and row[3].endswith(" A"), row
    assert checks.numbers(row[3])[0] == pytest.approx(0.2, abs=0.01)
