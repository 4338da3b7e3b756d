"""The monitor's model check and the output-error refinement catch the estimator's own failures only.

``cosim monitor`` turned any ValueError or ArithmeticError of the model check into "not checked: the model check
could not be run", and ``estimator.oe.output_error`` any ValueError or RuntimeError into "output error fell back to
IV": a coding error (a shape mismatch, a division by zero) read as a property of the data. Now only
``estimator.errors.FAILURES`` (a refusal, unusable input, a diverging simulation, numpy's singular matrix) do.
The monitor's check is made to fail by replacing ``check_signals`` (what fails is the point, not the check).
"""
from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "estimator"))
from synthetic import ROUND_TRIP, record  # noqa: E402

import feeddrive.cosim.monitor_pipeline as pipeline  # noqa: E402
from feeddrive.cosim.cli import main  # noqa: E402
from feeddrive.estimator import EstimationOptions, FilterSpec, MotionData  # noqa: E402
from feeddrive.estimator.errors import NumericalFailure  # noqa: E402
from feeddrive.estimator.estimate import least_squares, prepare  # noqa: E402
from feeddrive.estimator.oe import output_error  # noqa: E402

H = 1e-3


@pytest.fixture(scope="module")
def trip():
    return record(ROUND_TRIP, H, snr_db=40.0)


def test_the_monitor_raises_a_coding_error_of_its_model_check(tmp_path, capsys, monkeypatch, trip):
    path = tmp_path / "trip.csv"
    np.savetxt(path, np.column_stack([trip[k] for k in "tuiw"]), delimiter=",", header="t,u,i,w", comments="")
    argv = ["monitor", str(path), "--map", "time=t", "voltage=u", "current1=i", "speed=w", "--segment", "none",
            "--db", ":memory:", "--json"]

    def diverged(*args, **kwargs):
        raise NumericalFailure("the model check's simulation diverges")

    monkeypatch.setattr(pipeline, "check_signals", diverged)
    assert main(argv) == 0
    (m,) = json.loads(capsys.readouterr().out)["motions"]
    assert m["not_checked"]["model (paper, output error)"] == ("not checked: the model check could not be run: the "
                                                                "model check's simulation diverges")

    def bug(*args, **kwargs):
        return 1 / 0

    monkeypatch.setattr(pipeline, "check_signals", bug)
    with pytest.raises(ZeroDivisionError):  # it said "not checked: the model check could not be run: division by zero"
        main(argv)


def test_output_error_raises_a_coding_error(trip):
    options = EstimationOptions(method="oe", filter=FilterSpec(100.0))
    p = prepare(MotionData(H, u=trip["u"], i=trip["i"], w=trip["w"]), options)
    ls = least_squares(p, options)
    assert output_error(p, ls, options).method_used == "oe"  # it runs on this record
    broken = replace(ls, values=ls.values[:-1])  # one value short of its names: a coding error, not the data's
    with pytest.raises(RuntimeError, match="mismatching shape"):  # CasADi's; it said "fell back to LS: RuntimeError"
        output_error(p, broken, options)


def test_the_monitors_estimation_step_catches_the_estimators_failures_only(tmp_path, capsys, monkeypatch, trip):
    """``MonitorPipeline.process`` caught numpy's LinAlgError and any FloatingPointError around validation,
    estimation and diagnosis: an ArithmeticError (a coding error, errors.FAILURES) became "numerical failure on this
    motion's data". Now a singular matrix still is this motion's refusal (the next may be used), the coding error
    raises. The step is made to fail by replacing ``validate_measurements`` (the first it runs on u, i, w)."""
    path = tmp_path / "trip.csv"
    np.savetxt(path, np.column_stack([trip[k] for k in "tuiw"]), delimiter=",", header="t,u,i,w", comments="")
    argv = ["monitor", str(path), "--map", "time=t", "voltage=u", "current1=i", "speed=w", "--segment", "none",
            "--db", ":memory:", "--json"]

    def singular(*args, **kwargs):
        raise np.linalg.LinAlgError("SVD did not converge")

    monkeypatch.setattr(pipeline, "validate_measurements", singular)
    assert main(argv) == 3  # nothing judged: the one motion refused, with its reason
    (m,) = json.loads(capsys.readouterr().out)["motions"]
    assert m["error"] == "numerical failure on this motion's data (SVD did not converge)"

    def bug(*args, **kwargs):
        raise FloatingPointError("overflow encountered in multiply")

    monkeypatch.setattr(pipeline, "validate_measurements", bug)
    with pytest.raises(FloatingPointError):  # it said "numerical failure on this motion's data (overflow ...)"
        main(argv)
