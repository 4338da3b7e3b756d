"""Model-based simulation of the feed drive's physical equations (the IV instruments, OE, validation).

Each model equation is solved for the derivative of its state, as the model does for its ODE; the
signals that are not simulated are measured inputs. Dry friction uses the model's smoothed sign with
a smoothing speed ``w_eps`` chosen for the integration step (the estimator excludes the samples near
zero speed where it differs from the exact sign). RK4, inputs linearly interpolated between samples.
"""
from __future__ import annotations

from collections.abc import Mapping
from functools import lru_cache

import casadi as ca
import numpy as np

from feeddrive.estimator.errors import EstimatorInputError, NumericalFailure
from feeddrive.models.drives import drive_model

MODEL = drive_model("dc")  # the DC feed drive, the default model (the same object as EstimationOptions(model="dc"))
#: Default smoothing speed of sign(w) in simulations [rad/s]: well below the estimator's speed threshold.
W_EPS = 0.1


@lru_cache(maxsize=32)
def _ode(model, equations: tuple[str, ...], inputs: tuple[str, ...]):
    """ODE ``f(x, s, p)`` of the states solved by ``equations``; s = inputs, p = physical params + w_eps."""
    eqs = [model.equations[e] for e in equations]
    states = [e.solves_for for e in eqs]
    x = [model.variables[s].sym for s in states]
    s = [model.variables[n].sym for n in inputs]
    phys = [v for v in model.parameters if v.kind == "physical"]
    p = [v.sym for v in phys] + [model.variables["w_eps"].sym]
    rhs = []
    for e in eqs:
        r = e.residual
        # algebraic signals that are not measured inputs get their model definition (sgn_w = tanh(w/w_eps))
        for name, definition in model.algebraic.items():
            if name not in inputs and ca.depends_on(r, model.variables[name].sym):
                r = ca.substitute(r, model.variables[name].sym, definition)
        d = model.derivative[e.solves_for]
        rhs.append(-ca.substitute(r, d, 0) / ca.jacobian(r, d))
    rhs = ca.vertcat(*rhs)
    others = [v for v in model.variables.values()
              if ca.depends_on(rhs, v.sym) and v.sym.name() not in {y.name() for y in x + s + p}]
    zero = [v for v in others if v.kind == "input"]  # load torque: zero in a high-speed motion
    design = [v for v in others if v.kind == "design"]
    unknown = [v.name for v in others if v.kind not in ("input", "design")]
    if unknown:
        raise EstimatorInputError(f"simulating {equations} needs the signals {unknown} as inputs")
    rhs = ca.substitute(rhs, ca.vertcat(*[v.sym for v in zero + design]),
                        ca.DM([0.0] * len(zero) + [float(v.nominal) for v in design])) if zero + design else rhs
    used = tuple(v for v in phys if ca.depends_on(rhs, v.sym))
    return ca.Function("ode", [ca.vertcat(*x), ca.vertcat(*s), ca.vertcat(*p)], [rhs]), tuple(states), phys, used


def rk4_step(f: ca.Function, substeps: int) -> ca.Function:
    """One sample period of classical RK4 for ``f(x, s, p) -> dx/dt``.

    Returns ``step(x, [s0; s1], p, h) -> x(h)``: ``substeps`` RK4 substeps of ``h / substeps``, the
    inputs s interpolated linearly from s0 to s1 across the period (a held input would turn a ramp
    into a staircase, see ``models/feed_drive.py``).
    """
    x, p, h = ca.SX.sym("x", f.size1_in(0)), ca.SX.sym("p", f.size1_in(2)), ca.SX.sym("h")
    s0, s1 = ca.SX.sym("s0", f.size1_in(1)), ca.SX.sym("s1", f.size1_in(1))
    dt = h / substeps
    xk = x
    for k in range(substeps):
        a, b = s0 + (s1 - s0) * (k / substeps), s0 + (s1 - s0) * ((k + 1) / substeps)
        k1 = f(xk, a, p)
        k2 = f(xk + dt / 2 * k1, (a + b) / 2, p)
        k3 = f(xk + dt / 2 * k2, (a + b) / 2, p)
        k4 = f(xk + dt * k3, b, p)
        xk = xk + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return ca.Function("step", [x, ca.vertcat(s0, s1), p, h], [xk])


@lru_cache(maxsize=32)
def _rollout(model, equations: tuple[str, ...], inputs: tuple[str, ...], n: int, substeps: int):
    """``F(x0, S (2 len(inputs), n-1), p, h) -> X (nx, n-1)``: RK4 from each sample to the next."""
    f = _ode(model, equations, inputs)[0]
    return rk4_step(f, substeps).mapaccum("rollout", n - 1, [0], [0])


