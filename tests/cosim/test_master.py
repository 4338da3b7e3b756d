"""The master: Gauss-Seidel order, exact event timing, wiring, determinism, failure handling.

Analytic components (defined here, loadable from scenarios as ``test_master:<Class>``):
``Source`` outputs a value set by events and its own step count; ``Integrator`` integrates its input
exactly for piecewise-constant inputs, x_{n+1} = x_n + h a_n, and echoes what it received.
"""
from __future__ import annotations

import textwrap

import numpy as np
import pytest

from feeddrive.cosim.component import Component
from feeddrive.cosim.errors import ScenarioError, SimulationError
from feeddrive.cosim.master import Master, event_step
from feeddrive.cosim.scenario import load_scenario


class Source(Component):
    """Outputs ``a`` (set by events, held from the step the event is applied) and ``n`` (its step count)."""

    output_names = ("a", "n")
    output_units = ("m/s", "1")

    def setup(self, t0, h, n_steps):
        self.a, self.k = float((self.config or {}).get("a", 0.0)), 0
        self.terminated = 0

    def set_parameter(self, name, value):
        if name != "a":
            super().set_parameter(name, value)
        self.a = float(value)

    def step(self, n):
        self.k = n + 1

    def get_outputs(self):
        return [self.a, float(self.k)]

    def terminate(self):
        self.terminated += 1


class Integrator(Component):
    """x' = a; outputs ``x`` and ``seen`` (the last input received)."""

    input_names = ("a",)
    output_names = ("x", "seen")
    output_units = ("m", "")

    def setup(self, t0, h, n_steps):
        self.h, self.x, self.a = h, 0.0, 0.0

    def set_inputs(self, values):
        (self.a,) = values

    def step(self, n):
        self.x += self.h * self.a

    def get_outputs(self):
        return [self.x, self.a]


class Failing(Integrator):
    """Raises at the step given in its config."""

    def step(self, n):
        if n == self.config["at"]:
            raise ZeroDivisionError("boom")
        super().step(n)


def run(components, **kw):
    master = Master(components, **kw)
    rec = master.run()
    master.terminate()
    return rec.time, rec.signals()


def test_event_step_is_the_first_grid_point_at_or_after_the_event():
    h = 0.1
    assert event_step(0.3, 0.0, h) == 3  # 0.3 / 0.1 = 2.9999999999999996: on the grid, not postponed
    assert event_step(0.25, 0.0, h) == 3 and event_step(0.2000001, 0.0, h) == 3 and event_step(0.0, 0.0, h) == 0
    assert event_step(1.0, 0.5, 1e-4) == 5000


@pytest.mark.parametrize("source_first", [True, False])
def test_gauss_seidel_order_is_visible_in_the_values(source_first):
    comps = [("src", Source("src")), ("int", Integrator("int"))]
    t, s = run(comps if source_first else comps[::-1], step=0.5, n_steps=6,
               connections={"int.a": "src.n"}, record=["int.seen", "src.n"])
    # the integrator sees the source's output at t_{n+1} when the source runs first, at t_n otherwise
    expected = np.arange(7.0) if source_first else np.r_[0.0, np.arange(6.0)]
    np.testing.assert_array_equal(s["int.seen"], expected)
    np.testing.assert_array_equal(s["src.n"], np.arange(7.0))
    np.testing.assert_array_equal(t, 0.5 * np.arange(7))


def test_events_take_effect_at_their_grid_point_and_the_integral_is_exact():
    h, a1, a2 = 1e-3, 2.0, -0.5
    t, s = run([("src", Source("src")), ("int", Integrator("int"))], step=h, n_steps=1000,
               connections={"int.a": "src.a"},
               events=[(0.3, "src.a", a1), (0.7004, "src.a", a2)])  # grid points 300 and 701
    x_exact = a1 * np.clip(t - 0.3, 0, 0.401) + a2 * np.clip(t - 0.701, 0, None)
    np.testing.assert_allclose(s["int.x"], x_exact, rtol=0, atol=1e-12)
    assert s["src.a"][301] == a1 and s["src.a"][300] == 0.0  # recorded at t_{n+1} after step n = 300
    assert s["int.x"][300] == 0.0 and s["int.x"][301] == pytest.approx(a1 * h, abs=1e-15)


def test_constant_sources_and_unconnected_inputs():
    t, s = run([("int", Integrator("int"))], step=0.25, n_steps=4, connections={"int.a": 3.0})
    np.testing.assert_allclose(s["int.x"], 3.0 * t, rtol=1e-15)
    with pytest.raises(ScenarioError, match=r"input 'int\.a' is not connected"):
        Master([("int", Integrator("int"))], step=0.1, n_steps=1).setup()
    with pytest.raises(ScenarioError, match=r"unknown source 'int\.y'"):
        Master([("int", Integrator("int"))], step=0.1, n_steps=1, connections={"int.a": "int.y"}).setup()
    with pytest.raises(ScenarioError, match=r"record\[0\]: unknown signal 'int\.v'"):
        Master([("int", Integrator("int"))], step=0.1, n_steps=1, connections={"int.a": 1.0},
               record=["int.v"]).setup()


