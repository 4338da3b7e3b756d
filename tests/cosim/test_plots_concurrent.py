"""Figures drawn fast without losing what they show (issue 23, item 5): the min/max envelope of long
traces and the figures drawn at the same time in forked processes."""
from __future__ import annotations

import multiprocessing
import os
from pathlib import Path

import numpy as np
import pytest

from feeddrive.cosim.figure_data import DISPLAY_BUCKETS, envelope
from feeddrive.cosim.plots import draw_concurrently, plot_run

needs_fork = pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(),
                                reason="no fork start method on this platform: figures are drawn in turn")


def test_envelope_keeps_each_runs_extremes_and_a_one_sample_spike():
    rng = np.random.default_rng(3)
    n = 35_017  # not a multiple of the buckets: the tail is kept whole
    t = np.arange(n) * 1e-4
    y = rng.normal(0.0, 0.05, n)
    y[12_345], y[20_000] = 10.0, -7.0  # one-sample spikes
    te, ye = envelope(t, y)
    assert ye.size <= 2 * DISPLAY_BUCKETS + 2 + n % DISPLAY_BUCKETS
    assert ye.size < n / 10
    assert np.all(np.diff(te) > 0)  # time order, no duplicates
    assert (te[0], ye[0], te[-1], ye[-1]) == (t[0], y[0], t[-1], y[-1])
    assert 10.0 in ye and te[np.argmax(ye)] == t[12_345]
    assert -7.0 in ye and te[np.argmin(ye)] == t[20_000]
    # every kept sample is a sample of the trace at its own time
    k = np.searchsorted(t, te)
    np.testing.assert_array_equal(y[k], ye)
    # each run of samples keeps its minimum and maximum: the line covers the same span in each pixel column
    size = n // DISPLAY_BUCKETS
    for b in range(0, DISPLAY_BUCKETS, 97):
        run = slice(b * size, (b + 1) * size)
        inside = (te >= t[run][0]) & (te <= t[run][-1])
        assert ye[inside].min() == y[run].min() and ye[inside].max() == y[run].max()


def test_envelope_returns_a_short_trace_whole():
    t, y = np.arange(2500.0), np.sin(np.arange(2500.0))
    te, ye = envelope(t, y)
    np.testing.assert_array_equal(te, t)
    np.testing.assert_array_equal(ye, y)


def _writer(folder: Path, k: int):
    def job() -> list[Path]:
        path = folder / f"f{k}.txt"
        path.write_text(str(os.getpid()))
        return [path]
    return job


@needs_fork
def test_draw_concurrently_keeps_the_order_of_the_jobs_and_draws_in_other_processes(tmp_path):
    paths = draw_concurrently([_writer(tmp_path, k) for k in range(5)], processes=2)
    assert paths == [tmp_path / f"f{k}.txt" for k in range(5)]
    pids = {int(p.read_text()) for p in paths}
    assert len(pids) == 2 and os.getpid() in pids  # one worker forked with the jobs, and this process


@needs_fork
def test_draw_concurrently_raises_a_childs_error_and_redraws_for_a_dead_child(tmp_path):
    parent = os.getpid()

    def fails() -> list[Path]:
        raise ValueError("plots: no such signal sensors.Im3")

    with pytest.raises(ValueError, match="no such signal sensors.Im3"):
        draw_concurrently([_writer(tmp_path, 0), fails], processes=2)

    def dies_in_a_child() -> list[Path]:
        if os.getpid() != parent:
            os._exit(3)  # e.g. killed: no result through the pipe
        return _writer(tmp_path, 1)()

    paths = draw_concurrently([_writer(tmp_path, 0), dies_in_a_child], processes=2)
    assert paths == [tmp_path / "f0.txt", tmp_path / "f1.txt"]
    assert int((tmp_path / "f1.txt").read_text()) == parent  # drawn again here


def _draw_in_a_daemon(folder: Path) -> None:
    draw_concurrently([_writer(folder, k) for k in range(3)], processes=2)


