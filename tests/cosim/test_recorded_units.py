"""Units of recorded columns as users write them (audit 2): a percentage of a rated value is never taken on
trust, scaled or not."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from feeddrive.cosim.errors import DataError
from feeddrive.cosim.recorded import load_recording


@pytest.fixture
def percent_csv(tmp_path: Path) -> tuple[Path, np.ndarray]:
    """A drive's trace with its torque in % of a 0.5 N.m rating, as servo drives log it."""
    t = np.arange(200) * 1e-3
    torque = 0.5 * np.sin(2 * np.pi * 5 * t)  # N.m
    path = tmp_path / "drive.csv"
    np.savetxt(path, np.column_stack([t, 10 * np.cos(2 * np.pi * 5 * t), torque / 0.5 * 100]), delimiter=",",
               header="t [s],w [rad/s],T [%]", comments="", fmt="%.10g")
    return path, torque


def test_a_scaled_percentage_must_state_the_unit_of_the_scaled_values(percent_csv) -> None:
    """``torque=T*0.005`` on ``T [%]`` was taken with no unit ("'T [%]' states no unit ... taken as N.m"): the
    header does state one, and the scale converts it into another the map never named. Refused, naming the
    column and the fix, like a gear's scale on a m/s column; with the unit stated the values are the torque."""
    path, torque = percent_csv
    with pytest.raises(DataError, match=r"column 'T \[%\]' \(role torque\): the header says \[%\], not a unit of "
                                         r"torque.*--map 'torque=T\*0\.005 \[UNIT\]', e\.g\. \[N\.m\]"):
        load_recording(path, {"time": "t", "speed": "w", "torque": "T*0.005"})
    rec = load_recording(path, {"time": "t", "speed": "w", "torque": "T*0.005 [N.m]"})
    assert rec.units["torque"] == "N*m" and not rec.notes
    np.testing.assert_allclose(rec.signals["torque"], torque, rtol=1e-9, atol=1e-12)


def test_an_unscaled_percentage_is_refused_with_the_scale_it_needs(percent_csv) -> None:
    path, _ = percent_csv
    with pytest.raises(DataError, match=r"unit '%' is not a unit of role torque .*a fraction of a rated value needs "
                                         r"its scale: --map 'torque=COLUMN\*SCALE \[N\.m\]'"):
        load_recording(path, {"time": "t", "speed": "w", "torque": "T"})