def test_failure_keeps_rows_so_far_terminates_and_names_the_component(tmp_path):
    src = Source("src")
    master = Master([("src", src), ("bad", Failing("bad", {"at": 37}))], step=0.01, n_steps=100,
                    connections={"bad.a": "src.n"})
    with pytest.raises(SimulationError, match=r"bad: ZeroDivisionError: boom \(in step 37 from t=0\.37 s\)"):
        master.run(signals_path=tmp_path / "signals.csv")
    assert src.terminated == 1
    master.terminate()  # idempotent
    assert src.terminated == 1
    data = np.loadtxt(tmp_path / "signals.csv", delimiter=",", skiprows=1)
    assert data.shape[0] == 38 and data[-1, 0] == pytest.approx(0.37)  # rows t_0 .. t_37
    header = (tmp_path / "signals.csv").read_text().splitlines()[0]
    assert header == "time [s],src.a [m/s],src.n [1],bad.x [m],bad.seen"


SCENARIO = """\
name: master-test
step: 1.0e-4
stop_time: 0.6
plant: {{fmu: builtin}}
sensors:
  seed: {seed}
  current: [{{noise: 0.0}}, {{noise: 0.05}}]
nc:
  program:
    - rapid: {{to: 0.02}}
components:
  - {{name: charge, class: "test_master:Integrator", inputs: {{a: plant.current}}}}
events:
  - {{time: 0.1, target: sensors.Im1.gain, value: 1.03}}
"""


def run_scenario_signals(tmp_path, seed: int) -> dict:
    path = tmp_path / f"s{seed}.yaml"
    path.write_text(textwrap.dedent(SCENARIO.format(seed=seed)))
    with Master.from_scenario(load_scenario(path)) as master:
        return master.run().signals()


def test_scenario_run_is_deterministic_and_wires_user_components(tmp_path, feeddrive_fmu):
    a, b, c = (run_scenario_signals(tmp_path, seed) for seed in (1, 1, 2))
    assert a.keys() == b.keys()
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)  # bit for bit
    assert not np.array_equal(a["sensors.Im2"], c["sensors.Im2"])  # another seed, other noise
    np.testing.assert_array_equal(a["plant.current"], c["plant.current"])  # same plant
    # the user component runs after the plant: at step n it integrates the current at t_{n+1}
    h, i = 1e-4, a["plant.current"]
    np.testing.assert_allclose(a["charge.x"], np.r_[0.0, np.cumsum(h * i[1:])], rtol=1e-12, atol=1e-15)
    # sensor fault event at t = 0.1 s (step 1000): the output at t_1001 is the first with the new gain
    ratio = a["sensors.Im1"] / np.where(i == 0, np.nan, i)
    np.testing.assert_allclose(ratio[1:1001][np.isfinite(ratio[1:1001])], 1.0, rtol=1e-12)
    np.testing.assert_allclose(ratio[1001:], 1.03, rtol=1e-12)
    # the plant reaches the NC's target position
    assert abs(a["plant.position"][-1] - 0.02) < 1e-5


def test_user_component_errors_name_the_scenario_key(tmp_path, feeddrive_fmu):
    base = "name: t\nplant: {fmu: builtin}\nnc: {program: []}\ncomponents:\n"
    cases = [("  - {name: x, class: 'no_such_module:X'}\n", r":5: components\[0\]\.class: cannot import module"),
             ("  - {name: x, class: 'test_master:Failing', config: {at: 1}}\n  - {name: y, class: 'math:pi'}\n",
              r":6: components\[1\]\.class: 'math:pi' is not a subclass of feeddrive\.cosim\.component\.Component"),
             ("  - {name: x, class: 'test_master:Integrator'}\n", r"connections: input 'x\.a' is not connected")]
    for k, (text, pattern) in enumerate(cases):
        path = tmp_path / f"s{k}.yaml"
        path.write_text(base + text)
        with pytest.raises(ScenarioError, match=pattern):
            with Master.from_scenario(load_scenario(path)) as master:
                master.setup()


def test_nc_start_must_match_the_plant_position(tmp_path, feeddrive_fmu):
    path = tmp_path / "start.yaml"
    path.write_text("name: t\nplant: {fmu: builtin}\nnc:\n  start: 0.1\n  program: []\n")
    with pytest.raises(ScenarioError, match=r"start\.yaml:4: nc\.start: the NC program starts at 0\.1 m but the "
                                            r"plant at 0 m"):
        Master.from_scenario(load_scenario(path)).setup()
    # theta = 0.1 m / 0.02 m per turn * 2 pi: the plant starts where the program does
    path.write_text(f"name: t\nplant: {{fmu: builtin, start: {{theta: {10 * np.pi!r}}}}}\nstop_time: 0.01\n"
                    "nc:\n  start: 0.1\n  program: []\n")
    with Master.from_scenario(load_scenario(path)) as master:
        x = master.run().signals()["plant.position"]
    np.testing.assert_allclose(x, 0.1, atol=1e-12)
