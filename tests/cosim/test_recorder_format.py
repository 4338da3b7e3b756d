"""signals.csv's numbers: the compiled "%.10g" (cosim/fastloop/fineloop.c ``fd_format_rows``) writes exactly what
numpy.savetxt(fmt="%.10g") wrote, character for character, on values of every kind a recording holds and on the
cases where a shortcut could round differently (ties, near-ties, a carry into the next power of ten, subnormals)."""
from __future__ import annotations

import io

import numpy as np
import pytest

from feeddrive.cosim.fastloop.build import BuildFailed, library
from feeddrive.cosim.recorder import Recorder, format_rows


def savetxt(table: np.ndarray) -> str:
    out = io.StringIO()
    np.savetxt(out, table, delimiter=",", fmt="%.10g")
    return out.getvalue()


def tables(rng: np.random.Generator):
    shape = (5000, 20)
    yield rng.standard_normal(shape) * 10.0 ** rng.integers(-6, 4, shape)  # signals in SI units
    yield rng.standard_normal(shape) * 10.0 ** rng.integers(-323, 308, shape)  # every exponent
    yield np.round(rng.standard_normal(shape) * 10.0 ** rng.integers(0, 8, shape), 4)  # short decimals
    yield rng.integers(-10**13, 10**13, shape).astype(float)  # integers past 10 digits
    yield (rng.integers(0, 10**11, shape) * 10 + 5).astype(float) * 10.0 ** rng.integers(-14, 3)  # ties
    yield 9.9999999995 * 10.0 ** rng.integers(-20, 20, shape) * (1 + rng.integers(-3, 4, shape) * 2.0 ** -52)
    yield np.arange(shape[0] * shape[1]).reshape(shape) * 1e-4  # the time column of a 10 kHz run


def test_compiled_format_is_savetxts_character_for_character():
    try:
        library()
    except BuildFailed as exc:
        pytest.skip(f"no compiled fine loop here ({exc}): format_rows is numpy.savetxt itself")
    rng = np.random.default_rng(7)
    for k, table in enumerate(tables(rng)):
        table.flat[:10] = [np.nan, -np.nan, np.inf, -np.inf, -0.0, 0.0, 5e-324, np.finfo(float).max,
                           9.9999999995, -0.00099999999995]
        expected, got = savetxt(table), format_rows(table)
        if got != expected:
            bad = [(e, g) for e, g in zip(expected.splitlines(), got.splitlines()) if e != g]
            pytest.fail(f"table {k}: {bad[:3]}")


def test_streamed_and_final_signals_csv_are_the_same_file(tmp_path):
    rng = np.random.default_rng(1)
    data = rng.standard_normal((3000, 3)) * [1e-3, 10.0, 1e5]
    a, b = Recorder(["x", "y", "z"], ["A", "", "m"], 3000, 0.0, 1e-4), Recorder(["x", "y", "z"], ["A", "", "m"], 3000, 0.0, 1e-4)
    a.stream(tmp_path / "a.csv")
    for block in np.array_split(data, 7):
        a.extend(block)
        b.extend(block)
    a.write_csv(tmp_path / "a.csv")
    b.write_csv(tmp_path / "b.csv")
    text = (tmp_path / "a.csv").read_text()
    assert text == (tmp_path / "b.csv").read_text()
    assert text.splitlines()[0] == "time [s],x [A],y,z [m]"
    back = np.loadtxt(tmp_path / "a.csv", delimiter=",", skiprows=1)
    assert np.allclose(back[:, 1:], data, rtol=1e-9, atol=0) and np.allclose(back[:, 0], np.arange(3000) * 1e-4)