def simulate(equations: tuple[str, ...], inputs: Mapping[str, np.ndarray], params: Mapping[str, float], h: float,
             x0: Mapping[str, float], step: float | None = None, w_eps: float = W_EPS, model=MODEL,
             at: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Simulate the states solved by ``equations`` from measured inputs.

    Parameters
    ----------
    equations : tuple of str
        Model equations to integrate (``("electrical",)``, ``("mechanical",)`` or both).
    inputs : mapping of str to ndarray, each shape (n,)
        Measured signals the equations need and do not simulate (``u``, ``i``, ``w``), sampled every h.
    params : mapping of str to float
        Physical parameters; missing optional ones take their nominal value.
    h : float
        Sampling period of the inputs [s].
    x0 : mapping of str to float
        Initial value of each simulated state at the first sample.
    step : float, optional
        Integration step [s], a multiple of h; the result is interpolated back (cubic) to every sample.
        Default: h.
    w_eps : float
        Smoothing speed of sign(w) [rad/s].
    at : ndarray, shape (m,), optional
        Fractional sample indices to return the states at (cubic interpolation); default every sample.

    Returns
    -------
    dict of str to ndarray, shape (n,) or (m,)
        The simulated states.
    """
    names = tuple(sorted(inputs))
    n = len(next(iter(inputs.values())))
    k = max(1, int(round((step or h) / h)))
    idx = np.arange(0, n, k)
    if idx[-1] != n - 1:
        idx = np.append(idx, n - 1)
    f, states, phys, used = _ode(model, tuple(equations), names)
    values = []
    for v in phys:
        if v.name not in params and v in used and not v.optional:
            raise EstimatorInputError(f"simulation needs parameter {v.name!r}")
        values.append(float(params.get(v.name, v.nominal)))
    if len(idx) < 2:
        raise EstimatorInputError(f"simulation needs at least 2 samples, got {n}")
    # the samples idx by strides (and the last one when the stride steps over it), not a gather by index
    S, every = np.empty((len(names), idx.size)), (n - 1) // k + 1
    for row, m in zip(S, names):
        x = np.asarray(inputs[m], dtype=float)
        row[:every] = x[:n:k]
        row[every:] = x[n - 1:n]
    hk = np.diff(idx) * h
    # mapaccum needs one step size: integrate the uniform part, the last (shorter) step separately
    uniform = hk == k * h
    m = int(uniform.sum()) + 1
    x = np.array([float(x0[s]) for s in states])
    X = _roll(model, tuple(equations), names, m, 2 if k > 1 else 1, x, np.vstack([S[:, :m - 1], S[:, 1:m]]),
              values + [w_eps], k * h)
    X = np.hstack([x[:, None], X])
    if m < len(idx):  # one step of the same RK4 (2 substeps), compiled when it could be built
        xe = _roll(model, tuple(equations), names, 2, 2, X[:, -1], np.concatenate([S[:, m - 1], S[:, m]])[:, None],
                   values + [w_eps], hk[-1])
        X = np.hstack([X, xe.reshape(-1, 1)])
    if not np.all(np.isfinite(X)):
        # e.g. an electrical time constant L/R far below the integration step: explicit RK4 diverges
        tau = {"electrical": ("L", "R"), "mechanical": ("Jt", "ft")}
        hint = "; ".join(f"{e} time constant {a}/{b} = {params[a] / params[b]:.3g} s"
                         for e, (a, b) in tau.items() if e in equations and params.get(b) and a in params)
        raise NumericalFailure(f"the simulation of the {' and '.join(equations)} equation(s) is unstable or non-finite "
                               f"with an integration step of {k * h:.3g} s" + (f" ({hint})" if hint else ""))
    if k > 1 or at is not None:
        at = np.arange(n, dtype=float) if at is None else np.asarray(at, dtype=float)
        X = _spline(idx.astype(float), X, at, uniform_intervals(n, k, at))
    return {s: X[j] for j, s in enumerate(states)}


def simulate_current(u: np.ndarray, w: np.ndarray, params: Mapping[str, float], h: float, i0: float = 0.0,
                     step: float | None = None) -> np.ndarray:
    """Current from voltage and speed, electrical equation: ``I(s) = (U(s) - K W(s)) / (L s + R)``.

    This is the paper's Ir_hat (section IV.B) when ``u``, ``w`` are the validated filtered signals and
    ``params`` the last validated R, L, K.

    Parameters
    ----------
    u, w : ndarray, shape (n,)
        Armature voltage [V] and motor speed [rad/s], sampled every h.
    params : mapping
        At least ``R`` [Ohm], ``L`` [H], ``K`` [V.s/rad].
    h : float
        Sampling period [s].
    i0 : float
        Current at the first sample [A].
    step : float, optional
        Integration step [s] (a multiple of h); default h.

    Returns
    -------
    ndarray, shape (n,)
        Simulated current [A].
    """
    return simulate(("electrical",), {"u": u, "w": w}, params, h, {"i": i0}, step)["i"]


def simulate_speed(i: np.ndarray, params: Mapping[str, float], h: float, w0: float = 0.0,
                   step: float | None = None, w_eps: float = W_EPS) -> np.ndarray:
    """Speed from current, mechanical equation: ``Jt dw/dt = K i - ft w - Cd sign(w) - T0``.

    Used for model validation (measured speed against speed simulated from the estimated model).
    For a torque signal, pass it as ``i`` with ``K = 1``.

    Parameters
    ----------
    i : ndarray, shape (n,)
        Armature current [A], sampled every h.
    params : mapping
        At least ``K, Jt, ft, Cd`` (``T0`` defaults to 0).
    h : float
        Sampling period [s].
    w0 : float
        Speed at the first sample [rad/s].
    step : float, optional
        Integration step [s] (a multiple of h); default h.
    w_eps : float
        Smoothing speed of sign(w) [rad/s].

    Returns
    -------
    ndarray, shape (n,)
        Simulated speed [rad/s].
    """
    return simulate(("mechanical",), {"i": i}, params, h, {"w": w0}, step, w_eps)["w"]


def simulate_motor(u: np.ndarray, params: Mapping[str, float], h: float, i0: float = 0.0, w0: float = 0.0,
                   step: float | None = None, w_eps: float = W_EPS) -> tuple[np.ndarray, np.ndarray]:
    """Current and speed from the voltage alone (both equations coupled).

    Returns
    -------
    i, w : ndarray, shape (n,)
        Simulated current [A] and speed [rad/s].
    """
    x = simulate(("electrical", "mechanical"), {"u": u}, params, h, {"i": i0, "w": w0}, step, w_eps)
    return x["i"], x["w"]


@lru_cache(maxsize=32)
def _step(model, equations: tuple[str, ...], inputs: tuple[str, ...], substeps: int):
    """The RK4 step of ``_rollout`` and its compiled rollout (None without a C compiler)."""
    from feeddrive.estimator.compiled import compiled_step

    step = rk4_step(_ode(model, equations, inputs)[0], substeps)
    return step, compiled_step(step, f"{model.name}: {equations} from {inputs}, {substeps} RK4 substeps")


def _roll(model, equations: tuple[str, ...], inputs: tuple[str, ...], m: int, substeps: int, x: np.ndarray,
          S: np.ndarray, p: list[float], h: float) -> np.ndarray:
    """States (nx, m - 1) after each of the m - 1 RK4 steps from x: compiled C when it could be built, else
    the CasADi ``mapaccum`` (the same operations, tests/estimator/test_speed.py)."""
    run = _step(model, equations, inputs, substeps)[1]
    if run is not None:
        return run(x, S, np.asarray(p, dtype=float), h)
    roll = _rollout(model, equations, inputs, m, substeps)
    return np.asarray(roll(x, S, p, h)).reshape(len(x), -1)


def _spline(x: np.ndarray, Y: np.ndarray, at: np.ndarray, j: np.ndarray | None = None) -> np.ndarray:
    """``CubicSpline(x, Y, axis=1)(at)`` (not-a-knot, extrapolated), its arithmetic step by step, bit for bit.

    ``x`` (n,) increasing knots, ``Y`` (m, n) finite values, ``at`` (q,): returns (m, q). scipy's class spends
    most of its time on a few thousand knots checking its inputs (twice: as a spline and as a Hermite spline)
    and building a PPoly; the simulation's knots are known to be increasing and its states finite. The same
    banded system (its diagonals, right-hand side and LAPACK solve), the same coefficients and the same
    evaluation (``sum c_k u^k`` with the powers of ``u`` built by products, as scipy's ``evaluate_poly1``);
    tests/estimator/test_speed.py compares the two. Fewer than 4 knots: scipy's own. ``j`` (q,), optional: the
    interval of each time (``_interval_of(x, at)``), when the caller knows it (``uniform_intervals``).
    """
    n = x.size
    if n < 4:
        from scipy.interpolate import CubicSpline  # here: scipy.interpolate takes 0.5-1 s to import

        return CubicSpline(x, Y, axis=1)(at)
    from feeddrive.estimator import spline_c

    if spline_c.available():  # the same steps in two C loops around the same gtsv (0.3 -> 0.1 ms a call)
        return spline_c.spline(x, Y, at, _interval_of(x, at) if j is None else j)
    from scipy.linalg.lapack import dgtsv

    y = Y.T
    dx = np.diff(x)
    dxr = dx[:, None]
    slope = np.diff(y, axis=0) / dxr
    # the tridiagonal system's diagonals (solve_banded's rows of ab for (1, 1): upper, main, lower), given to the
    # LAPACK routine it calls for them (gtsv) without its wrapper's checks: the same solve
    upper, main, lower = np.empty(n - 1), np.empty(n), np.empty(n - 1)
    b = np.empty(y.shape)
    main[1:-1] = 2 * (dx[:-1] + dx[1:])
    upper[1:] = dx[:-1]
    lower[:-1] = dx[1:]
    b[1:-1] = 3 * (dxr[1:] * slope[:-1] + dxr[:-1] * slope[1:])
    d = x[2] - x[0]  # not-a-knot at the start ...
    main[0], upper[0] = dx[1], d
    b[0] = ((dxr[0] + 2 * d) * dxr[1] * slope[0] + dxr[0] ** 2 * slope[1]) / d
    d = x[-1] - x[-3]  # ... and at the end
    main[-1], lower[-1] = dx[-2], d
    b[-1] = (dxr[-1] ** 2 * slope[-2] + (2 * d + dxr[-1]) * dxr[-2] * slope[-1]) / d
    s, info = dgtsv(lower, main, upper, b, 1, 1, 1, 1)[3:]
    if info > 0:
        raise np.linalg.LinAlgError("singular matrix")
    t = (s[:-1] + s[1:] - 2 * slope) / dxr
    j = _interval_of(x, at) if j is None else j
    # take() along the rows: the same values as indexing with j, without the general indexing's iterator
    # (2.4x faster on these (n, 1) arrays)
    u = (at - x.take(j))[:, None]
    z = u
    res = 0.0 + y[:-1].take(j, axis=0) * 1.0
    res = res + s[:-1].take(j, axis=0) * z
    z = z * u
    res = res + ((slope - s[:-1]) / dxr - t).take(j, axis=0) * z
    z = z * u
    res = res + (t / dxr).take(j, axis=0) * z
    return res.T


#: the last knots, times and intervals of ``_interval_of``: the instruments simulate each equation of a half on
#: the same knots and read it at the same times (two splines of the same layout per half and IV iteration)
_LAST_INTERVALS: tuple = ()


def _interval_of(x: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The interval of the knots ``x`` (n,) each time of ``at`` falls in, the end ones extrapolated:
    ``clip(searchsorted(x, at, "right") - 1, 0, n - 2)``, kept for the next call with the same values."""
    global _LAST_INTERVALS
    last = _LAST_INTERVALS  # one read: another thread may replace it meanwhile
    if last and last[0].shape == x.shape and last[1].shape == at.shape and np.array_equal(last[0], x) \
            and np.array_equal(last[1], at):
        return last[2]
    j = np.clip(_intervals(x, at) - 1, 0, x.size - 2)
    j.setflags(write=False)
    _LAST_INTERVALS = (x.copy(), at.copy(), j)
    return j


def uniform_intervals(n: int, k: int, at: np.ndarray) -> np.ndarray:
    """``_interval_of(x, at)`` for the simulation's knots ``x``: every ``k``-th of ``n`` samples (``0, k, 2k, ...``)
    and the last one, ``n - 1``, when the stride steps over it; from the integers, not a search.

    A knot ``i k`` (an integer) is <= ``t`` exactly when it is <= ``floor(t)``: ``floor(t) // k + 1`` of the
    strided knots are, at most all ``(n - 1) // k + 1`` of them, and the last knot ``n - 1`` when ``floor(t)``
    reaches it; the interval is that count less one, clipped to the first and the last (the same integers as
    the search, tests/estimator/test_simulation_intervals.py). ``at`` (q,) finite [samples]; returns (q,) intp.
    """
    every = (n - 1) // k + 1  # the strided knots 0, k, ..., (every - 1) k
    knots = every + int((n - 1) % k != 0)
    f = (at + 1.0).astype(np.intp)  # floor(t) + 1 for t >= -1 (truncation); below, a count <= 0 all the same
    f -= 1
    if knots > every:
        extra = f >= n - 1
    f //= k
    f += 1
    np.minimum(f, every, out=f)
    if knots > every:
        f += extra
    f -= 1
    return np.clip(f, 0, knots - 2, out=f)  # the interval: the count less one, the ends extrapolated


def _intervals(x: np.ndarray, at: np.ndarray) -> np.ndarray:
    """``np.searchsorted(x, at, side="right")``: how many knots ``x`` (increasing) are <= each of ``at``.

    ``at`` sorted (a simulation's sample times, every sample): counted from where each knot falls among them
    (``len(x)`` searches instead of ``len(at)``, the same integers); otherwise the search itself.
    """
    if not np.all(at[1:] >= at[:-1]):
        return np.searchsorted(x, at, side="right")
    first = np.searchsorted(at, x, side="left")  # knot i is <= at[t] for every t >= first[i]
    return np.cumsum(np.bincount(first, minlength=at.size + 1)[:at.size])
