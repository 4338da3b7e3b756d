"""The estimator's defaults refer to the data, not to the built-in plant: scaling the data scales the
estimates exactly, and a refusal is the same at any scale."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "cosim"))
from linear_axis import TRUTH, H, linear_axis  # noqa: E402

from feeddrive.estimator import EstimationOptions, MotionData, NotEnoughExcitation, estimate_motion  # noqa: E402


@pytest.mark.parametrize("scale", [1e-3, 1e3])
def test_estimates_scale_with_the_position_unit(scale):
    """Position in m vs in another unit (x scale): Jt and ft scale by 1/scale, Cd and T0 not at all."""
    d = linear_axis(seed=5)
    k = slice(0, int(6 / H))
    options = EstimationOptions(method="ls", offset=True)
    ref = estimate_motion(MotionData(H, position=d["x"][k], torque=d["F"][k]), options).parameters
    got = estimate_motion(MotionData(H, position=d["x"][k] * scale, torque=d["F"][k]), options).parameters
    for name, power in (("Jt", -1), ("ft", -1), ("Cd", 0), ("T0", 0)):
        assert got[name].value == pytest.approx(ref[name].value * scale ** power, rel=1e-6), name
    assert ref["Jt"].value == pytest.approx(TRUTH["Jt"], rel=0.02)


@pytest.mark.parametrize("speed", [0.05, 50.0])
def test_constant_speed_is_refused_at_any_scale(speed):
    """An exactly constant speed leaves dw/dt as rounding noise: the inertia column is empty whatever the
    speed's unit (the test used to compare with the built-in plant's nominal Jt)."""
    n = 5000
    w = np.full(n, speed)
    force = 200.0 * speed + 20.0
    with pytest.raises(NotEnoughExcitation) as exc:
        estimate_motion(MotionData(H, w=w, torque=np.full(n, force)), EstimationOptions(method="ls"))
    assert {"Jt", "ft", "Cd"} == set(exc.value.unidentifiable)
