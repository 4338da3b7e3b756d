"""The paper's treatments on arrays: derivative operator, filter, CT-ARX regressions derived from the
model, LS / IV / OE estimation with uncertainties, segmentation of recordings (and, in their own
modules, measurement validation, model mismatch, diagnosis and the history store).

The names below are imported on first use (PEP 562): importing a submodule (``estimator.errors``,
``estimator.history``) runs this file, which must not load the estimation and scipy with it (1.3 s).
"""
from __future__ import annotations

import importlib

#: name -> the submodule defining it
_WHERE = {
    "zero_forcing_derivative": "derivative",
    "EstimatorInputError": "errors", "NotEnoughExcitation": "errors",
    "EstimationOptions": "estimate", "MethodResult": "estimate", "MotionData": "estimate",
    "MotionEstimate": "estimate", "ParameterEstimate": "estimate", "estimate_motion": "all_or_none",
    "FilterSpec": "filtering", "lowpass": "filtering",
    "simulate_current": "simulation", "simulate_motor": "simulation", "simulate_speed": "simulation",
}

__all__ = sorted(_WHERE, key=str.lower)


def __getattr__(name: str):  # noqa: ANN202 - lazy re-exports
    where = _WHERE.get(name)
    if where is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{where}"), name)
    globals()[name] = value  # the next access is a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))
