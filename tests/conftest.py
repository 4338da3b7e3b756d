"""Shared fixtures. FMUs are built into pytest's temporary directory, never into ~/.cache."""
from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

# one BLAS thread per process, as the cosim command sets (cosim/cli BLAS_THREADS), before anything loads numpy (the
# xdist workers inherit it): OpenBLAS's threads of two workers on two cores spun against each other, and the
# residue tests' Monte Carlo took 22 s instead of 2
from feeddrive.cosim.cli import BLAS_THREADS  # noqa: F401 - sets them (it imports no numerical module)
from feeddrive.fmu_build import builtin_fmu


def pytest_configure(config: pytest.Config) -> None:
    """Byte-compile the project once: the tests start ~150 Python processes (the CLI, drawing and campaign
    workers), and with ``PYTHONDONTWRITEBYTECODE`` set (as on this machine and in CI) each one compiled every
    module it imported from source again (~0.25 s of CPU each). compileall writes the cache whatever that
    variable says, and only what is out of date."""
    import compileall

    import feeddrive.estimator

    root = Path(feeddrive.estimator.__file__).resolve().parents[1]
    for folder in ("models", "fmu_build", "estimator", "cosim"):
        compileall.compile_dir(root / folder, quiet=2)


def _module_seconds() -> dict[str, float]:
    """tests/module_seconds.txt: test module (path from the repository root) -> seconds of a full run."""
    out = {}
    for line in (Path(__file__).parent / "module_seconds.txt").read_text(encoding="utf-8").splitlines():
        if line.strip() and not line.startswith("#"):
            seconds, module = line.split()
            out[module] = float(seconds)
    return out


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The slowest modules first (tests/module_seconds.txt), each module's tests together and in their order.

    With two xdist workers the run's end is what costs: in collection order a long module could start last
    and leave one core idle while it finished. pyproject's ``--dist loadscope`` gives whole modules to the
    workers in this order (a module's fixtures set up once, on one worker), so both start on the long ones
    and finish on short ones. Every worker sorts its collection alike, as xdist requires."""
    seconds = _module_seconds()
    first: dict[str, int] = {}
    for k, item in enumerate(items):
        first.setdefault(item.nodeid.split("::")[0], k)
    items.sort(key=lambda item: (-seconds.get(item.nodeid.split("::")[0], 0.0), first[item.nodeid.split("::")[0]]))


def _cpu_seconds() -> float:
    """CPU seconds (user + system) of this process and of the child processes it has waited for (the CLI's,
    drawing, campaign and compiler processes the tests start)."""
    import resource

    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


_CPU_START = pytest.StashKey[float]()


@pytest.hookimpl(wrapper=True)
def pytest_runtest_setup(item: pytest.Item):
    item.stash[_CPU_START] = _cpu_seconds()
    return (yield)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item: pytest.Item):
    item.stash[_CPU_START] = _cpu_seconds()
    return (yield)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_teardown(item: pytest.Item):
    item.stash[_CPU_START] = _cpu_seconds()
    return (yield)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo):
    """Each phase's report carries ``cpu_s``, the CPU seconds the phase took (a plain attribute: xdist sends it
    to the controller with the report). On a loaded machine a test's wall time measures the load as much as
    the test; its CPU time does not."""
    report = yield
    if _CPU_START in item.stash:
        report.cpu_s = _cpu_seconds() - item.stash[_CPU_START]
    return report


_BUSY: dict[str, list[float]] = {}


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    """Each worker's (``-n 0``: this process's) test time, CPU time, first start and last stop (for the summary)."""
    node = getattr(report, "node", None)
    busy = _BUSY.setdefault(node.gateway.id if node is not None else "main", [0.0, 0.0, report.start, report.stop])
    busy[0] += report.duration
    busy[1] += getattr(report, "cpu_s", 0.0)
    busy[2], busy[3] = min(busy[2], report.start), max(busy[3], report.stop)


def pytest_terminal_summary(terminalreporter) -> None:  # noqa: ANN001 - pytest's TerminalReporter
    """One line per xdist worker: seconds in its tests (setup + call + teardown), the CPU seconds they took (its
    own and its waited-for child processes'), and from its first test's start to its last one's end. With
    ``--dist loadscope`` the run ends when the last worker does: an idle tail on the other is a core unused
    (refresh tests/module_seconds.txt, split a long module). Compare runs by the CPU: on a loaded machine the
    wall times scale with the load."""
    if _BUSY:
        end = max(stop for *_, stop in _BUSY.values())
        terminalreporter.write_line("worker busy: " + ", ".join(
            f"{w} {busy:.1f} s in tests ({cpu:.1f} s CPU), {stop - start:.1f} s first to last, "
            f"idle for the last {end - stop:.1f} s" for w, (busy, cpu, start, stop) in sorted(_BUSY.items())))


# pytest rewrites the asserts of every test module it imports (parse, rewrite, compile: ~8 s of CPU per process
# for this suite's ~220 modules, each xdist worker again) and caches the result in tests/**/__pycache__ only when
# bytecode may be written: with PYTHONDONTWRITEBYTECODE set (as on this machine and in CI) it redid the work in
# every run. This process (not the subprocesses the tests start) writes bytecode, so the next run reads it back.
sys.dont_write_bytecode = False


@pytest.fixture(scope="session", autouse=True)
def fmu_cache_dir(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """``$FEEDDRIVE_CACHE`` for the whole session, so code calling ``builtin_fmu()`` stays in tmp.

    Under pytest-xdist the workers share one cache (in the run's common temporary root): the builds are safe
    for parallel processes (private build directory, atomic rename), and an FMU or a compiled rollout that one
    worker built is not compiled again by the other."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        cache = tmp_path_factory.getbasetemp().parent / "fmu_cache"
        cache.mkdir(exist_ok=True)
    else:
        cache = tmp_path_factory.mktemp("fmu_cache")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("FEEDDRIVE_CACHE", str(cache))
        yield cache


@pytest.fixture(scope="session", autouse=True)
def draw_in_turn() -> Iterator[None]:
    """``FEEDDRIVE_PLOT_PROCESSES=1`` for the session (unless set): each ``cosim run`` draws its figures itself.

    By default a run forks its drawing processes at its start, and the first one draws a throw-away figure to
    warm matplotlib, whether the run draws anything or not: ~0.8 s of CPU per run (the Reference-FMU conformance
    runs took 48 s of CPU with them, 23 s without). The suite already keeps both cores busy with its two xdist
    workers, so drawing in parallel gained no time here. The processes themselves are tested with an explicit
    count (tests/cosim/test_plot_workers.py, test_plots_concurrent.py, test_run_imports.py), and the README's
    sessions run with the user's default (tests/layout/test_readme_outputs.py)."""
    with pytest.MonkeyPatch.context() as mp:
        if not os.environ.get("FEEDDRIVE_PLOT_PROCESSES"):
            mp.setenv("FEEDDRIVE_PLOT_PROCESSES", "1")
        yield


@pytest.fixture(scope="session")
def feeddrive_fmu(fmu_cache_dir: Path) -> Path:
    """The built-in feed-drive plant FMU (FMI 2.0, CS + ME), built once per test session."""
    return builtin_fmu(fmu_cache_dir)


@pytest.fixture(scope="session")
def vendor_pmsm_fmu(fmu_cache_dir: Path) -> Path:
    """The hand-written vendor-style PMSM FMU (tests/plants/vendor_pmsm), compiled once per test session.

    In the session's FMU cache, which the xdist workers share: the first worker to need it compiles it into a
    private folder and renames that into place (atomic), the others take it (or, racing, build their own copy
    and discard it)."""
    import tempfile

    plants = Path(__file__).parent / "plants"
    sys.path.insert(0, str(plants))
    from vendor_pmsm import MODEL, build_vendor_pmsm

    target = fmu_cache_dir / "vendor_pmsm"  # the cache lives for this session only: the sources cannot change
    if not (target / f"{MODEL}.fmu").is_file():
        with tempfile.TemporaryDirectory(dir=fmu_cache_dir) as tmp:
            build_vendor_pmsm(Path(tmp) / "fmu")
            try:
                os.rename(Path(tmp) / "fmu", target)
            except OSError:  # another worker put its copy there first
                pass
    return target / f"{MODEL}.fmu"


@pytest.fixture(scope="session")
def built_once(fmu_cache_dir: Path) -> Callable[[str, Callable[[Path], Path]], Path]:
    """``built_once(name, build) -> path``: the test FMU ``build(folder)`` makes, made once for the whole test run.

    Several modules compile the same test plant (RefAxis, RampIntegrator, Faulty, the example's vendor FMU:
    0.5-2 s of CPU each): the first caller builds it into the session's FMU cache (which the xdist workers
    share), holding a lock file that the others wait on, and every caller gets that file. ``name`` says what
    is built (with its options: the cache lives for this session only, so the sources cannot change); the FMU
    is read only for its users (a test that changes one builds its own)."""
    import fcntl

    def get(name: str, build: Callable[[Path], Path]) -> Path:
        folder = fmu_cache_dir / "built_once"
        folder.mkdir(exist_ok=True)
        done = folder / f"{name}.path"
        with open(folder / f"{name}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            try:
                if not done.is_file():
                    (folder / name).mkdir(exist_ok=True)
                    done.write_text(str(build(folder / name)), encoding="utf-8")
            finally:
                fcntl.flock(lock, fcntl.LOCK_UN)
        return Path(done.read_text(encoding="utf-8"))

    return get


#: the examples that several modules run through ``cosim run`` as a user does (tests/conftest.py example_runs)
EXAMPLE_RUNS = ("tool_change", "worn_axis", "current_sensor_fault")


@pytest.fixture(scope="session")
def example_runs(feeddrive_fmu: Path, tmp_path_factory: pytest.TempPathFactory) -> dict:
    """``cosim run examples/<name>.yaml`` of each of ``EXAMPLE_RUNS``, in that order, in one working folder:
    the default output folders (``runs/<scenario>-<time>``) and the default history ``runs/history.sqlite``,
    which then holds one motion of axis X, worn-X and sensor-X (each example its own axis).

    Returns ``{"work": folder, "out": {name: run folder}, "stdout": {name: what the command printed}}``.
    Read only: a test that continues the history copies ``work`` first, a test that writes next to a page
    copies the page. Each run draws its figures (~3 s of a run's 3.5 s of CPU), and four modules read these
    runs (the report page, the browser, the baseline's CLI sequence, the summary of a sensor fault): they are
    made once for the whole test run; under xdist the first worker to need them makes them in the run's
    common temporary root, the other waits for it (a lock file) and reads them."""
    import contextlib
    import fcntl
    import io
    import json

    from feeddrive.cosim.cli import main

    examples = Path(__file__).resolve().parents[1] / "examples"
    if os.environ.get("PYTEST_XDIST_WORKER"):
        work = tmp_path_factory.getbasetemp().parent / "example_runs"
        work.mkdir(exist_ok=True)
    else:
        work = tmp_path_factory.mktemp("example_runs")
    done = work / "example_runs.json"
    with open(work / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            if not done.is_file():
                printed, out = {}, {}
                with pytest.MonkeyPatch.context() as mp:
                    mp.chdir(work)
                    for name in EXAMPLE_RUNS:
                        before = set(Path("runs").glob("*/report.json"))
                        buffer = io.StringIO()
                        with contextlib.redirect_stdout(buffer):
                            assert main(["run", str(examples / f"{name}.yaml"), "--no-progress"]) == 0
                        (new,) = set(Path("runs").glob("*/report.json")) - before
                        printed[name], out[name] = buffer.getvalue(), str(work / new.parent)
                done.write_text(json.dumps({"stdout": printed, "out": out}), encoding="utf-8")
        finally:  # explicitly: the runs' forked children share the lock's open file
            fcntl.flock(lock, fcntl.LOCK_UN)
    data = json.loads(done.read_text(encoding="utf-8"))
    return {"work": work, "out": {k: Path(v) for k, v in data["out"].items()}, "stdout": data["stdout"]}


# hypothesis profiles: the fuzz tests (tests/cosim/test_fuzz.py) run 500 examples each by default;
# `pytest --hypothesis-profile=fuzz tests/cosim/test_fuzz.py` runs 10 000 each
from hypothesis import HealthCheck, settings  # noqa: E402

settings.register_profile("fuzz", max_examples=10_000, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
