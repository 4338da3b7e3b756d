"""Fuzz of the readers: any role-map expression against a MATLAB tree, and any text log, gives a signal or
one DataError (a ValueError) naming the file, never another exception."""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from feeddrive.cosim.errors import DataError
from feeddrive.cosim.readers import open_source

EXAMPLES = max(300, settings().max_examples)
FUZZ = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))


@pytest.fixture(scope="module")
def mat(tmp_path_factory) -> Path:
    import scipy.io

    path = tmp_path_factory.mktemp("fz") / "f.mat"
    scipy.io.savemat(path, {"data": np.arange(60.0).reshape(20, 3), "rec": {"t": np.arange(20.0), "s": "txt",
                            "m": np.ones((3, 20))}, "arr": np.array([{"a": np.ones(20)}, {"a": np.zeros(20)}],
                                                                    dtype=object), "k": 3.0})
    return path


pieces = st.sampled_from(["data", "rec", "arr", "k", "x", ".t", ".s", ".m", ".a", ".", "[", "]", ":", ",", "0",
                          "1", "-1", "2", "99", "-99", "::", " ", "[:,0]", "[0]", "[1]", "[:,:]", "1e3", "*"])


@FUZZ
@given(st.lists(pieces, min_size=1, max_size=8).map("".join))
def test_any_expression_is_a_signal_or_a_data_error(mat, expr):
    source = open_source(mat)
    try:
        sig = source.resolve(expr, "speed")
    except DataError as exc:
        assert str(mat) in str(exc) and "\n" not in str(exc)
    else:
        assert sig.values.ndim == 1 and sig.values.dtype == float


lines = st.one_of(st.just("% 1 2 time [s], u [V]: 0 0"), st.just("# 3 x"), st.just("%"), st.just(""),
                  st.just("0.1 2"), st.just("0.2 3 4"), st.just("nan inf"), st.just("1,5 2"),
                  st.text(alphabet="0123456789 .-e%#[]:,\t", max_size=20))


@FUZZ
@given(st.lists(lines, max_size=12))
def test_any_text_log_is_a_table_or_a_data_error(rows):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "l.txt"
        path.write_text("\n".join(rows), encoding="utf-8")
        try:
            source = open_source(path)
            variables = source.variables()
            for v in variables:
                source.resolve(v.name, "voltage")
        except DataError as exc:
            assert str(path) in str(exc) and "\n" not in str(exc)
