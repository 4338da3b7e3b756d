"""The report pages in a real browser (headless Chromium from Debian): no horizontal scrolling at 1280 and
400 px, the model check's values inside the viewport, the verdict of a sensor-fault motion first and never
green, no ``nan`` in the rendered text.

Pages: ``cosim run`` of examples/tool_change.yaml (healthy) and examples/current_sensor_fault.yaml (Im1 3 %
gain and 0.2 A offset fault on its second motion) on one history, and that history's page.
Set ``FEEDDRIVE_SCREENS=<folder>`` to keep the screenshots (of the whole page then; else of the viewport only).
"""
from __future__ import annotations

import importlib.util
import json
import os
import re
import shutil
from pathlib import Path

import pytest

from feeddrive.cosim.cli import main

_here = Path(__file__).parent
_spec = importlib.util.spec_from_file_location("report_browser", _here / "browser.py")
browser = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(browser)
WIDTHS = (1280, 400)
#: the page's colours (report.html.j2): a fault's red, the healthy green
RED, GREEN = "rgb(248, 207, 207)", "rgb(216, 240, 216)"


@pytest.fixture(scope="module")
def chromium():
    exe = browser.find_chromium()
    if exe is None:
        pytest.skip("chromium not found: install the Debian package chromium (.ci/run does it when run as root)")
    b = browser.Browser(exe)
    yield b
    b.close()


@pytest.fixture(scope="module")
def pages(tmp_path_factory, example_runs) -> dict[str, Path]:
    """report.html of a healthy and of a sensor-fault run on one history, and the history's page.

    The runs are the session's ``cosim run`` of the examples (tests/conftest.py), read only: their pages, their
    report.json and their history are copied here, where the screenshots are written next to them."""
    work = tmp_path_factory.mktemp("browser")
    for name, scenario in (("healthy", "tool_change"), ("sensor_fault", "current_sensor_fault")):
        (work / "runs" / name).mkdir(parents=True)
        for file in ("report.html", "report.json"):
            shutil.copy(example_runs["out"][scenario] / file, work / "runs" / name / file)
    # the history both runs wrote to, wherever the run put it
    db = json.loads((work / "runs" / "sensor_fault" / "report.json").read_text())["components"]["monitor"]["db"]
    for file in Path(db).parent.glob(Path(db).name + "*"):  # with its -wal file, if one was left
        shutil.copy(file, work / file.name.replace(Path(db).name, "history.sqlite"))
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(work)
        # the sensor-fault example is its own machine (axis sensor-X): its two motions, healthy then faulty
        assert main(["history", "--db", "history.sqlite", "--axis", "sensor-X", "--html", "axis_X.html"]) == 0
    return {"healthy": work / "runs" / "healthy" / "report.html",
            "sensor_fault": work / "runs" / "sensor_fault" / "report.html", "history": work / "axis_X.html"}


@pytest.fixture(scope="module")
def loaded(chromium, pages) -> dict[tuple[str, int], dict]:
    out = {}
    keep = os.environ.get("FEEDDRIVE_SCREENS")
    for name, path in pages.items():
        for width in WIDTHS:
            # the whole page only when it is kept to be looked at: the checks read the rendered page itself
            page = out[name, width] = chromium.page(path, width, full=bool(keep))
            shot = path.with_name(f"{name}_{width}.png")
            shot.write_bytes(page["png"])
            if keep:
                Path(keep).mkdir(parents=True, exist_ok=True)
                shutil.copy(shot, Path(keep) / shot.name)
    return out


@pytest.mark.parametrize("name", ["healthy", "sensor_fault", "history"])
@pytest.mark.parametrize("width", WIDTHS)
def test_no_horizontal_scrolling(loaded, name, width):
    page = loaded[name, width]
    assert page["inner_width"] == width
    assert page["scroll_width"] <= width, f"{name} at {width} px is {page['scroll_width']} px wide"
    # every element ends inside the viewport, or inside a box that scrolls on its own (a wide table)
    wider = page["eval"]("""[...document.querySelectorAll('body *')].filter(e => {
        let p = e; while (p && p !== document.body) { if (getComputedStyle(p).overflowX === 'auto') return false;
                                                     p = p.parentElement; }
        return e.getBoundingClientRect().right > window.innerWidth + 0.5; }).map(e => e.tagName + '.' + e.className)""")
    assert wider == []
    text = page["eval"]("document.body.innerText")
    assert not re.search(r"\bnan\b", text, re.IGNORECASE)
    assert "OVER BUDGET" not in text
    # the PNG is the page at that width (what the lead looks at)
    assert page["png"][:8] == b"\x89PNG\r\n\x1a\n" and int.from_bytes(page["png"][16:20], "big") == width


def test_model_check_values_are_inside_the_viewport_at_1280(loaded):
    page = loaded["sensor_fault", 1280]
    cells = page["eval"]("""[...document.querySelectorAll('table.model-check td')].map(td => {
        const r = td.getBoundingClientRect(); return [td.textContent, r.left, r.right]; })""")
    assert len(cells) == 6 * (5 + 3)  # motion 1: 5 tests, motion 2 (no current noise level): 3 tests
    assert all(0 <= left and right <= 1280 for _, left, right in cells)
    assert {c[0] for c in cells[5::6]} == {"pass"}


def test_sensor_fault_motion_leads_with_its_verdict(loaded, pages):
    report = json.loads(pages["sensor_fault"].with_name("report.json").read_text(encoding="utf-8"))
    (fault,) = report["motions"][1]["sensor_faults"]
    assert fault["sensor"] == "Im1" and abs(fault["gain"] - 1.03) < 0.003 and abs(fault["offset"] - 0.2) < 0.01
    for width in WIDTHS:
        page = loaded["sensor_fault", width]
        first = page["eval"]("document.querySelector('#motion-2').innerText.split('\\n')[0]")
        assert first == (f"Motion 2: sensor fault: Im1 gain {fault['gain']:.4g}, offset {fault['offset']:.3g} A; "
                         "parameters estimated from Im2")
        assert page["eval"]("getComputedStyle(document.getElementById('verdict-2')).backgroundColor") == RED
        section = page["eval"]("document.querySelector('#motion-2').innerText")
        assert "validated, healthy" not in section and "measurements valid" not in section
        current = page["eval"]("[...document.querySelectorAll('#residues-2 tr[data-pair=current] td')]"
                               ".map(td => td.textContent)")
        assert current[6] == "no" and current[7].startswith("Im1 gain 1.03")
        # the healthy first motion of the same run is green
        assert page["eval"]("document.getElementById('verdict-1').dataset.kind") == "healthy"
        assert page["eval"]("getComputedStyle(document.getElementById('verdict-1')).backgroundColor") == GREEN
    healthy = loaded["healthy", 1280]
    assert healthy["eval"]("document.getElementById('verdict-1').textContent").startswith("healthy: validated")


def test_history_page_shows_each_motions_verdict_colour(loaded):
    page = loaded["history", 1280]
    rows = page["eval"]("""[...document.querySelectorAll('#history td.verdict')].map(td =>
        [td.dataset.kind, td.textContent, getComputedStyle(td).backgroundColor])""")
    assert [r[0] for r in rows] == ["healthy", "sensor fault"]
    assert rows[1][1].startswith("sensor fault: Im1 gain 1.03") and rows[1][2] == RED
    assert rows[0][2] == GREEN
