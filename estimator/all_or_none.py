"""Every parameter of one motion, or none: ``estimate_motion`` (a campaign's per-method table, the benchmarks).

LS, then for ``iv`` and ``oe`` the IV with the fall-backs every caller runs (``lagged_iv.iv_with_fallbacks``: the
split-sample IV, else the lagged IV, else LS, each labelled), then OE. Unlike ``partial.estimate_parameters`` (the
monitor, ``cosim estimate``), which gives each parameter on its own and names the refused ones, any parameter that
fails the relative standard error rule refuses the whole motion (``NotEnoughExcitation``).
"""
from __future__ import annotations

from dataclasses import replace

from feeddrive.estimator.estimate import derived_estimates, least_squares, prepare
from feeddrive.estimator.lagged_iv import iv_with_fallbacks
from feeddrive.estimator.motion import EstimationOptions, MotionData, MotionEstimate, check_result


def estimate_motion(data: MotionData, options: EstimationOptions = EstimationOptions()) -> MotionEstimate:
    """Estimate the physical parameters of one high-speed motion.

    Parameters
    ----------
    data : MotionData
        Voltage, current and speed (or position, or torque) of one motion, sampled every ``data.h``.
    options : EstimationOptions

    Returns
    -------
    MotionEstimate
        LS always; IV for methods ``iv`` and ``oe`` (``lagged_iv.iv_with_fallbacks``: the lagged IV, then LS, stand
        in when it fails, labelled ``iv`` with the reason); OE for ``oe`` (falls back to IV with a message).

    Raises
    ------
    NotEnoughExcitation
        The data cannot determine some parameters (they are named); no numbers are returned.
    EstimatorInputError
        Unusable signals or options.
    """
    p = prepare(data, options)
    ls = least_squares(p, options)
    iv = oe = None
    if options.method in ("iv", "oe"):
        # the fall-backs of the monitor's and `cosim estimate`'s IV (partial.estimate_parameters): the split-sample
        # IV, else the lagged IV, else LS, each labelled; it fell back to LS at once here, so a campaign's table
        # scored another estimate than the monitor's under the same label
        iv = iv_with_fallbacks(data, ls, options, {}, {r.equation for r in p.regressions})
        check_result(iv, options)  # every parameter or none (the monitor's path refuses them one at a time)
    if options.method == "oe":
        from feeddrive.estimator.oe import output_error

        oe = output_error(p, iv, options)
    out = MotionEstimate(options.method, float(data.t0), float(data.t0 + (data.n - 1) * data.h), ls, iv, oe,
                         rate_hz=1.0 / p.h)
    return replace(out, derived=derived_estimates(out.result, options.model))
