"""Trend panels: the scale is set by the data and the band together, and sensor faults and model mismatches
are marked on every panel (cosim/trends.py)."""
from __future__ import annotations

import matplotlib.pyplot as plt
import pytest

from feeddrive.cosim.trends import BAND_ZOOM, trend_figure

THRESHOLDS = {"z_crit": 3.29, "min_relative": dict.fromkeys(("R", "L", "K", "Jt", "ft", "Cd"), 0.05),
              "baseline": {"R": {"value": 0.6, "std": 5e-5}}}


def motion(value: float, **kw) -> dict:
    """A validated motion whose R has a CI of +-0.01 % (the 5 % band is 500 times wider)."""
    return {"validated": True, "parameters": {"R": {"value": value, "std": 3e-5, "ci95": [value - 6e-5, value + 6e-5],
                                                    "unit": "Ohm"}}} | kw


@pytest.fixture
def figure():
    figs = []

    def make(motions, thresholds=THRESHOLDS):
        figs.append(trend_figure(motions, "axis X", thresholds))
        return figs[-1].axes[0]

    yield make
    for f in figs:
        plt.close(f)


def test_narrow_cis_are_not_squashed_by_the_band(figure):
    ax = figure([motion(0.6), motion(0.60008), motion(0.59995)])
    lo, hi = ax.get_ylim()
    data = 0.60008 + 6e-5 - (0.59995 - 6e-5)
    assert data / (hi - lo) > 0.6  # the CIs fill the panel, not one line in the band
    assert lo > 0.6 * 0.95 and hi < 0.6 * 1.05  # so the band's edges are off this scale, and said so
    (note,) = [t.get_text() for t in ax.texts]
    assert note.startswith("alarm thresholds 0.57") and note.endswith("off this scale")


def test_band_is_drawn_whole_when_comparable_to_the_data(figure):
    # a drift of 4 %: data spread 0.024 against a band 0.06 wide (< BAND_ZOOM times): both in view
    ax = figure([motion(0.6), motion(0.624)])
    lo, hi = ax.get_ylim()
    assert (0.624 + 6e-5 - 0.6 + 6e-5) * BAND_ZOOM > 0.06
    assert lo < 0.57 and hi > 0.63 and not ax.texts


def test_sensor_faults_and_mismatches_are_marked(figure):
    fault = [{"sensor": "Im1", "kind": "gain+offset", "gain": 1.03, "offset": 0.2}]
    ax = figure([motion(0.6), motion(0.6001, sensor_faults=fault),
                 motion(0.5999, validated=False, mismatch={"passed": False, "test": "speed size"})])
    marks = {ln.get_label(): list(ln.get_xdata()) for ln in ax.lines if ln.get_label() in ("sensor fault",
                                                                                           "model mismatch")}
    assert marks == {"sensor fault": [2.0], "model mismatch": [3.0]}
    labels = {t.get_text() for t in ax.figure.legends[0].texts}
    assert {"sensor fault", "model mismatch"} <= labels
