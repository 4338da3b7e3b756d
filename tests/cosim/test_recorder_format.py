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


def test_a_block_whose_writing_was_interrupted_is_written_with_the_next(tmp_path, monkeypatch):
    """Ctrl-C while a block of rows was being formatted (most of a block's time) left that block out of the
    streamed signals.csv and wrote the next one after it: a row missing, the times around it one step apart
    more. The rows recorded and not written are written with the next block, or when the file is closed."""
    import feeddrive.cosim.recorder as recorder_module

    rec = Recorder(["a", "b"], ["V", "A"], 10, 0.0, 1e-4)
    path = tmp_path / "signals.csv"
    rec.stream(path)
    rec.extend(np.array([[1.0, 2.0], [3.0, 4.0]]))
    calls = {"n": 0}

    def interrupted_once(table):
        calls["n"] += 1
        if calls["n"] == 1:
            raise KeyboardInterrupt
        return format_rows(table)

    monkeypatch.setattr(recorder_module, "format_rows", interrupted_once)
    with pytest.raises(KeyboardInterrupt):
        rec.extend(np.array([[5.0, 6.0]]))  # recorded, its writing interrupted
    rec.extend(np.array([[7.0, 8.0]]))  # the run's last rows (cosim/master.py's failure path)
    rec.write_csv(path)
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    np.testing.assert_array_equal(table[:, 1:], [[1, 2], [3, 4], [5, 6], [7, 8]])
    np.testing.assert_allclose(table[:, 0], [0.0, 1e-4, 2e-4, 3e-4], rtol=0, atol=1e-15)


class _Interrupting:
    """signals.csv's stream, its next write cut at ``cut`` of its text by a Ctrl-C (1.0: written whole, the
    interruption before the recorder counted it)."""

    def __init__(self, stream, cut: float) -> None:
        self.stream, self.cut, self.armed = stream, cut, True

    def write(self, text: str) -> int:
        if self.armed:
            self.armed = False
            self.stream.write(text[:int(len(text) * self.cut)])
            raise KeyboardInterrupt
        return self.stream.write(text)

    def __getattr__(self, name: str):
        return getattr(self.stream, name)


@pytest.mark.parametrize("cut", [1.0, 0.5])
def test_a_block_written_whole_or_in_part_when_interrupted_is_in_the_file_once(tmp_path, cut):
    """A Ctrl-C after a block's text was written but before the recorder counted it: the block was written again
    when the file was closed, its times going back 0.1 s (tests/cosim/test_run_interrupt.py saw it); one cut in
    the middle of the text left half a row. The file is cut back to its last counted block and written on."""
    rec = Recorder(["a", "b"], ["V", "A"], 10, 0.0, 1e-4)
    path = tmp_path / "signals.csv"
    rec.stream(path)
    rec.extend(np.array([[1.0, 2.0], [3.0, 4.0]]))
    rec._stream = _Interrupting(rec._stream, cut)
    with pytest.raises(KeyboardInterrupt):
        rec.extend(np.array([[5.0, 6.0], [7.5, 8.5]]))
    rec.extend(np.array([[9.0, 10.0]]))
    rec.write_csv(path)
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    np.testing.assert_array_equal(table[:, 1:], [[1, 2], [3, 4], [5, 6], [7.5, 8.5], [9, 10]])
    np.testing.assert_allclose(table[:, 0], np.arange(5) * 1e-4, rtol=0, atol=1e-15)
