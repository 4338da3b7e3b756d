"""NC trajectory generator: exact profiles, load, states and motions, identification requests, position loop."""
import math

import numpy as np
import pytest

from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.nc import NCComponent, NCConfig
from feeddrive.models import feed_drive

SPEED_REF, LOAD, X_REF, V_REF, A_REF, STATE, MOTION = range(7)


def run(nc, h, n_steps, plant="plan", x0=None, request=None):
    """Drive ``nc`` in the master's call order; returns outputs at t_0..t_N, shape (N + 1, 7).

    plant="plan": the position fed back at t_n is the planned x_ref(t_n) (a perfect axis);
    plant="integrator": an ideal speed-controlled axis, x_{n+1} = x_n + h speed_ref pitch / (2 pi belt_ratio).
    """
    nc.setup(0.0, h, n_steps)
    ys = [list(nc.get_outputs())]
    cfg = nc.config
    conv = 2 * math.pi * cfg.belt_ratio / cfg.pitch
    x = cfg.start if x0 is None else x0
    for n in range(n_steps):
        nc.set_inputs([ys[-1][X_REF] if plant == "plan" else x, request(n) if request else 0.0])
        nc.step(n)
        ys.append(list(nc.get_outputs()))
        x += h * ys[-1][SPEED_REF] / conv
    return np.array(ys)


def trapezoid(t, x_from, x_to, v_max, accel):
    """Reference profile (x, v, a) of a rest-to-rest move written from its phase durations; a is right-continuous."""
    d = abs(x_to - x_from)
    s = math.copysign(1.0, x_to - x_from)
    v_peak = min(v_max, math.sqrt(accel * d))
    t_acc = v_peak / accel
    t_end = 2 * t_acc + (d - v_peak * t_acc) / v_peak
    t = np.clip(t, 0.0, None)
    rise, fall = t < t_acc, (t >= t_end - t_acc) & (t < t_end)
    after = t >= t_end
    tail = np.clip(t_end - t, 0.0, None)
    x = np.where(rise, 0.5 * accel * t**2, np.where(t < t_end - t_acc, v_peak * (t - 0.5 * t_acc),
                                                     d - 0.5 * accel * tail**2))
    v = np.where(rise, accel * t, np.where(fall | after, accel * tail, v_peak))
    a = np.where(rise, accel, np.where(fall, -accel, 0.0))
    return x_from + s * np.where(after, d, x), s * np.where(after, 0.0, v), s * a, t_end


def nc_with(*program, **config):
    return NCComponent("nc", {"program": list(program), **config})