@needs_fork
def test_a_daemonic_process_draws_its_figures_itself(tmp_path):
    """A campaign's Pool or Dask worker is daemonic and may not fork: its figures are drawn in turn, no error."""
    worker = multiprocessing.get_context("fork").Process(target=_draw_in_a_daemon, args=(tmp_path,), daemon=True)
    worker.start()
    worker.join(120)
    assert worker.exitcode == 0
    assert {int((tmp_path / f"f{k}.txt").read_text()) for k in range(3)} == {worker.pid}


@needs_fork
def test_a_figure_drawn_in_a_child_is_the_figure_drawn_here(tmp_path):
    """The run's figures, drawn by a forked child, are byte for byte those drawn in this process."""
    n = 30_000
    t = np.arange(n) * 1e-4
    rng = np.random.default_rng(5)
    current = 10 * np.sin(2 * np.pi * t)
    signals = {"nc.state": np.r_[np.zeros(100), np.ones(n - 200), np.zeros(100)], "nc.motion": np.ones(n),
               "plant.current": current, "sensors.Im1": current + rng.normal(0, 0.05, n),
               "sensors.Im2": current + rng.normal(0, 0.05, n), "plant.voltage": 50 * np.cos(2 * np.pi * t)}
    here = plot_run(t, signals, tmp_path / "here", title="T")
    # the first job goes to the worker, the second is this process's share
    there = draw_concurrently([lambda: plot_run(t, signals, tmp_path / "there", title="T"), lambda: []],
                              processes=2)
    assert [p.name for p in here] == [p.name for p in there] == ["motion_1_profiles.png", "motion_1_currents.png"]
    for a, b in zip(here, there):
        assert a.read_bytes() == b.read_bytes()


def test_the_monitor_figures_are_sent_as_envelopes_and_drawn_the_same(tmp_path):
    """What a drawing process is sent of a monitor trace (cosim.figure_data.MotionFigure) is a fraction of it,
    needs no estimator, keeps a one-sample fault in a residue and in r = Im1 - Im2, and draws the same bytes."""
    import pickle

    from feeddrive.cosim.figure_data import motion_figure
    from feeddrive.cosim.monitor_pipeline import MotionTrace
    from feeddrive.cosim.monitor_plots import plot_motion
    from feeddrive.estimator.mismatch import MismatchResult, ResidueCheck
    from feeddrive.estimator.residue_tests import TestResult

    rng = np.random.default_rng(1)
    n = 20_000
    t = 0.3 + np.arange(n) * 1e-4
    im1, im2 = 5 * np.sin(3 * t) + rng.normal(0, 0.05, n), 5 * np.sin(3 * t) + rng.normal(0, 0.05, n)
    im1[7_777] += 2.0  # a one-sample fault of one sensor
    checks = {}
    for j, name in enumerate(("i_q",)):  # a model's own check: two panels (a DC axis's current and speed: four)
        residue = 0.05 * rng.standard_normal(n)
        residue[:40] = np.nan
        residue[12_345] = -1.5  # a one-sample spike of the residue
        checks[name] = ResidueCheck(name, {"independence": TestResult("independence", 1.0, (30.0, 80.0), 0.5)},
                                    0.05, 0.05, 10 * np.sin(4 * t + j), residue, rng.standard_normal((11, 2)) * 0.05,
                                    0.2)
    mm = MismatchResult("i_q independence", 1.0, 1.0, 0.01, True, "Bonferroni over 1 test", checks)
    trace = MotionTrace(1, t, {"Im1": im1, "Im2": im2}, None, mm, {"verdict": "healthy"})
    shown = motion_figure(trace)
    sent = pickle.dumps(shown)
    assert len(sent) < len(pickle.dumps(trace)) / 4  # 4 lines of ~2000 samples: 0.13 MB, not 0.8
    assert b"feeddrive.estimator" not in sent  # a drawing process unpickles it without importing the estimator
    te, r = shown.lines["r"]
    assert r.max() == (im1 - im2).max() and te[np.argmax(r)] == t[7_777]
    te, res = shown.lines["i_q residue"]
    assert np.nanmin(res) == -1.5 and te[np.nanargmin(res)] == t[12_345]
    # the figure with the most long series (the correlation figure draws none of them)
    assert plot_motion(trace, tmp_path / "whole.png").read_bytes() == plot_motion(shown, tmp_path / "sent.png").read_bytes()
