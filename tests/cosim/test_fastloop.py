"""The compiled fine loop (cosim/fastloop) gives the Python loop's results bit for bit, and runs only where it can."""
from __future__ import annotations

import runpy
from pathlib import Path

import numpy as np
import pytest
import yaml

from feeddrive.cosim.errors import FMIError
from feeddrive.cosim.master import Master
from feeddrive.cosim.scenario import scenario_from_dict

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
COMPILED = "compiled fine loop (NC, plant FMU, sensors)"
#: with a monitor, whose buffering of a motion's samples the compiled loop does too
WITH_MONITOR = "compiled fine loop (NC, plant FMU, sensors, monitor's buffering)"
#: a PMSM axis: its servo sensors in the compiled loop too (tests/cosim/test_fastloop_servo.py)
WITH_SERVO = "compiled fine loop (NC, plant FMU, sensors, servo sensors, monitor's buffering)"
#: report entries that are wall or CPU times, not results
TIMES = ("processing_s", "processing_cpu_s", "max_processing_s", "max_processing_cpu_s")


def _without_times(x):
    if isinstance(x, dict):
        return {k: _without_times(v) for k, v in x.items() if k not in TIMES}
    if isinstance(x, list):
        return [_without_times(v) for v in x]
    return x


def run_both(monkeypatch, data: dict) -> tuple[dict, dict]:
    """``{"loop", "data", "names", "reports"}`` of the Python loop, then of the compiled one."""
    out = []
    for flag in ("0", "1"):
        monkeypatch.setenv("FEEDDRIVE_FASTLOOP", flag)
        with Master.from_scenario(scenario_from_dict(data)) as master:
            rec = master.run()
            out.append({"loop": master.loop, "data": rec.data[:rec.n].copy(), "names": rec.names,
                        "reports": _without_times(master.reports())})
    return out[0], out[1]


def assert_identical(py: dict, fast: dict) -> None:
    assert py["loop"] == "python loop: FEEDDRIVE_FASTLOOP=0" and fast["loop"].startswith("compiled fine loop (")
    assert py["names"] == fast["names"] and py["data"].shape == fast["data"].shape
    for j, name in enumerate(py["names"]):  # bit-identical, NaN (monitor outputs before a motion) included
        np.testing.assert_array_equal(fast["data"][:, j], py["data"][:, j], err_msg=name)
    assert fast["reports"] == py["reports"]


def example(name: str, **changes) -> dict:
    data = yaml.safe_load((EXAMPLES / name).read_text())
    return data | changes


@pytest.mark.parametrize("name, stop", [("tool_change.yaml", None), ("nc_cycle.yaml", 1.2)])
def test_examples_bit_identical(monkeypatch, feeddrive_fmu, name, stop):
    data = example(name) | ({"stop_time": stop} if stop else {})
    py, fast = run_both(monkeypatch, data)
    assert_identical(py, fast)
    speed = fast["data"][:, fast["names"].index("plant.speed")]
    assert np.abs(speed).max() > 60  # a real rapid traverse went through both loops (rad/s)
    if stop is None:  # the whole tool change: the monitor identified the motion in both
        motions = fast["reports"]["monitor"]["motions"]
        assert motions and motions[0]["parameters"]["R"]["value"] == pytest.approx(0.6, rel=0.02)


def monitored(program: list, monitor: dict, stop: float, **nc) -> dict:
    return {"name": "request", "axis": "X", "step": 1e-4, "plant": {"fmu": "builtin"}, "sensors": {"seed": 4},
            "nc": {"program": program, "identification": {"distance": 0.1}, **nc}, "monitor": monitor,
            "stop_time": stop}


SHORT = [{"dwell": {"time": 0.1}}, {"rapid": {"to": 0.03}}]  # too short to identify: the monitor requests one


