"""The CasADi model: metadata, the derived ODE against the implicit equations, analytic steady states."""
import casadi as ca
import numpy as np
import pytest

from feeddrive.models import Variable, feed_drive


@pytest.fixture(scope="module")
def model():
    return feed_drive()


def test_metadata_complete(model):
    assert [v.name for v in model.of_kind("physical")] == ["R", "L", "K", "Jt", "ft", "Cd", "T0"]
    assert [v.name for v in model.outputs] == ["i", "w", "theta", "i_ref", "u_ref", "u", "x"]
    assert [v.name for v in model.inputs] == ["w_ref", "Tl", "u_in"]
    for v in model.variables.values():
        assert v.unit and v.description, v.name
        if v.is_parameter:
            assert v.source, f"{v.name} has no documented source"
            if v.lower is not None:
                assert v.nominal > v.lower or (v.nominal == v.lower and not v.lower_strict), v.name
    assert [o.name for o in model.of_kind("physical") if o.optional] == ["T0"]


def test_explicit_ode_satisfies_the_implicit_equations(model):
    """Substituting the derived derivatives back into each paper equation gives zero residual."""
    x, u, p = model.vectors()
    xdot = model.state_derivatives()
    rng = np.random.default_rng(0)
    nominal = np.array(list(model.nominal().values()))
    for eq in model.equations.values():
        k = [s.name for s in model.states].index(eq.solves_for)
        r = model._substitute_algebraic(ca.substitute(eq.residual, model.derivative[eq.solves_for], xdot[k]))
        f = ca.Function("r", [x, u, p], [r])
        for _ in range(20):
            xv = rng.normal(size=x.shape[0]) * [5, 30, 3, 5, 20, 30]
            uv = rng.normal(size=u.shape[0]) * [50, 2, 60]
            assert abs(float(f(xv, uv, nominal))) < 1e-9


@pytest.mark.parametrize("w_ref", [70.0, -35.0, 5.0])
def test_closed_loop_steady_state_is_analytic(model, w_ref):
    """At a constant speed reference: w = w_ref, i = (ft w + Cd)/K, u = R i + K w."""
    x, u, p = model.vectors()
    nominal = model.nominal()
    pv = ca.DM([nominal[v.name] for v in model.parameters])
    uv = ca.DM([w_ref, 0.0, 0.0])
    names = [s.name for s in model.states]
    free = [k for k, n in enumerate(names) if n != "theta"]
    z = ca.SX.sym("z", len(free))
    xs = ca.SX.zeros(len(names))
    for j, k in enumerate(free):
        xs[k] = z[j]
    xdot = ca.substitute(model.state_derivatives(), ca.vertcat(x, u, p), ca.vertcat(xs, uv, pv))
    solve = ca.rootfinder("ss", "newton", ca.Function("f", [z], [xdot[free]]), {"abstol": 1e-13})
    K, R, ft, Cd = (nominal[n] for n in ("K", "R", "ft", "Cd"))
    i_ss = (ft * w_ref + Cd * np.sign(w_ref)) / K
    guess = {"i": i_ss, "w": w_ref, "xi_w": i_ss, "xi_i": R * i_ss + K * w_ref, "w_rf": w_ref}
    zs = np.array(solve([guess[names[k]] for k in free])).ravel()
    state = dict(zip([names[k] for k in free], zs))
    assert state["w"] == pytest.approx(w_ref, rel=1e-12)
    assert state["i"] == pytest.approx(i_ss, rel=1e-9)
    y = np.array(model.output_function()([state.get(n, 0.0) for n in names], uv, pv)).ravel()
    out = dict(zip([o.name for o in model.outputs], y))
    assert out["u"] == pytest.approx(R * i_ss + K * w_ref, rel=1e-9)
    assert out["u_ref"] == pytest.approx(out["u"], rel=1e-12)  # ideal converter, Kc = 1


def test_bypass_freezes_the_loops_and_passes_u_in(model):
    x, u, p = model.vectors()
    values = {**model.nominal(), "bypass": 1.0}
    pv = [values[v.name] for v in model.parameters]
    xdot = np.array(model.rhs_function()([2.0, 10.0, 0.0, 3.0, 4.0, 0.0], [50.0, 0.0, 24.0], pv)).ravel()
    R, L, K = values["R"], values["L"], values["K"]
    assert xdot[0] == pytest.approx((24.0 - R * 2.0 - K * 10.0) / L, rel=1e-12)
    assert xdot[3] == 0.0 and xdot[4] == 0.0


def test_backlash_variant_static_twist():
    """At constant speed the chain transmits the load friction: twist = gap/2 + (ft w + Cd)/k_s."""
    m = feed_drive(backlash=True)
    names = [s.name for s in m.states]
    assert names[-2:] == ["wl", "thetal"] and m.name == "FeedDriveBacklash"
    nominal = m.nominal()
    w = 40.0
    friction = nominal["ft"] * w + nominal["Cd"]
    twist = nominal["backlash"] / 2 + friction / nominal["k_s"]
    i = friction / nominal["K"]
    x = {"i": i, "w": w, "theta": twist, "xi_w": i, "xi_i": nominal["R"] * i + nominal["K"] * w,
         "w_rf": w, "wl": w, "thetal": 0.0}
    pv = [nominal[v.name] for v in m.parameters]
    xdot = np.array(m.rhs_function()([x[n] for n in names], [w, 0.0, 0.0], pv)).ravel()
    d = dict(zip(names, xdot))
    assert abs(d["w"]) < 1e-9 and abs(d["wl"]) < 1e-9 and abs(d["i"]) < 1e-9


def test_variable_validation():
    with pytest.raises(ValueError, match="kind"):
        Variable("q", "1", "bad", "constant")
    with pytest.raises(ValueError, match="outputs"):
        Variable("q", "1", "bad", "physical", 1.0, output=True)


def test_symbol_lookup(model):
    assert model.symbol("i") is model.variables["i"].sym
    assert model.symbol("der(i)") is model.derivative["i"]
    assert ca.depends_on(model.equations["electrical"].residual, model.symbol("der(i)"))
