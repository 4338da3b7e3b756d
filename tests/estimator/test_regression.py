"""Regressions derived from the CasADi model (paper eq. 4, 5)."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from feeddrive.estimator import EstimatorInputError
from feeddrive.estimator.regression import derive_regression
from feeddrive.models import Equation, Model, Variable, feed_drive

MODEL = feed_drive()
RNG = np.random.default_rng(1)
SIG = {k: RNG.standard_normal(7) for k in ("u", "i", "w", "Di", "Dw")}
SIG["sgn_w"] = np.sign(SIG["w"])
ALL = ["R", "L", "K", "Jt", "ft", "Cd"]


def test_electrical_regression_is_eq_4():
    reg = derive_regression(MODEL, "electrical", ALL, {})
    assert reg.names == ("R", "L", "K") and reg.normaliser is None
    y, Phi = reg.evaluate(SIG)
    np.testing.assert_allclose(y, SIG["u"])
    np.testing.assert_allclose(Phi, np.column_stack([SIG["i"], SIG["Di"], SIG["w"]]))


def test_mechanical_regression_is_eq_5_normalised_by_K():
    reg = derive_regression(MODEL, "mechanical", ALL, {})
    assert reg.names == ("Jt", "ft", "Cd") and reg.normaliser == "K"
    y, Phi = reg.evaluate(SIG)
    np.testing.assert_allclose(y, SIG["i"])
    np.testing.assert_allclose(Phi, np.column_stack([SIG["Dw"], SIG["w"], SIG["sgn_w"]]))


def test_the_regressors_alone_are_evaluates_phi():
    """Regression.regressors (the instruments' Phi, y not formed): evaluate's Phi, the same bits and strides."""
    for eq, known in (("electrical", {}), ("mechanical", {}), ("mechanical", {"K": 0.3})):
        reg = derive_regression(MODEL, eq, ALL, known)
        Phi, alone = reg.evaluate(SIG)[1], reg.regressors(SIG)
        np.testing.assert_array_equal(alone, Phi)
        assert alone.strides == Phi.strides


def test_the_optional_offset_term_adds_a_column_of_ones():
    reg = derive_regression(MODEL, "mechanical", ALL + ["T0"], {})
    assert reg.names == ("Jt", "ft", "Cd", "T0")
    _, Phi = reg.evaluate(SIG)
    np.testing.assert_allclose(Phi[:, 3], 1.0)


def test_a_known_K_moves_the_torque_to_the_output_and_removes_the_normaliser():
    reg = derive_regression(MODEL, "mechanical", ALL, {"K": 2.0})
    assert reg.names == ("Jt", "ft", "Cd") and reg.normaliser is None
    y, _ = reg.evaluate(SIG)
    np.testing.assert_allclose(y, 2.0 * SIG["i"])
    elec = derive_regression(MODEL, "electrical", ALL, {"K": 2.0})
    y, Phi = elec.evaluate(SIG)
    assert elec.names == ("R", "L")
    np.testing.assert_allclose(y, SIG["u"] - 2.0 * SIG["w"])


def test_a_model_nonlinear_in_its_parameters_is_refused():
    V = Variable
    variables = [V("i", "A", "current", "state", 0.0), V("u", "V", "voltage", "input", 0.0),
                 V("R", "Ohm", "resistance", "physical", 1.0), V("L", "H", "inductance", "physical", 1.0)]
    s = {v.name: v.sym for v in variables}
    der = ca.SX.sym("der_i")
    eq = Equation("electrical", s["L"] * s["R"] * der + s["R"] * s["i"] - s["u"], "i", "u", None, "test")
    model = Model("NonLinear", variables, [eq], {}, {}, "test", derivative_symbols={"i": der})
    with pytest.raises(EstimatorInputError, match="not linear"):
        derive_regression(model, "electrical", ["R", "L"], {})


def test_numpy_evaluation_equals_casadi():
    from feeddrive.estimator.regression import numpy_function

    x = ca.SX.sym("x", 3)
    f = ca.Function("f", [x], [ca.vertcat(2 * x[0] - x[1] / x[2], ca.tanh(x[2] / 0.1) * x[0] ** 2, -x[1], 3.0)])
    X = RNG.uniform(0.5, 2.0, (3, 11))
    np.testing.assert_allclose(numpy_function(f)(X), np.asarray(f.map(11)(X)), rtol=1e-14)