@pytest.mark.parametrize("x_from, x_to", [(0.0, 0.3), (0.3, 0.0)])
def test_trapezoid_exact_at_breakpoints_and_every_step(x_from, x_to):
    # v_max 0.2, accel 0.5: 0.4 s ramps over 0.04 m, 1.1 s cruise; every breakpoint lies on the 1 ms grid
    nc = nc_with({"rapid": {"to": x_to, "v_max": 0.2, "accel": 0.5}}, start=x_from)
    assert nc.duration() == pytest.approx(1.9, abs=1e-15)
    h = 1e-3
    y = run(nc, h, 2000)
    s = math.copysign(1.0, x_to - x_from)
    for n, (x, v, a) in {0: (0.0, 0.0, 0.5), 400: (0.04, 0.2, 0.0), 1500: (0.26, 0.2, -0.5),
                         1900: (0.3, 0.0, 0.0)}.items():
        assert y[n, X_REF] == pytest.approx(x_from + s * x, abs=1e-12)
        assert y[n, V_REF] == pytest.approx(s * v, abs=1e-12)
        assert y[n, A_REF] == pytest.approx(s * a, abs=1e-12)
    x, v, a, _ = trapezoid(np.arange(2001) * h, x_from, x_to, 0.2, 0.5)
    np.testing.assert_allclose(y[:, X_REF], x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(y[:, V_REF], v, rtol=0, atol=1e-12)
    np.testing.assert_allclose(y[:, A_REF], a, rtol=0, atol=1e-12)
    assert y[-1, X_REF] == x_to  # ends exactly on the target


def test_triangular_profile_peaks_at_sqrt_accel_distance():
    # 0.02 m at 0.5 m/s^2 cannot reach 0.2 m/s: peak sqrt(0.5 * 0.02) = 0.1 m/s at t = 0.2 s
    nc = nc_with({"rapid": {"to": -0.02, "v_max": 0.2, "accel": 0.5}})
    assert nc.duration() == pytest.approx(2 * math.sqrt(0.02 / 0.5), abs=1e-15)
    y = run(nc, 1e-3, 500)
    assert y[200, V_REF] == pytest.approx(-math.sqrt(0.5 * 0.02), abs=1e-12)
    assert y[200, X_REF] == pytest.approx(-0.01, abs=1e-12)
    assert np.abs(y[:, V_REF]).max() == pytest.approx(0.1, abs=1e-12)
    assert set(np.round(y[:400, A_REF], 12)) == {-0.5, 0.5}  # no cruise piece
    x, v, _, _ = trapezoid(np.arange(501) * 1e-3, 0.0, -0.02, 0.2, 0.5)
    np.testing.assert_allclose(y[:, X_REF], x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(y[:, V_REF], v, rtol=0, atol=1e-12)


def test_feed_load_opposes_motion_and_is_timed_with_the_cut():
    # nc.accel 0.5: each 0.01 m feed at 5 mm/s takes 0.01 + 1.99 + 0.01 = 2.01 s
    nc = nc_with({"dwell": {"time": 0.1}}, {"feed": {"to": 0.01, "feed": 0.005, "load": 5.0}},
                 {"feed": {"to": 0.0, "feed": 0.005, "load": 5.0}}, accel=0.5)
    assert nc.duration() == pytest.approx(4.12, abs=1e-12)
    t = np.arange(4301) * 1e-3
    y = run(nc, 1e-3, 4300)
    forward, backward = (t >= 0.1 - 1e-9) & (t < 2.11 - 1e-9), (t >= 2.11 - 1e-9) & (t < 4.12 - 1e-9)
    np.testing.assert_array_equal(y[:, LOAD], np.where(forward, 5.0, np.where(backward, -5.0, 0.0)))
    np.testing.assert_array_equal(y[:, STATE], np.where(forward | backward, 2, 0))
    assert np.abs(y[:, V_REF]).max() == pytest.approx(0.005, abs=1e-15)
    moving = y[:, V_REF] != 0
    np.testing.assert_array_equal(np.sign(y[moving, LOAD]), np.sign(y[moving, V_REF]))  # model: +Tl brakes +w
    assert np.all(y[:, MOTION] == 0)  # feed moves are not high-speed motions
    # (that a positive load decelerates the plant is checked with the model in the closed-loop test)


def test_dwell_tool_change_states_and_motion_index():
    nc = nc_with({"rapid": {"to": 0.1}}, {"rapid": {"to": 0.15}}, {"dwell": {"time": 0.3}},
                 {"tool_change": {"position": 0.0, "time": 0.5}}, {"feed": {"to": 0.16, "feed": 0.01}},
                 {"rapid": {"to": 0.0}})
    h = 1e-3
    n = int(round(nc.duration() / h)) + 10
    y = run(nc, h, n)
    # run-length encoding of (state, motion) over the grid
    change = np.flatnonzero(np.any(np.diff(y[:, [STATE, MOTION]], axis=0) != 0, axis=1)) + 1
    blocks = [tuple(int(v) for v in y[k, [STATE, MOTION]]) for k in np.r_[0, change]]
    assert blocks == [(1, 1), (0, 1), (1, 2), (2, 2), (1, 3), (0, 3)]
    # contiguous rapids merge into one motion; the tool change stays state 1 while standing at the changer
    t = np.arange(n + 1) * h
    t_rapids = trapezoid(0, 0, 0.1, 0.22, 0.6)[3] + trapezoid(0, 0.1, 0.15, 0.22, 0.6)[3]
    t_move = trapezoid(0, 0.15, 0.0, 0.22, 0.6)[3]  # to the changer, and the same back
    t_change = t_rapids + 0.3
    assert change[:3].tolist() == [
        math.ceil(x / h - 1e-9) for x in (t_rapids, t_change, t_change + 2 * t_move + 0.5)]
    at_changer = (t >= t_change + t_move - 1e-9) & (t < t_change + t_move + 0.5 - 1e-9)
    assert at_changer.sum() == 500
    assert np.all(y[at_changer, X_REF] == 0.0) and np.all(y[at_changer, V_REF] == 0.0)
    x_out = trapezoid(t - t_change, 0.15, 0.0, 0.22, 0.6)[0]
    x_back = trapezoid(t - t_change - t_move - 0.5, 0.0, 0.15, 0.22, 0.6)[0]
    tool_change = (t >= t_change - 1e-9) & (t < change[2] * h)
    expected = np.where(t < t_change + t_move + 0.5 - 1e-9, x_out, x_back)
    np.testing.assert_allclose(y[tool_change, X_REF], expected[tool_change], rtol=0, atol=1e-12)
    t_feed = t_change + 2 * t_move + 0.5  # the feed starts back where the tool change came from
    x_feed = trapezoid(t - t_feed, 0.15, 0.16, 0.01, 0.6)[0]
    np.testing.assert_allclose(y[change[2]:change[3], X_REF], x_feed[change[2]:change[3]], rtol=0, atol=1e-12)
    assert y[-1, X_REF] == 0.0 and nc.report()["motions"] == 3


def test_identification_request_inserted_once_per_rising_edge():
    ident = {"distance": -0.1, "v_max": 0.2, "accel": 0.5}  # 0.4 s + 0.1 s + 0.4 s each way: 1.8 s
    nc = nc_with({"rapid": {"to": 0.2, "v_max": 0.2, "accel": 0.5}},
                 {"feed": {"to": 0.21, "feed": 0.01, "load": 3.0}},
                 {"rapid": {"to": 0.0, "v_max": 0.2, "accel": 0.5}}, accel=0.5, identification=ident)
    h = 1e-3
    t_rapid1 = trapezoid(0, 0, 0.2, 0.2, 0.5)[3]
    t_feed = trapezoid(0, 0.2, 0.21, 0.01, 0.5)[3]
    t_rapid2 = trapezoid(0, 0.21, 0.0, 0.2, 0.5)[3]
    assert nc.duration() == pytest.approx(t_rapid1 + t_feed + t_rapid2, abs=1e-12)
    t_id = 2 * trapezoid(0, 0, 0.1, 0.2, 0.5)[3]
    # request held high from 0.5 s (during the first rapid) to 3 s, low, then high again after the end
    t_end = nc.duration() + t_id
    n_again = int(round((t_end + 0.5) / h))
    n = n_again + int(round(t_id / h)) + 100
    y = run(nc, h, n, request=lambda k: 1.0 if 500 <= k < 3000 or k >= n_again else 0.0)
    t = np.arange(n + 1) * h
    # first identification: after the first rapid (the next item boundary), from x = 0.2, out to 0.1 and back
    x_id, v_id, _, _ = trapezoid(t - t_rapid1, 0.2, 0.1, 0.2, 0.5)
    x_back, v_back, _, _ = trapezoid(t - t_rapid1 - t_id / 2, 0.1, 0.2, 0.2, 0.5)
    in_id = (t >= t_rapid1 - 1e-9) & (t < t_rapid1 + t_id - 1e-9)
    first_half = t < t_rapid1 + t_id / 2 - 1e-9
    np.testing.assert_allclose(y[in_id, X_REF], np.where(first_half, x_id, x_back)[in_id], rtol=0, atol=1e-12)
    assert np.all(y[in_id, STATE] == 1) and np.all(y[in_id, MOTION] == 1)  # contiguous with the rapid
    # the rest of the program is shifted by the identification time
    in_feed = (t >= t_rapid1 + t_id - 1e-9) & (t < t_rapid1 + t_id + t_feed - 1e-9)
    assert np.all(y[in_feed, STATE] == 2) and np.all(y[in_feed, LOAD] == 3.0)
    x_feed = trapezoid(t - t_rapid1 - t_id, 0.2, 0.21, 0.01, 0.5)[0]
    np.testing.assert_allclose(y[in_feed, X_REF], x_feed[in_feed], rtol=0, atol=1e-12)
    # second rising edge after the program ended: identification at once, from the final position 0.0
    k0 = n_again  # request seen at step n_again, so the motion starts at t_{n_again}
    x_late = trapezoid(t - k0 * h, 0.0, -0.1, 0.2, 0.5)[0]
    np.testing.assert_allclose(y[k0:k0 + 800, X_REF], x_late[k0:k0 + 800], rtol=0, atol=1e-12)
    assert y[k0, STATE] == 0 and y[k0 + 1, STATE] == 1 and y[k0 + 1, MOTION] == 3
    assert y[-1, X_REF] == 0.0 and y[-1, STATE] == 0
    inserted = nc.report()["identifications_inserted_s"]
    assert inserted == pytest.approx([t_rapid1, k0 * h], abs=1e-12)
    states = y[:, STATE]
    assert np.sum((states[1:] == 1) & (states[:-1] != 1)) + (states[0] == 1) == 3  # rapid+id, rapid, id


def test_position_loop_error_decays_geometrically_and_feed_forward_tracks_exactly():
    program = [{"rapid": {"to": 0.3}}, {"feed": {"to": 0.31, "feed": 0.01}}, {"rapid": {"to": -0.05}}]
    h, kv = 1e-4, 30.0
    n = int(nc_with(*program).duration() / h) + 100
    exact = run(nc_with(*program, kv=kv), h, n, plant="integrator")
    planned = run(nc_with(*program, kv=kv), h, n)
    np.testing.assert_allclose(exact[:, X_REF], planned[:, X_REF], rtol=0, atol=0)
    # ideal axis: e_{n+1} = (1 - kv h) e_n with the mid-step speed feed-forward, whatever the plan
    nc = nc_with(*program, kv=kv)
    e0 = 1e-3
    cfg = nc.config
    conv = 2 * math.pi * cfg.belt_ratio / cfg.pitch
    nc.setup(0.0, h, n)
    x, errors = e0, []
    for k in range(n):
        nc.set_inputs([x, 0.0])
        nc.step(k)
        x += h * nc.get_outputs()[SPEED_REF] / conv
        errors.append(nc.get_outputs()[X_REF] - x)
    np.testing.assert_allclose(errors, -e0 * (1 - kv * h) ** np.arange(1, n + 1), rtol=0, atol=1e-12)
    # no feed-forward: e_{n+1} = (1 - kv h) e_n + x_ref(t_{n+1}) - x_ref(t_n); in a long cruise at
    # 0.22 m/s (0.37 s to 1.36 s, time constant 1/kv = 33 ms) it settles at v / kv
    lag = run(nc_with(*program, kv=kv, feed_forward=False), h, n, plant="integrator")
    x_axis = lag[0, X_REF] + np.r_[0.0, np.cumsum(h * lag[1:, SPEED_REF] / conv)]
    e = np.zeros(n + 1)
    for k in range(n):
        e[k + 1] = (1 - kv * h) * e[k] + lag[k + 1, X_REF] - lag[k, X_REF]
    np.testing.assert_allclose(lag[:, X_REF] - x_axis, e, rtol=0, atol=1e-12)
    k_mid = int(1.3 / h)
    assert lag[k_mid, V_REF] == pytest.approx(0.22, abs=1e-12)
    assert lag[k_mid, X_REF] - x_axis[k_mid] == pytest.approx(0.22 / kv, rel=1e-9)


def test_speed_reference_uses_the_configured_drive_chain():
    default = NCConfig.parse({}, "nc")
    nominal = feed_drive().nominal()
    assert (default.pitch, default.belt_ratio) == (nominal["pitch"], nominal["belt_ratio"])
    nc = nc_with({"rapid": {"to": 0.3, "v_max": 0.2, "accel": 0.5}}, pitch=0.01, belt_ratio=2.5)
    y = run(nc, 1e-3, 1000)
    # with the plant on the plan, speed_ref is the mid-step planned speed in motor rad/s
    assert y[800, SPEED_REF] == pytest.approx(0.2 * 2 * math.pi * 2.5 / 0.01, rel=1e-12)
    mid = (y[1:, X_REF] - y[:-1, X_REF]) / 1e-3 * 2 * math.pi * 2.5 / 0.01
    np.testing.assert_allclose(y[1:, SPEED_REF], mid, rtol=1e-12, atol=1e-9)


def test_config_round_trips_through_yaml_shape():
    import yaml

    cfg = NCConfig.parse({"start": 0.1, "program": [{"rapid": {"to": 0.25}}, {"dwell": {"time": 0.2}},
                                                    {"tool_change": {"position": 0.0, "time": 0.5}}]}, "nc")
    dumped = yaml.safe_load(yaml.safe_dump(cfg.model_dump(mode="json")))
    assert dumped["program"][1] == {"dwell": {"time": 0.2}}
    assert NCConfig.parse(dumped, "nc") == cfg


@pytest.mark.parametrize("section, message", [
    ({"program": [{"rapid": {"to": 1.0}}, {"dwell": {"time": 1}}, {"rapid": {"to": 0, "accel": 0}}]},
     "nc.program[2].rapid.accel: must be > 0"),
    ({"program": [{"rapid": {"to": 1.0, "v_max": -0.2}}]}, "nc.program[0].rapid.v_max: must be > 0"),
    ({"program": [{"feed": {"to": 1.0, "feed": 0.0}}]}, "nc.program[0].feed.feed: must be > 0"),
    ({"program": [{"feed": {"to": 1.0}}]}, "nc.program[0].feed.feed: required key is missing"),
    ({"program": [{"jump": {"to": 1.0}}]}, "nc.program[0]: expected a mapping with exactly one of rapid, feed"),
    ({"program": [{"rapid": {"to": 1.0}, "dwell": {"time": 1}}]}, "nc.program[0]: expected a mapping"),
    ({"program": [{"dwell": {"time": -1}}]}, "nc.program[0].dwell.time: must be >= 0"),
    ({"program": [{"rapid": {"to": 1.0, "speed": 2}}]}, "nc.program[0].rapid.speed: unknown key"),
    ({"identification": {"distance": 0}}, "nc.identification.distance: must be non-zero"),
    ({"kv": "fast"}, "nc.kv: Input should be a valid number"),
    ({"pitch": 0}, "nc.pitch: must be > 0"),
    ({"program": {"rapid": {"to": 1}}}, "nc.program: expected a list"),
])
def test_bad_config_names_the_key(section, message):
    with pytest.raises(ScenarioError) as info:
        NCComponent("nc", section)
    assert str(info.value).startswith(message)
    assert "\n" not in str(info.value)


def test_closed_loop_with_the_model_plant_tracks_and_the_cut_loads_the_motor():
    """The NC driving the CasADi feed drive (RK4, 10 substeps per 0.1 ms step): the paper's ~70 rad/s
    rapid, the target reached, and during the cut the mechanical equation's steady current
    K i = ft w + Cd + load, i.e. the load opposes the motion."""
    import casadi as ca

    m = feed_drive()
    x, u, p = m.vectors()
    f = m.rhs_function()
    h, sub = 1e-4, 10
    xk = x
    for _ in range(sub):
        k1 = f(xk, u, p)
        k2 = f(xk + h / sub / 2 * k1, u, p)
        k3 = f(xk + h / sub / 2 * k2, u, p)
        k4 = f(xk + h / sub * k3, u, p)
        xk = xk + h / sub / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    out = [o.name for o in m.outputs]
    plant = ca.Function("plant", [x, u, p], [xk, m.output_function()(xk, u, p)])
    nc = nc_with({"tool_change": {"position": 0.15, "time": 0.1}}, {"feed": {"to": 0.01, "feed": 0.01, "load": 5.0}})
    n = int((nc.duration() + 0.3) / h)
    nc.setup(0.0, h, n)
    par = m.nominal()
    state, position, rows = np.zeros(len(m.states)), 0.0, []
    for k in range(n):
        nc.set_inputs([position, 0.0])
        nc.step(k)
        y = nc.get_outputs()
        state, signals = plant(state, [y[SPEED_REF], y[LOAD], 0.0], list(par.values()))
        signals = signals.full().ravel()
        position = signals[out.index("x")]
        rows.append([y[X_REF], position, signals[out.index("w")], signals[out.index("i")], y[STATE], y[LOAD]])
    r = np.array(rows)
    assert r[-1, 1] == pytest.approx(0.01, abs=1e-6)
    assert np.abs(r[:, 0] - r[:, 1]).max() < 2e-4  # following error below 0.2 mm
    assert np.abs(r[:, 2]).max() == pytest.approx(0.22 * 2 * math.pi / 0.02, rel=0.03)  # the paper's ~70 rad/s
    mid = np.flatnonzero(r[:, 4] == 2)[len(np.flatnonzero(r[:, 4] == 2)) // 2]
    w, i, load = r[mid, 2], r[mid, 3], r[mid, 5]
    assert w == pytest.approx(2 * math.pi * 0.01 / 0.02, rel=1e-4) and load == 5.0
    assert par["K"] * i == pytest.approx(par["ft"] * w + par["Cd"] + load, abs=1e-3)  # load 5 N.m: sign matters
