"""The estimator on the real recordings of ../shared/realdata: never an exception other than a refusal,
never a warning, never a nan, never an impossible estimate without a flag (issue 22).

Not the project's data: read in place with scipy.io / numpy (the readers of the CLI are another
module's), skipped where absent. Role maps from the folder's README.
"""
from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from feeddrive.estimator import EstimationOptions, EstimatorInputError, FilterSpec, MotionData, NotEnoughExcitation
from feeddrive.estimator.lagged_iv import LAGGED
from feeddrive.estimator.partial import estimate_parameters
from feeddrive.estimator.physical import NON_NEGATIVE, STRICT
from feeddrive.estimator.segmentation import from_speed

ROOT = Path(__file__).resolve().parents[2] / ".." / "shared" / "realdata"


def _need(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"real recording not found: {path}")
    return path


def quanser() -> list[tuple[str, MotionData]]:
    from scipy.io import loadmat

    x = loadmat(_need(ROOT / "quanser_aero2" / "NO_WEIGHTS_4V.mat"))["data"]
    h = float(np.median(np.diff(x[0])))
    amp = 0.0041229 * x[1] ** 2 + 0.6799 * x[1] - 0.096188  # the amplifier's map from the source repository
    return [("quanser raw", MotionData(h, u=x[1], i=x[3], w=x[9])), ("quanser amp", MotionData(h, u=amp, i=x[3], w=x[9]))]


def regbot() -> list[tuple[str, MotionData]]:
    out = []
    for f in sorted(_need(ROOT / "regbot").glob("*.txt")):
        x = np.loadtxt(f, comments="%")
        h = float(np.median(np.diff(x[:, 0])))
        for side, (ju, ji, jw) in (("left", (6, 8, 10)), ("right", (7, 9, 11))):
            out.append((f"{f.name} {side}", MotionData(h, u=x[:, ju], i=x[:, ji], w=x[:, jw] / 0.0297 * 9.68)))
    return out


def kuka() -> list[tuple[str, MotionData]]:
    from scipy.io import loadmat

    r = loadmat(_need(ROOT / "kuka_kr300" / "rec_A.mat"), squeeze_me=True, struct_as_record=False)["rec"]
    h = 0.004
    out = []
    for axis in range(3):
        w = np.deg2rad(r.act_vel_mot_deg_per_s[axis])
        torque = r.act_torque_abs_nm[axis]
        for k, seg in enumerate(from_speed(w, h)):
            out.append((f"kuka axis {axis + 1} motion {k}", MotionData(h, w=w[seg.start:seg.stop],
                                                                       torque=torque[seg.start:seg.stop])))
    return out


@pytest.mark.parametrize("source", [quanser, regbot, kuka])
@pytest.mark.parametrize("method", ["ls", "iv", "oe"])
def test_every_recording_gives_estimates_or_reasons_and_nothing_impossible_unflagged(source, method):
    counts = {"given": 0, "refused": 0}
    for name, data in source():
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            try:
                est = estimate_parameters(data, EstimationOptions(method=method,
                                                                  filter=FilterSpec(min(50.0, 0.1 / data.h))))
            except (NotEnoughExcitation, EstimatorInputError) as exc:
                assert "nan" not in str(exc) and "\n" not in str(exc), name
                counts["refused"] += 1
                continue
        counts["given"] += 1
        text = json.dumps(est.to_dict())
        assert "NaN" not in text and "Infinity" not in text, name
        assert est.method_used in ("ls", "iv", "oe", LAGGED) and (est.method_used == method or est.result.message), name
        for n, p in est.parameters.items():
            impossible = (n in STRICT and p.value <= 0) or (n in NON_NEGATIVE and p.ci95[1] < 0)
            assert not impossible or n in est.flags, (name, n, p)
        assert set(est.parameters).isdisjoint(est.refused)
    assert counts["given"] + counts["refused"] > 0


def test_quanser_iv_and_oe_fall_back_with_their_reason_and_k_is_within_10_percent_with_the_amplifier_map():
    """IV and OE used to end in ``ValueError: y must contain only finite values`` here."""
    (_, raw), (_, amp) = quanser()
    for method in ("iv", "oe"):
        est = estimate_parameters(amp, EstimationOptions(method=method, filter=FilterSpec(50.0)))
        assert est.method_used == "iv" and "without simulated instruments for the electrical" in est.result.message
        assert est.to_dict().get("method_requested") == (method if method == "oe" else None)
        assert "L" in est.refused and est.refused["L"].startswith("sample period 0.002 s too long")
        assert est.parameters["K"].value == pytest.approx(0.042, rel=0.10)
