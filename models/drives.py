"""Drive kinds: the model of each motor and what the estimator measures on it (issue 25).

``drive_model("dc")`` is ``feed_drive()``, ``"pmsm"`` is ``pmsm_drive()``, ``"pmsm-spm"`` is
``pmsm_drive(surface=True)``. The estimator takes the model as data; what it needs to know about a
model is derived here from its equations, never from the motor's name:

* the *states* of the physical equations (each equation's ``solves_for``: DC ``i, w``; PMSM ``i_q, i_d,
  w``): measured and differentiated;
* the *measured* signals: those states, and the algebraic signals in the residuals that are neither
  defined from a physical parameter (the PMSM's air-gap torque, substituted by its definition) nor a
  function of the equations' states alone (``sgn_w``, computed from the speed): DC ``u``, PMSM ``u_q, u_d``;
* *derived* quantities: expressions of the parameters reported next to them (PMSM: ``K_t = 1.5 p psi_f``
  and ``K_e = p psi_f``).

Known design parameters (the PMSM's pole pairs ``p``) are the model's nominal values, replaced with
:func:`with_design` when the user knows better.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace
from functools import cache, lru_cache

import casadi as ca

from feeddrive.models.base import Model
from feeddrive.models.feed_drive import feed_drive
from feeddrive.models.pmsm import pmsm_drive

#: drive kind -> model builder
DRIVES: dict[str, Callable[[], Model]] = {
    "dc": feed_drive,
    "pmsm": pmsm_drive,
    "pmsm-spm": lambda: pmsm_drive(surface=True),
}

#: model name -> derived quantity -> (unit, description, expression builder from the model's symbols)
_DERIVED: dict[str, dict[str, tuple[str, str, Callable[[Mapping[str, ca.SX]], ca.SX]]]] = {
    name: {
        "K_t": ("N.m/A", "torque constant 1.5 p psi_f (peak current)", lambda s: 1.5 * s["p"] * s["psi_f"]),
        "K_e": ("V.s/rad", "back-EMF constant p psi_f (mechanical speed, phase peak)", lambda s: s["p"] * s["psi_f"]),
    } for name in ("PMSMFeedDrive", "PMSMFeedDriveSPM")
}


@cache
def drive_model(kind: str) -> Model:
    """The model of a drive kind (one object per kind, so the estimator's caches are shared).

    Raises
    ------
    ValueError
        ``kind`` is not one of ``DRIVES``.
    """
    if kind not in DRIVES:
        raise ValueError(f"drive must be one of {sorted(DRIVES)}, got {kind!r}")
    return DRIVES[kind]()


@lru_cache(maxsize=32)
def _with_design(model: Model, items: tuple[tuple[str, float], ...]) -> Model:
    variables = [replace(v, nominal=float(dict(items)[v.name])) if v.name in dict(items) else v
                 for v in model.variables.values()]
    return Model(model.name, variables, list(model.equations.values()), model._explicit, model.algebraic,
                 model.description, derivative_symbols=model.derivative)


def with_design(model: Model, design: Mapping[str, float]) -> Model:
    """``model`` with the nominal values of some design parameters replaced (the same symbols and equations).

    Parameters
    ----------
    model : Model
    design : mapping of str to float
        Design parameter -> its known value (``{"p": 3}``: three pole pairs).

    Returns
    -------
    Model
        ``model`` itself when nothing changes; otherwise one cached object per (model, values).
    """
    bad = [k for k in design if k not in model.variables or model.variables[k].kind != "design"]
    if bad:
        raise ValueError(f"{bad[0]!r} is not a design parameter of {model.name}")
    items = tuple(sorted((k, float(v)) for k, v in design.items() if float(v) != model.variables[k].nominal))
    return _with_design(model, items) if items else model


def _residual_symbols(model: Model) -> set[str]:
    return {s.name() for e in model.equations.values() for s in ca.symvar(e.residual)}


def parameter_defined(model: Model) -> tuple[str, ...]:
    """Algebraic signals of the residuals defined from physical parameters (the PMSM's torque): substituted."""
    phys = [v.sym for v in model.of_kind("physical")]
    used = _residual_symbols(model)
    return tuple(n for n, d in model.algebraic.items()
                 if model.variables[n].sym.name() in used and any(ca.depends_on(d, p) for p in phys))


def differentiated(model: Model) -> tuple[str, ...]:
    """The states of the physical equations, in equation order: measured and differentiated."""
    return tuple(e.solves_for for e in model.equations.values())


def computed(model: Model) -> tuple[str, ...]:
    """Algebraic signals of the residuals that are functions of the equations' states alone (``sgn_w``)."""
    states = {model.variables[s].sym.name() for s in differentiated(model)}
    used = _residual_symbols(model)
    out = []
    for n, d in model.algebraic.items():
        if model.variables[n].sym.name() not in used:
            continue
        deps = {s.name() for s in ca.symvar(d)}
        non_design = {s for s in deps if s in {v.sym.name() for v in model.variables.values() if v.kind != "design"}}
        if non_design and non_design <= states:
            out.append(n)
    return tuple(out)


def measured(model: Model) -> tuple[str, ...]:
    """Signals measured on the drive: the equations' states, then the measured algebraic signals (voltages)."""
    skip = set(parameter_defined(model)) | set(computed(model))
    used = _residual_symbols(model)
    alg = [n for n in model.algebraic if n not in skip and model.variables[n].sym.name() in used]
    return differentiated(model) + tuple(alg)


def derived_quantities(model: Model) -> dict[str, tuple[str, str, ca.SX]]:
    """Derived quantity -> ``(unit, description, expression)`` in the model's parameter symbols; {} for DC."""
    s = {v.name: v.sym for v in model.variables.values()}
    return {k: (unit, text, f(s)) for k, (unit, text, f) in _DERIVED.get(model.name, {}).items()}


def parameter_order() -> tuple[str, ...]:
    """Every drive kind's physical parameter names, each kind's own order kept (a new name right after the one
    it follows in its model): R, L_d, L_q, psi_f, L, K, Jt, ft, Cd, T0 sorts the DC and the PMSM sets alike."""
    order: list[str] = []
    for kind in DRIVES:
        prev = None
        for v in drive_model(kind).of_kind("physical"):
            if v.name not in order:
                order.insert(order.index(prev) + 1 if prev else 0, v.name)
            prev = v.name
    return tuple(order)
