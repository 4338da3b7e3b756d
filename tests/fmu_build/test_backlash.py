"""The backlash variant of the plant: the dead zone seen through the FMU's outputs."""
import math

import fmpy
import numpy as np
import pytest

from feeddrive.fmu_build import builtin_fmu
from feeddrive.models import feed_drive

NOMINAL = feed_drive(backlash=True).nominal()


def _twist(result):
    """Motor angle minus load angle [rad], the load angle recovered from the table position."""
    return result["theta"] - result["x"] * 2 * math.pi * NOMINAL["belt_ratio"] / NOMINAL["pitch"]


@pytest.fixture(scope="module")
def backlash_fmu(fmu_cache_dir):
    return builtin_fmu(fmu_cache_dir, backlash=True)


def test_static_twist_is_half_the_gap_plus_the_friction_deflection(backlash_fmu):
    w = 30.0
    r = fmpy.simulate_fmu(str(backlash_fmu), stop_time=1.5, output_interval=1e-3,
                          start_values={"w_ref": w}, output=["theta", "x", "w", "i"])
    friction = NOMINAL["ft"] * w + NOMINAL["Cd"]
    assert r["w"][-1] == pytest.approx(w, rel=1e-9)
    assert r["i"][-1] == pytest.approx(friction / NOMINAL["K"], rel=1e-6)
    assert _twist(r)[-1] == pytest.approx(NOMINAL["backlash"] / 2 + friction / NOMINAL["k_s"], rel=1e-6)


def test_a_reversal_crosses_the_whole_gap(backlash_fmu):
    """Before and after a reversal the twist changes sign: the motor travels the gap alone."""
    signal = np.array([(0.0, 20.0), (0.5, 20.0), (0.5, -20.0), (1.5, -20.0)],
                      dtype=[("time", float), ("w_ref", float)])
    r = fmpy.simulate_fmu(str(backlash_fmu), stop_time=1.5, output_interval=1e-3, input=signal,
                          output=["theta", "x"])
    twist = _twist(r)
    friction = NOMINAL["ft"] * 20.0 + NOMINAL["Cd"]
    expected = NOMINAL["backlash"] / 2 + friction / NOMINAL["k_s"]
    before = twist[np.searchsorted(r["time"], 0.49)]
    after = twist[-1]
    assert before == pytest.approx(expected, rel=1e-4)
    assert after == pytest.approx(-expected, rel=1e-4)