@pytest.mark.parametrize("data, inserted", [
    # the request rises after the program ended: the NC inserts the identification at once
    (monitored(SHORT, {"max_motions": 0}, 2.6), [0.5473]),
    # it rises in a dwell: pending until the next program item, an NC cycle of 4 plant steps
    (monitored(SHORT + [{"dwell": {"time": 0.3}}, {"feed": {"to": 0.05, "feed": 0.01}}], {"max_motions": 0}, 3.0,
               cycle=4e-4) | {"plant": {"fmu": "builtin", "oversample": 2}}, [0.8472136]),
    # by age (max_age_s) from the start, then after the identification: the monitor's age step ends a block
    (monitored(SHORT + [{"dwell": {"time": 0.3}}, {"rapid": {"to": 0.0}}], {"max_age_s": 0.05, "max_motions": 10},
               2.5), [0.1, 2.4896378]),
])
def test_identification_requests_bit_identical(monkeypatch, feeddrive_fmu, data, inserted):
    """The NC and the monitor's buffering in the compiled loop: a request's edge and a pending identification
    (the NC's steps that insert pieces run in Python), motions that start and end inside a stretch, a motion
    unfinished at the end: the Python loop's bits, and the identification motion inserted when requested."""
    py, fast = run_both(monkeypatch, data)
    assert fast["loop"] == WITH_MONITOR
    assert_identical(py, fast)
    assert fast["reports"]["nc"]["identifications_inserted_s"] == pytest.approx(inserted, abs=1e-6)
    x = fast["data"][:, fast["names"].index("plant.position")]
    assert x.max() > 0.09  # the identification's 0.1 m out and back ran (m)
    unfinished = [r["reports"]["monitor"]["unfinished_motion"] for r in (py, fast)]
    assert type(unfinished[1]) is type(unfinished[0])  # the NC's motion index stays an int (report.json)


def test_pmsm_axis_with_servo_sensors_bit_identical(monkeypatch, feeddrive_fmu):
    """A PMSM axis: the servo sensors, which feed the monitor, step in the compiled loop with the NC and the
    monitor's buffering."""
    data = yaml.safe_load((EXAMPLES / "pmsm_monitor.yaml").read_text()) | {"stop_time": 0.8}
    data["events"] = [e for e in data.get("events") or [] if e["time"] < 0.8]  # its psi_f drop at 1.6 s: after the end
    py, fast = run_both(monkeypatch, data)
    assert fast["loop"] == WITH_SERVO
    assert_identical(py, fast)
    x = fast["data"][:, fast["names"].index("nc.x_ref")]
    assert x.max() > 0.15 and fast["reports"]["monitor"]["unfinished_motion"] == 1  # mid tool change (m)


def test_vendor_fmu_at_oversample_10_bit_identical(monkeypatch, built_once):
    """The example's vendor FMU (rpm, mm: a role map with scales) at 10 plant steps per recording step."""
    fmu = built_once("VendorDrive", lambda folder: runpy.run_path(str(EXAMPLES / "vendor_fmu" / "build_vendor_fmu.py"))[
        "main"](["--out", str(folder / "VendorDrive.fmu")]))
    data = example("vendor_fmu.yaml", stop_time=0.45)
    data["plant"] = data["plant"] | {"fmu": str(fmu), "oversample": 10}
    py, fast = run_both(monkeypatch, data)
    assert_identical(py, fast)
    position = fast["data"][:, fast["names"].index("plant.position")]
    assert position[-1] > 0.01  # metres, converted from the FMU's mm: the axis moved


