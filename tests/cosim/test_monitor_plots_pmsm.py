"""Paper Fig. 13, 14 on a PMSM (issue 25): the monitor's motion figure draws the q and d currents' and the speed's
measured, simulated and residue traces of the output-error check (estimator/model_check.py), said advisory."""
from __future__ import annotations

import numpy as np
import pytest

import feeddrive.cosim.monitor_plots as mp
from feeddrive.cosim.monitor_pipeline import MotionTrace
from feeddrive.estimator.mismatch import MismatchResult, ResidueCheck
from feeddrive.estimator.residue_tests import TestResult


def test_the_motion_figure_draws_each_pmsm_residue_against_its_noise(tmp_path, monkeypatch):
    """A check of the PMSM's three equations (what check_model_equations returns, built here: the figure is under
    test): each state's panel holds its measured and simulated traces and, on its right axis, its residue with
    +- its sensor noise; the decision is titled advisory; the correlation figure has one panel per residue."""
    rng = np.random.default_rng(0)
    t = np.arange(2000) * 1.25e-4
    noise = {"i_q": 0.06, "i_d": 0.05, "w": 0.3}
    checks = {}
    for j, (name, sd) in enumerate(noise.items()):
        residue = sd * rng.standard_normal(t.size)
        residue[:50] = np.nan  # the filter's transients are not tested
        test = TestResult("independence", 1.0, (30.0, 80.0), 0.4 + 0.1 * j)
        checks[name] = ResidueCheck(name, {"independence": test}, sd, sd, 10 * np.sin(40 * t + j), residue,
                                    rng.standard_normal((11, 3)) * 0.05, 0.2)
    mm = MismatchResult("i_q independence", 1.0, 1.0, 0.01, True, "Bonferroni over 3 tests", checks)
    trace = MotionTrace(1, t, {}, None, mm, {"output_error_check": {"deciding": False}, "verdict": "healthy"})
    figures = []
    monkeypatch.setattr(mp.plt, "close", figures.append)  # keep the figures to read what they draw
    assert mp.plot_motion(trace, tmp_path / "m.png").stat().st_size > 0
    assert mp.plot_correlation(trace, tmp_path / "c.png").stat().st_size > 0
    fig = figures[0]
    assert {"i_q [A]", "i_d [A]", "w [rad/s]", "residue [A]", "residue [rad/s]"} <= {a.get_ylabel() for a in fig.axes}
    assert "(advisory: the residue check decides)" in fig.axes[3].get_title()
    for name, check in checks.items():
        ax = next(a for a in fig.axes if any(line.get_label() == f"{name} residue" for line in a.get_lines()))
        line = next(line for line in ax.get_lines() if line.get_label() == f"{name} residue")
        assert np.nanmax(line.get_ydata()) == np.nanmax(check.residue)  # the envelope keeps the extremes
        bands = sorted(line.get_ydata()[0] for line in ax.get_lines() if line.get_linestyle() == ":")
        assert bands == [-noise[name], noise[name]]
    assert len(figures[1].axes) == 3  # one correlation panel per residue


def test_one_current_sensor_draws_its_current_where_the_pairs_residue_is(tmp_path, monkeypatch):
    """A recording with one current sensor (REGBOT): the first panel was an empty 0-1 axes holding the sentence
    "current residue: not checked"; it draws the motion's current, with that sentence as its title."""
    t = np.arange(500) * 1e-3
    current = 0.9 * np.exp(-((t - 0.19) / 0.02) ** 2) + 0.01 * np.sin(300 * t)
    why = "not checked: no second current sensor (Im2)"
    trace = MotionTrace(1, t, {"Im1": current}, None, None,
                        {"verdict": "not estimated: motion too short", "not_checked": {"current": why}})
    figures = []
    monkeypatch.setattr(mp.plt, "close", figures.append)
    mp.plot_motion(trace, tmp_path / "m.png")
    ax = figures[0].axes[0]
    (line,) = ax.get_lines()
    assert ax.get_ylabel() == "current [A]" and ax.get_title() == f"current residue: {why}"
    assert np.max(line.get_ydata()) == np.max(current) and np.min(line.get_ydata()) == np.min(current)
    assert ax.get_ylim()[1] > 0.9 and not ax.texts


def test_the_torque_pair_draws_its_residue(tmp_path, monkeypatch):
    """A torque measurement and its command (``torque_ref``, HSM150): the first panel said "current residue: not
    checked: a torque signal replaces the current sensors" above the measured torque, while the pair it did check
    disagreed; it draws the pair's residue, titled with the pair's decision."""
    t = np.arange(2000) * 1e-3
    command = 0.05 * np.sign(np.sin(3 * t))
    measured = 0.82 * command + 0.008
    fault = {"sensor": "torque or torque_ref", "kind": "gain+offset", "gain": 0.82, "offset": 0.008}
    trace = MotionTrace(1, t, {"torque": measured, "torque_ref": command}, None, None,
                        {"verdict": "sensor fault", "sensor_faults": [fault],
                         "not_checked": {"current": "not checked: a torque signal replaces the current sensors"}})
    figures = []
    monkeypatch.setattr(mp.plt, "close", figures.append)
    mp.plot_motion(trace, tmp_path / "m.png")
    ax = figures[0].axes[0]
    (line,) = ax.get_lines()
    assert line.get_label() == "r = torque - torque_ref" and ax.get_ylabel() == "residue [N.m]"
    assert np.max(line.get_ydata()) == pytest.approx(np.max(measured - command))
    assert ax.get_title() == "torque pair: sensor fault, gain+offset (not isolated)"
