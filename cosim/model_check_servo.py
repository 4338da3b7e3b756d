"""The paper's output-error model check of a PMSM motion in the monitor (issue 25 item 4).

``estimator.model_check.check_model_equations`` on the servo drive's signals, chosen as the DC monitor's
``check_signals`` does: the simulation runs on the first sensor of each pair and the second one, whose noise is
independent, is the instrument of the independence test:

    input   first (simulated from, compared with)          instrument
    u_q     terminal voltage ``u_q`` (or ``u``)              the regulator's reference ``u_q_ref``
    u_d     terminal voltage ``u_d``                         ``u_d_ref``
    i_q     current sensor 1 ``Im1``                         ``Im2``
    w       tachometer ``w_tach``                            encoder speed ``w_enc``
    i_d     the recording's or the phases' Park transform    none (not a regressor of the test)

A sensor named in a fault is neither (the estimator's signal is used, uninstrumented). Without any second sensor
(a recording of the drive's dq signals) the check is not run, said so: regressed on the very inputs whose noise
the residue carries, its independence test rejected both healthy motions of tests/cosim/test_monitor_pmsm.py. Sensor noises from
first differences (``validation.noise_std``). Nothing here knows the motor beyond these signal names: the
equations, their parameters and the simulations come from the model.
"""
from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

import numpy as np

from feeddrive.estimator.errors import FAILURES
from feeddrive.estimator.model_check import check_model_equations
from feeddrive.estimator.validation import noise_std

#: input -> (first sensors in order of preference, instrument)
PAIRS = {"u_q": (("u_q", "u"), "u_q_ref"), "u_d": (("u_d",), "u_d_ref"), "i_q": (("Im1",), "Im2"),
         "w": (("w_tach",), "w_enc")}


def servo_model_check(pipe: Any, signals: Mapping[str, Any], dq: Mapping[str, np.ndarray],  # noqa: ANN401
                      best: Mapping[str, np.ndarray], h: float, est: Any, faults: list) -> tuple:  # noqa: ANN401
    """``(MismatchResult or None, why it was not checked or None)`` for one PMSM motion.

    ``pipe`` is the ``MonitorPipeline``; ``dq`` and ``best`` the signals the estimator got; ``est`` its
    ``MotionEstimate``; ``faults`` the motion's sensor faults (report.json ``sensor_faults``).
    """
    cfg, model = pipe.config, pipe.estimation_options.model
    values = {**est.fixed, **est.lumped, **{n: q.value for n, q in est.parameters.items()}}
    if not {v.name for v in model.of_kind("physical") if not v.optional} <= set(values):
        return None, "not checked: needs every parameter estimated or known"
    faulty = {tok for f in faults if isinstance(f, Mapping) for tok in re.split(r" or |, ", str(f.get("sensor", "")))}
    x = {**dq, "w": best["w"]}
    inst = {}
    for name, (firsts, second) in PAIRS.items():
        first = next((s for s in firsts if signals.get(s) is not None and s not in faulty), None)
        if first is None or signals.get(second) is None or second in faulty:
            continue
        x[name] = np.asarray(signals[first], float)
        inst[name] = np.asarray(signals[second], float)
    if not inst:  # the residue carries the inputs' noise: regressed on the same signals, it rejected healthy motions
        return None, ("not checked: no second sensor of an input (u_q_ref, u_d_ref, Im2, w_enc) to instrument the "
                      "output-error check's independence test; the residue check decides")
    noise = {name: noise_std(np.asarray(v, float)) for name, v in x.items()}
    try:
        with np.errstate(all="ignore"):
            r = check_model_equations(x, h, values, model, cfg.filter, cfg.mismatch_alpha,
                                      covariance=est.covariance, names=est.names, noise=noise, noise_dof=len(x["w"]),
                                      speed_threshold=cfg.speed_threshold, speed_fraction=cfg.speed_fraction,
                                      instruments=inst, undetermined=est.undetermined)
    except FAILURES as exc:  # NumericalFailure: it diverged (a coding error, a bare ValueError, is raised)
        return None, f"not checked: the model check could not be run: {exc}"
    return r, None
