"""A motion whose recording has no redundant pair (a torque and a speed, HSM150-like) is not shown as validated
measurements: nothing was checked, and the page says what replaced the current sensors (found by audit2)."""
from __future__ import annotations

import re
from pathlib import Path

from feeddrive.cosim.report.page import render_run

TORQUE_ONLY = {
    "motion": 1, "start": 0.06, "end": 20.0, "validated": True, "measurements_valid": True, "residues": {},
    "sensor_faults": [], "gain_ratio": None, "diagnosis": [], "notes": [], "refused": {},
    "parameters": {"ft": {"value": 4.9e-5, "std": 7e-6, "ci95": [3.5e-5, 6.3e-5], "unit": "N.m.s/rad"}},
    "not_checked": {"current": "not checked: a torque signal replaces the current sensors",
                    "voltage": "not checked: no terminal voltage (u) and no voltage reference (u_ref)"},
}


def text_of(html: str, start: str, length: int = 600) -> str:
    i = html.index(start)
    return " ".join(re.sub("<[^>]+>", " ", html[i:i + length]).split())


def test_nothing_checked_is_not_called_valid():
    html = render_run({"scenario": "hsm", "status": "ok", "kind": "monitor", "motions": [TORQUE_ONLY]}, Path("."))
    heading = text_of(html, "<h3>Measurement validation")
    assert heading.startswith("Measurement validation: no redundant pair to check"), heading
    assert "measurements valid" not in heading
    assert 'class="badge not-judged" id="validation-1"' in html  # grey, not the green of a checked pair
    assert "current gain ratio a1/a2 (eq. 12) not checked: a torque signal replaces the current sensors" in heading
