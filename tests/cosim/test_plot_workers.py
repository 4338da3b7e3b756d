"""The run's drawing processes (issue 23): forked when the run starts, they draw the figures it sends at its
end, in the order asked, the same bytes as drawn here; a failure is raised here, a dead worker's figure is
drawn here, and no process is left behind."""
from __future__ import annotations

import functools
import multiprocessing
import os
import pickle
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from feeddrive.cosim.figure_data import DISPLAY_BUCKETS
from feeddrive.cosim.figure_jobs import FigureBatch, FigureJob, run_figure_jobs
from feeddrive.cosim.plot_workers import PlotWorkers

needs_fork = pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(),
                                reason="no fork start method on this platform: figures are drawn in turn")


def write_pid(path: Path) -> list[Path]:
    """A job: the file names the process that wrote it."""
    path.write_text(str(os.getpid()))
    return [path]


def slow_write_pid(path: Path, seconds: float) -> list[Path]:
    time.sleep(seconds)
    return write_pid(path)


def fail(message: str) -> list[Path]:
    raise ValueError(message)


def die(path: Path, parent: int) -> list[Path]:
    if os.getpid() != parent:
        os.kill(os.getpid(), signal.SIGKILL)  # e.g. the OOM killer: no result through the pipe
    return write_pid(path)


def _children(pid: int) -> set[int]:
    """Processes whose parent is ``pid`` (Linux /proc); empty elsewhere."""
    out = set()
    for entry in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = entry.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] != "Z":
            out.add(int(entry.parent.name))
    return out


@needs_fork
def test_workers_draw_in_order_in_other_processes_and_leave_nothing_behind(tmp_path):
    before = _children(os.getpid())
    with PlotWorkers(processes=2) as workers:
        jobs = [FigureJob(__name__, "write_pid", (tmp_path / f"f{k}.txt",)) for k in range(5)]
        here = tmp_path / "here.txt"
        jobs.insert(2, lambda: write_pid(here))  # not a FigureJob (a user component's write_plots): drawn here
        meanwhile = []  # the run's own work while the workers draw (report.html's template)
        paths = workers.draw(jobs, meanwhile=lambda: meanwhile.append(os.getpid()))
    assert meanwhile == [os.getpid()]
    assert paths == [tmp_path / "f0.txt", tmp_path / "f1.txt", here] + [tmp_path / f"f{k}.txt" for k in range(2, 5)]
    assert int(here.read_text()) == os.getpid()
    pids = {int((tmp_path / f"f{k}.txt").read_text()) for k in range(5)}
    assert os.getpid() not in pids and 1 <= len(pids) <= 2
    # the first worker was waited for, the others were its children: no new child is left. A child an earlier
    # test in this xdist worker left exiting (a run's drawing processes close without waiting) may be gone now.
    assert _children(os.getpid()) <= before


def _all_children(pid: int) -> set[int]:
    """Processes whose parent is ``pid``, zombies (exited, not yet waited for) included."""
    out = set()
    for entry in Path("/proc").glob("[0-9]*/stat"):
        try:
            if int(entry.read_text().rsplit(")", 1)[1].split()[1]) == pid:
                out.add(int(entry.parent.name))
        except (OSError, IndexError, ValueError):
            continue
    return out


@needs_fork
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="no /proc: the children cannot be listed")
def test_idle_workers_closed_without_waiting_exit_and_are_reaped(tmp_path):
    """The run's end (``close(wait=False)``): the idle workers are told to exit and reaped in the background,
    none is left running or as a zombie."""
    before = _all_children(os.getpid())
    workers = PlotWorkers(processes=2, warm=False)
    paths = workers.draw([FigureJob(__name__, "write_pid", (tmp_path / f"f{k}.txt",)) for k in range(3)])
    workers.close(wait=False)
    workers.close()  # then nothing is left to close (the run's finally)
    assert paths == [tmp_path / f"f{k}.txt" for k in range(3)]
    assert os.getpid() not in {int(path.read_text()) for path in paths}
    deadline = time.monotonic() + 30
    while _all_children(os.getpid()) - before and time.monotonic() < deadline:
        time.sleep(0.02)
    assert _all_children(os.getpid()) - before == set()