def test_filters_instant_sampling_events_and_noise_blocks(monkeypatch, feeddrive_fmu):
    """Every sensor sampling, an NC cycle of 25 plant steps, sensor and plant events off the recording grid,
    and more recorded samples than one block of noise rows (4096): still the same bits."""
    data = example("nc_cycle.yaml", stop_time=0.52, monitor=None)
    data["plant"] = data["plant"] | {"oversample": 5}
    data["nc"] = data["nc"] | {"cycle": 5.0e-4}
    data["sensors"] = {"seed": 3, "voltage": {"sampling": "lowpass", "order": 4},
                       "voltage_ref": {"sampling": "lowpass", "order": 3, "cutoff_hz": 1500.0},
                       "tachometer": {"sampling": "instant"}, "current": [{"noise": 0.05}, {"sampling": "lowpass"}],
                       "encoder": {"noise": 1e-4}}
    data["events"] = [{"time": 0.23003, "target": "sensors.Im1.gain", "value": 1.2},
                      {"time": 0.30001, "target": "sensors.u.noise", "value": 0.5},
                      {"time": 0.31207, "target": "plant.R", "value": 0.9}]
    py, fast = run_both(monkeypatch, data)
    assert_identical(py, fast)
    names = fast["names"]
    i1, i2 = (fast["data"][:, names.index(f"sensors.{c}")] for c in ("Im1", "Im2"))
    late = slice(int(0.25e4), None)  # after the gain fault: Im1 / Im2 ~ 1.2 where the current is large
    big = np.abs(i2[late]) > 2.0
    assert big.any() and np.median(i1[late][big] / i2[late][big]) == pytest.approx(1.2, rel=0.02)


@pytest.mark.parametrize("cycle", [None, 2.0e-3])
def test_an_fmu_failure_in_a_compiled_block_is_the_python_loops(monkeypatch, feeddrive_fmu, tmp_path, cycle):
    """An FMU that fails inside a block (with an NC cycle of 20 steps: after rows the block recorded itself):
    the same error, time and rows as the Python loop."""
    data = example("tool_change.yaml", stop_time=0.3, monitor=None)
    if cycle:
        data["nc"] = data["nc"] | {"cycle": cycle}
    data["events"] = [{"time": 0.2503, "target": "plant.L", "value": 1e-9}]  # the RK4 step blows up
    seen = []
    for flag in ("0", "1"):
        monkeypatch.setenv("FEEDDRIVE_FASTLOOP", flag)
        with Master.from_scenario(scenario_from_dict(data)) as master:
            with pytest.raises(FMIError) as info:
                master.run(signals_path=tmp_path / f"signals{flag}.csv")
            seen.append((str(info.value), info.value.function, master.recorder.n,
                         master.recorder.data[:master.recorder.n].copy()))
    (msg0, f0, n0, d0), (msg1, f1, n1, d1) = seen
    assert (msg1, f1, n1) == (msg0, f0, n0) and f1 == "fmi2DoStep" and "t=0.2505 s" in msg1
    np.testing.assert_array_equal(d1, d0)
    assert (tmp_path / "signals1.csv").read_text() == (tmp_path / "signals0.csv").read_text()


def test_model_exchange_and_the_switch_take_the_python_loop(monkeypatch, feeddrive_fmu):
    data = example("tool_change.yaml", stop_time=0.01, monitor=None)
    me = data | {"plant": data["plant"] | {"interface": "me"}}
    with Master.from_scenario(scenario_from_dict(me)) as master:
        master.run()
        assert master.loop == "python loop: the plant is not an FMI 2.0 Co-Simulation FMU"
    monkeypatch.setenv("FEEDDRIVE_FASTLOOP", "0")
    with Master.from_scenario(scenario_from_dict(data)) as master:
        master.run()
        assert master.loop == "python loop: FEEDDRIVE_FASTLOOP=0"


