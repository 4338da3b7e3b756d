"""FMI 3.0 Co-Simulation intermediate update, exercised: RampIntegrator (tests/plants/ramp_integrator.py), a C
FMU that asks the master for its inputs at the end of each of its four substeps per step, integrates a ramp
from a Python component. The master sets the linearly extrapolated input inside fmi3DoStep, so each step's
integral of the ramp is the analytic one to rounding; held (zoh, or the FMU without intermediate update) it
is b h^2 / 2 short per step (the mean input h b / 2 low). fmpy's simulate_fmu, a second engine, agrees: with
held inputs, and with an intermediateUpdate callback of the test's own that sets the exact ramp."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "plants"))
from ramp_integrator import build  # noqa: E402
from ref_axis import build as build_axis  # noqa: E402

from feeddrive.cosim.cli import main  # noqa: E402
from feeddrive.cosim.master import Master  # noqa: E402
from feeddrive.cosim.scenario import scenario_from_dict  # noqa: E402

H, N, A, B, W = 1e-3, 40, 0.2, 3.0, 0.5  # step [s], steps, ramp r(t) = A + B t [m/s], constant w [rad/s]


@pytest.fixture(scope="module")
def fmus(built_once) -> dict[bool, Path]:
    """RampIntegrator with and without intermediate update, built once for the test run (tests/conftest.py)."""
    return {flag: built_once(f"RampIntegrator{int(flag)}",
                             lambda folder, flag=flag: build(folder / f"RampIntegrator{int(flag)}.fmu", intermediate=flag))
            for flag in (True, False)}


def run(fmu: Path, **config) -> tuple[dict[str, np.ndarray], dict]:
    """The FMU fed by the ramp (after it in the stepping order: it reads r(t_n) at step n) and w = W."""
    data = {"name": "ramp", "step": H, "stop_time": N * H, "components": [
        {"name": "ri", "fmu": str(fmu), "config": config, "inputs": {"v": "ramp.r", "w": W}},
        {"name": "ramp", "class": "ramp_integrator:Ramp", "config": {"start": A, "slope": B, "unit": "m/s"}}]}
    with Master.from_scenario(scenario_from_dict(data)) as master:
        signals = master.run().signals()
        return signals, master.components["ri"].report()


def test_the_master_sets_the_ramped_input_inside_each_step(fmus, monkeypatch):
    from feeddrive.cosim import fmi_progress
    from feeddrive.cosim.fmi3_adapter import FMU3Component

    seen = []  # the supervisor's record while the FMU asks (inside fmi3DoStep): function and time t_n
    original = FMU3Component._intermediate_update

    def spy(self, env, t, *args):  # noqa: ANN001
        seen.append((self._rec.function, self._rec.time, t))
        return original(self, env, t, *args)
    monkeypatch.setattr(FMU3Component, "_intermediate_update", spy)
    s, report = run(fmus[True])
    assert report["input_hold"] == "foh"
    calls = [(f, tn, t) for f, tn, t in seen if f]  # the framework also calls it after each substep (no request)
    assert {f for f, _, _ in calls} == {fmi_progress.CODE["fmi3DoStep"]}
    assert all(0 < t - tn <= H * (1 + 1e-9) for _, tn, t in calls) and len(seen) == 8 * N
    t = np.arange(N + 1) * H
    r = A + B * t
    dx = np.diff(s["ri.x"])
    exact = H * r[:-1] + B * H**2 / 2  # the integral of the ramp over [t_n, t_n+1]
    # step 0 has no slope yet (no previous value): held, B H^2 / 2 short; from step 1 on the analytic integral
    np.testing.assert_allclose(dx[0], H * A, rtol=0, atol=1e-15)
    np.testing.assert_allclose(dx[1:], exact[1:], rtol=0, atol=1e-12)
    # the value the FMU received last, at t_n+1: the extrapolated ramp, r(t_n+1) (held at step 0)
    np.testing.assert_allclose(s["ri.v_last"][2:], r[2:], rtol=0, atol=1e-12)
    assert s["ri.requests"][-1] == 4 * N  # four substeps per step, each one asked for the inputs
    np.testing.assert_allclose(s["ri.phi"], W * t, rtol=0, atol=1e-12)  # a constant stays constant (slope 0)
    held, report = run(fmus[True], input_hold="zoh")  # no callback registered: the FMU holds v over the step
    assert report["input_hold"] == "zoh" and held["ri.requests"][-1] == 0
    np.testing.assert_allclose(exact[1:] - np.diff(held["ri.x"])[1:], B * H**2 / 2, rtol=0, atol=1e-12)
    plain, report = run(fmus[False])  # an FMU without intermediate update: held by default
    assert report["input_hold"] == "zoh"
    np.testing.assert_allclose(plain["ri.x"], held["ri.x"], rtol=0, atol=1e-15)
    me, report = run(fmus[True], interface="me", tolerance=1e-11)  # Model Exchange: the master ramps v in CVode
    assert report["input_hold"] == "foh"
    np.testing.assert_allclose(me["ri.x"], s["ri.x"], rtol=0, atol=2e-9)  # CVode: ~2 tolerance per step


def _fmpy(fmu: Path, callback: bool) -> np.ndarray:
    """x on the grid from fmpy's simulate_fmu, inputs r(t_n) at the communication points; with ``callback``
    the test's own intermediateUpdate sets the exact ramp r(t) whenever the FMU asks."""
    import fmpy
    from fmpy.simulation import instantiate_fmu

    md, unzipped = fmpy.read_model_description(str(fmu)), fmpy.extract(str(fmu))
    holder = []

    def update(env, t, set_requested, get_allowed, finished, can_return, early, early_time):  # noqa: ANN001
        early[0] = False
        if set_requested:
            holder[0].setFloat64([1], [A + B * t])
    inst = instantiate_fmu(unzipped, md, "CoSimulation", intermediate_update=update if callback else None)
    holder.append(inst)
    t = np.arange(N + 1) * H
    signal = np.array(list(zip(t, A + B * t)), dtype=[("time", np.float64), ("v", np.float64)])
    result = fmpy.simulate_fmu(unzipped, model_description=md, fmu_instance=inst, fmi_type="CoSimulation",
                               stop_time=N * H, output_interval=H, input=signal, start_values={"w": W},
                               output=["x", "requests"])
    inst.freeInstance()
    assert result["requests"][-1] == (4 * N if callback else 0)
    return result["x"]