@needs_fork
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="no /proc: the children cannot be listed")
def test_workers_forked_before_a_child_draw_for_it_and_their_forker_reaps_them(tmp_path):
    """``cosim run``: the drawing processes are forked first, the run is a child forked after; the child draws with
    them and ends them (it is not their parent: it reaps nothing), the first process reaps them: none is left."""
    before = _all_children(os.getpid())
    workers = PlotWorkers(processes=2, warm=False)
    pid = os.fork()
    if pid == 0:  # the run's supervised child
        code = 1
        try:
            paths = workers.draw([FigureJob(__name__, "write_pid", (tmp_path / f"f{k}.txt",)) for k in range(3)])
            workers.close()  # waits for them to exit (as the run's finally does on a failure), reaps nothing
            code = 0 if paths == [tmp_path / f"f{k}.txt" for k in range(3)] else 2
        finally:
            os._exit(code)
    assert os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]) == 0
    workers.close()
    drawn_by = {int((tmp_path / f"f{k}.txt").read_text()) for k in range(3)}
    assert not drawn_by & {os.getpid(), pid}  # by the workers, not by the child itself
    assert _all_children(os.getpid()) - before == set()  # reaped at close(): no zombie either


@needs_fork
def test_a_workers_error_is_raised_here_and_a_dead_workers_figure_is_drawn_here(tmp_path):
    workers = PlotWorkers(processes=2)
    try:
        with pytest.raises(ValueError, match="no such signal sensors.Im3"):
            workers.draw([FigureJob(__name__, "fail", ("plots: no such signal sensors.Im3",))])
        paths = workers.draw([FigureJob(__name__, "die", (tmp_path / "f0.txt", os.getpid())),
                              FigureJob(__name__, "write_pid", (tmp_path / "f1.txt",))])
    finally:
        workers.close()
    assert paths == [tmp_path / "f0.txt", tmp_path / "f1.txt"]
    assert int((tmp_path / "f0.txt").read_text()) == os.getpid()  # drawn again here


def _draw_in_a_daemon(folder: Path) -> None:
    with PlotWorkers(processes=2) as workers:
        workers.draw([FigureJob(__name__, "write_pid", (folder / f"f{k}.txt",)) for k in range(3)])


@needs_fork
def test_a_daemonic_process_has_no_workers_and_draws_its_figures_itself(tmp_path):
    """A campaign's Pool or Dask worker is daemonic and may not fork: its figures are drawn in turn, no error."""
    worker = multiprocessing.get_context("fork").Process(target=_draw_in_a_daemon, args=(tmp_path,), daemon=True)
    worker.start()
    worker.join(120)
    assert worker.exitcode == 0
    assert {int((tmp_path / f"f{k}.txt").read_text()) for k in range(3)} == {worker.pid}


