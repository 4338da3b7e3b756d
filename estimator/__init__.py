"""The paper's treatments on arrays: derivative operator, filter, CT-ARX regressions derived from the
model, LS / IV / OE estimation with uncertainties, segmentation of recordings (and, in their own
modules, measurement validation, model mismatch, diagnosis and the history store)."""
from feeddrive.estimator.derivative import zero_forcing_derivative
from feeddrive.estimator.errors import EstimatorInputError, NotEnoughExcitation
from feeddrive.estimator.estimate import (
    EstimationOptions,
    MethodResult,
    MotionData,
    MotionEstimate,
    ParameterEstimate,
    estimate_motion,
)
from feeddrive.estimator.filtering import FilterSpec, lowpass
from feeddrive.estimator.simulation import simulate_current, simulate_motor, simulate_speed

__all__ = [
    "EstimationOptions", "EstimatorInputError", "FilterSpec", "MethodResult", "MotionData", "MotionEstimate",
    "NotEnoughExcitation", "ParameterEstimate", "estimate_motion", "lowpass", "simulate_current",
    "simulate_motor", "simulate_speed", "zero_forcing_derivative",
]