def test_fmpy_agrees_held_and_with_its_own_intermediate_update(fmus):
    s, _ = run(fmus[True])
    held, _ = run(fmus[True], input_hold="zoh")
    np.testing.assert_allclose(held["ri.x"], _fmpy(fmus[True], callback=False), rtol=0, atol=1e-14)
    # fmpy's callback ramps from step 0 on; the master has no slope at step 0: B H^2 / 2 less, then the same
    exact = _fmpy(fmus[True], callback=True)
    np.testing.assert_allclose(s["ri.x"][1:], exact[1:] - B * H**2 / 2, rtol=0, atol=1e-13)


def test_cosim_info_states_the_input_handling(fmus, capsys):
    assert main(["info", str(fmus[True])]) == 0
    out = capsys.readouterr().out
    assert ("Co-Simulation inputs: first-order hold (input_hold foh, the default): the master sets u_n + slope "
            "(t - t_n) when the FMU asks inside fmi3DoStep (intermediate update of v, w)") in out
    assert main(["info", str(fmus[False])]) == 0
    out = capsys.readouterr().out
    assert ("Co-Simulation inputs: held over each communication step h (input_hold zoh): a ramp of slope s is "
            "seen s h / 2 low on average over the step (FMI 3.0 has no input derivatives and the FMU provides "
            "no intermediate update)") in out
    assert "Model Exchange inputs: first-order hold by the master inside CVode" in out


def test_an_fmi2_component_in_model_exchange_gets_the_ramp_on_its_own_inputs(built_once):
    """The first-order hold of an FMU component's own inputs (not roles), here RefAxis FMI 2.0 in Model
    Exchange: pos_mm' = n_set / 60 * pitch_mm integrates the ramped n_set, B H^2 / 2 more per step than held."""
    fmu = built_once("RefAxis2", lambda folder: build_axis(folder / "RefAxis2.fmu", 2))

    def position(hold: str) -> np.ndarray:
        data = {"name": "ramp2", "step": H, "stop_time": N * H, "components": [
            {"name": "ax", "fmu": str(fmu), "config": {"interface": "me", "input_hold": hold, "tolerance": 1e-11},
             "inputs": {"n_set": "ramp.r", "T_load": 0.0}},
            {"name": "ramp", "class": "ramp_integrator:Ramp", "config": {"start": A, "slope": B, "unit": "rpm"}}]}
        with Master.from_scenario(scenario_from_dict(data)) as master:
            return master.run().signals()["ax.pos_mm"]

    ramped, held = position("foh"), position("zoh")
    r = A + B * np.arange(N + 1) * H
    k = 20.0 / 60.0  # mm per second per rpm (pitch 20 mm)
    np.testing.assert_allclose(np.diff(held), k * H * r[:-1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.diff(ramped)[1:], k * (H * r[1:-1] + B * H**2 / 2), rtol=0, atol=2e-10)