@needs_fork
def test_the_run_figures_drawn_by_a_worker_are_those_drawn_here(tmp_path):
    """Each figure job carries only its motion's traces, as envelopes (kB, not the motion's MB) that keep a
    one-sample spike; a worker draws the bytes drawn here (plot_run draws the same jobs)."""
    n = 30_000
    t = np.arange(n) * 1e-4
    rng = np.random.default_rng(5)
    current = 10 * np.sin(2 * np.pi * t)
    state = np.r_[np.zeros(100), np.ones(n // 2 - 200), np.zeros(200), np.ones(n // 2 - 200), np.zeros(100)]
    signals = {"nc.state": state, "nc.motion": np.r_[np.ones(n // 2), 2 * np.ones(n // 2)],
               "plant.current": current, "sensors.Im1": current + rng.normal(0, 0.05, n),
               "sensors.Im2": current + rng.normal(0, 0.05, n), "plant.voltage": 50 * np.cos(2 * np.pi * t),
               "plant.position": np.cumsum(current)}
    signals["sensors.Im1"][n // 4] += 30.0  # a one-sample spike of one sensor: in its trace and in the residue
    jobs = run_figure_jobs(t, signals, tmp_path / "there", title="T")
    assert all("plant.position" not in job.args[1] for job in jobs)  # not drawn: not sent
    motion = np.flatnonzero(state == 1)[: n // 2 - 200]
    for job in jobs[:2]:  # motion 1's figures
        for name, (te, ye) in job.args[1].items():
            assert te[0] == t[motion[0]] and te[-1] == t[motion[-1]]  # the motion's span, not the other's
            assert ye.size <= 2 * DISPLAY_BUCKETS + 2 + motion.size % DISPLAY_BUCKETS < motion.size
        assert len(pickle.dumps(job)) < 400_000  # the motion's 6 traces whole: 1.1 MB
    im1, residue = jobs[1].args[1]["sensors.Im1"], jobs[1].args[1]["residue"]
    assert im1[1].max() == signals["sensors.Im1"][motion].max() and im1[0][np.argmax(im1[1])] == t[n // 4]
    full = signals["sensors.Im1"][motion] - signals["sensors.Im2"][motion]
    assert residue[1].max() == full.max() and jobs[1].args[2] == pytest.approx(full.mean(), rel=1e-12)
    names = ["motion_1_profiles.png", "motion_1_currents.png", "motion_2_profiles.png", "motion_2_currents.png"]
    assert [job.args[-2].name for job in jobs] == names
    # motion 2's figures (half the drawing: the test's time) drawn here, as plot_run does, and by the workers
    here = [path for job in run_figure_jobs(t, signals, tmp_path / "here", title="T")[2:] for path in job()]
    with PlotWorkers(processes=2) as workers:
        there = workers.draw(jobs[2:])
    assert [p.name for p in here] == [p.name for p in there] == names[2:]
    for a, b in zip(here, there):
        assert a.read_bytes() == b.read_bytes()


@needs_fork
def test_jobs_submitted_while_the_run_goes_on_take_one_idle_worker_and_are_returned_in_their_place(tmp_path):
    """A motion's figures are sent when it ends (``submit``): to one idle worker (the simulation keeps the other
    CPU), a batch drawn there in turn; ``draw`` returns their files where the submitted jobs stand. A job submitted
    while a worker draws waits for ``draw``; a submitted job's error is raised by ``draw``; a dead worker's
    submitted figures are drawn here."""
    job = functools.partial(FigureJob, __name__)
    with PlotWorkers(processes=2, warm=False) as workers:
        workers.draw([job("write_pid", (tmp_path / "first.txt",))])  # a worker has said it is ready
        early = workers.submit(FigureBatch((job("slow_write_pid", (tmp_path / "a.txt", 0.3)),
                                            job("write_pid", (tmp_path / "b.txt",)))))
        later = workers.submit(job("write_pid", (tmp_path / "c.txt",)))
        assert early.sent and not later.sent
        paths = workers.draw([job("write_pid", (tmp_path / "d.txt",)), early, later])
        assert paths == [tmp_path / f"{name}.txt" for name in "dabc"]
        pids = {name: int((tmp_path / f"{name}.txt").read_text()) for name in "abcd"}
        assert pids["a"] == pids["b"] != os.getpid() and os.getpid() not in pids.values()
        failed = workers.submit(job("fail", ("plots: no such signal sensors.Im3",)))
        assert failed.sent
        with pytest.raises(ValueError, match="no such signal sensors.Im3"):
            workers.draw([failed])
        dead = workers.submit(job("die", (tmp_path / "e.txt", os.getpid())))
        assert dead.sent
        assert workers.draw([dead]) == [tmp_path / "e.txt"]
    assert int((tmp_path / "e.txt").read_text()) == os.getpid()  # drawn again here


@needs_fork
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="no /proc: the children cannot be listed")
def test_abandoned_workers_are_ended_at_once_and_reaped():
    """``cosim run`` failing before its run drew (a bad scenario): the workers, still warming up, are ended and
    reaped at once, not waited for."""
    before = _all_children(os.getpid())
    workers = PlotWorkers(processes=2, preload=("feeddrive.cosim.plots",))
    pid = workers._pid
    workers.abandon()
    workers.abandon()  # nothing left to end
    workers.close()
    assert pid is not None and _all_children(os.getpid()) - before == set()
