"""The same FMU under libcosim (OSP) gives the same trajectories as under fmpy.

libcosim sets input values only (no fmi2SetRealInputDerivatives), so the FMU holds them over each
step: the fmpy reference sets no derivatives either (the zero-order-hold path)."""
from __future__ import annotations

import numpy as np
import pytest

libcosimpy = pytest.importorskip("libcosimpy")
from libcosimpy.CosimEnums import CosimVariableType  # noqa: E402
from libcosimpy.CosimExecution import CosimExecution  # noqa: E402
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level  # noqa: E402
from libcosimpy.CosimObserver import CosimObserver  # noqa: E402
from libcosimpy.CosimSlave import CosimLocalSlave  # noqa: E402

H_NS = 100_000  # 1e-4 s in libcosim's integer nanoseconds
STEPS = 1000
SIGNALS = ("i", "w", "theta", "u", "i_ref")


def test_libcosim_and_fmpy_trajectories_agree(feeddrive_fmu, instance, tmp_path, monkeypatch):
    monkeypatch.setenv("TMPDIR", str(tmp_path))  # libcosim unpacks the FMU there
    log_output_level(CosimLogLevel.WARNING)
    start = {"w_ref": 50.0, "Tl": 1.5}

    ref = instance(**start)
    h = H_NS * 1e-9
    expected = []
    for n in range(STEPS):
        ref.fmu.doStep(n * h, h)
        expected.append(ref.get(*SIGNALS))
    expected = np.array(expected)

    execution = CosimExecution.from_step_size(step_size=H_NS)
    slave = execution.add_local_slave(CosimLocalSlave(fmu_path=str(feeddrive_fmu), instance_name="plant"))
    for name, value in start.items():
        assert execution.real_initial_value(slave, ref.vr[name], value)
    observer = CosimObserver.create_time_series()
    execution.add_observer(observer)
    for name in SIGNALS:
        assert observer.start_time_series(slave, ref.vr[name], CosimVariableType.REAL)
    assert execution.simulate_until(STEPS * H_NS)

    for k, name in enumerate(SIGNALS):
        times, steps, values = observer.time_series_real_samples(slave, ref.vr[name], from_step=1, sample_count=STEPS)
        assert list(steps) == list(range(1, STEPS + 1))
        assert times[-1] == STEPS * H_NS
        np.testing.assert_allclose(values, expected[:, k], rtol=1e-12, atol=1e-12 * np.max(np.abs(expected[:, k])))
    assert np.max(np.abs(expected[:, 1])) > 10  # the drive actually moved


def test_libcosim_holds_a_ramping_input_like_fmpy_without_derivatives(feeddrive_fmu, instance, tmp_path,
                                                                       monkeypatch):
    """w_ref ramps at 200 rad/s^2, set before every step (an override manipulator in libcosim): libcosim
    matches fmpy setting values only, and differs from fmpy adding the slope (first-order hold)."""
    from libcosimpy.CosimManipulator import CosimManipulator

    monkeypatch.setenv("TMPDIR", str(tmp_path))
    log_output_level(CosimLogLevel.WARNING)
    steps, h, slope = 300, H_NS * 1e-9, 200.0
    refs = [slope * n * h for n in range(steps)]

    def fmpy_run(foh: bool) -> np.ndarray:
        sim, rows = instance(), []
        for n, w_ref in enumerate(refs):
            sim.set(w_ref=w_ref)
            if foh:
                sim.fmu.setRealInputDerivatives([sim.vr["w_ref"]], [1], [slope])
            sim.fmu.doStep(n * h, h)
            rows.append(sim.get("u", "i"))
        return np.array(rows)

    zoh, foh = fmpy_run(False), fmpy_run(True)
    execution = CosimExecution.from_step_size(step_size=H_NS)
    slave = execution.add_local_slave(CosimLocalSlave(fmu_path=str(feeddrive_fmu), instance_name="plant"))
    override = CosimManipulator.create_override()
    assert execution.add_manipulator(override)
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    vr = instance(init=False).vr
    rows = []
    for w_ref in refs:
        assert override.slave_real_values(slave, [vr["w_ref"]], [w_ref])
        assert execution.step()
        rows.append(observer.last_real_values(slave, [vr["u"], vr["i"]]))
    for k in range(2):
        np.testing.assert_allclose(np.array(rows)[:, k], zoh[:, k], rtol=1e-12, atol=1e-12 * np.abs(zoh[:, k]).max())
    assert np.abs(foh[:, 0] - zoh[:, 0]).max() > 0.01  # the hold matters: libcosim really holds