def test_a_supervised_run_takes_the_compiled_loop_and_writes_the_same_csv(monkeypatch, feeddrive_fmu, tmp_path):
    """Containment (``cosim run``: a forked child with the shared progress record) keeps the fast path."""
    import json

    from feeddrive.cosim.run import run_scenario
    from feeddrive.cosim.supervise import run_supervised

    scenario = scenario_from_dict(example("nc_cycle.yaml", stop_time=0.2, monitor=None))
    run_supervised(scenario, tmp_path / "child", plots=False)
    report = json.loads((tmp_path / "child" / "report.json").read_text())
    assert report["status"] == "ok" and report["loop"] == COMPILED
    monkeypatch.setenv("FEEDDRIVE_FASTLOOP", "0")
    run_scenario(scenario, tmp_path / "python", plots=False)
    assert json.loads((tmp_path / "python" / "report.json").read_text())["loop"] == "python loop: FEEDDRIVE_FASTLOOP=0"
    assert (tmp_path / "child" / "signals.csv").read_bytes() == (tmp_path / "python" / "signals.csv").read_bytes()


def test_without_a_c_compiler_the_python_loop_runs_and_says_why(monkeypatch, feeddrive_fmu, tmp_path):
    from feeddrive.cosim.fastloop import build

    data = example("tool_change.yaml", stop_time=0.01, monitor=None)
    scenario = scenario_from_dict(data)  # the built-in FMU, from the cache
    monkeypatch.setattr(build, "_cache_root", lambda: tmp_path)  # no compiled loop there yet
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    build.library.cache_clear()
    try:
        with Master.from_scenario(scenario) as master:
            rec = master.run()
        assert master.loop == f"python loop: no C compiler {str(tmp_path / 'no-such-cc')!r} (set $CC)"
        assert rec.n == 101
    finally:
        build.library.cache_clear()  # the next run builds with the real compiler again


NAN_AXIS = '''
import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class NanAxis(Fmi2Slave):
    """An ideal speed-controlled axis whose current output turns NaN from t = 0.0025 s on."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.w_ref = self.Tl = self.u = self.i = self.w = self.x = 0.0
        for name in ("w_ref", "Tl"):
            self.register_variable(Real(name, causality=Fmi2Causality.input))
        for name in ("u", "i", "w", "x"):
            self.register_variable(Real(name, causality=Fmi2Causality.output))

    def do_step(self, t, dt):
        self.w = self.w_ref
        self.x += self.w_ref * dt * 0.02 / (2 * math.pi * 3.0)
        self.u = 0.1 * self.w
        self.i = math.nan if t + dt > 0.0025 else 0.0
        return True
'''


def test_a_non_finite_output_in_a_compiled_block_is_the_python_loops(monkeypatch, tmp_path):
    """A pythonfmu plant (the FMU calls back into Python from the compiled loop) whose output turns NaN."""
    import textwrap

    from pythonfmu.builder import FmuBuilder

    from feeddrive.cosim.fmu_adapter import NonFiniteOutput

    script = tmp_path / "nan_axis.py"
    script.write_text(textwrap.dedent(NAN_AXIS))
    fmu = FmuBuilder.build_FMU(script, dest=tmp_path)
    data = {"name": "nan", "step": 1.0e-3, "stop_time": 0.01,
            "plant": {"fmu": str(fmu), "interface": "cs", "map": {
                "speed_ref": {"var": "w_ref"}, "load": {"var": "Tl"}, "voltage": {"var": "u"},
                "current": {"var": "i"}, "speed": {"var": "w"}, "position": {"var": "x"}}},
            "sensors": {"seed": 1}, "nc": {"program": [{"rapid": {"to": 0.001}}]}}
    seen = []
    for flag in ("0", "1"):
        monkeypatch.setenv("FEEDDRIVE_FASTLOOP", flag)
        with Master.from_scenario(scenario_from_dict(data)) as master:
            with pytest.raises(NonFiniteOutput) as info:
                master.run()
            seen.append((master.loop, str(info.value), master.recorder.data[:master.recorder.n].copy()))
    assert seen[1][0] == COMPILED
    assert seen[1][1] == seen[0][1] == ("plant: fmi2GetReal returned nan for current (FMU variable i) at t=0.003 s; "
                                        "expected a finite number")
    np.testing.assert_array_equal(seen[1][2], seen[0][2])
    assert len(seen[1][2]) == 3  # t = 0, 0.001, 0.002 s
