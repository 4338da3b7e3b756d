"""CSV numbers: Arrow's reader (the fast path) and the csv module (the path that names a bad cell's row) give
the same value, to the last bit, for every cell spelling a recording may hold; whatever Arrow does not read as
numbers (text, time stamps, empty cells, ragged rows) falls back to the csv module's path and its messages."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from feeddrive.cosim.errors import DataError
from feeddrive.cosim.readers.csvfile import CsvSource, arrow_numbers

#: spellings of one float: repr, fixed, scientific (both cases), 3 significant figures, padded, quoted, integral
SPELLINGS = [repr, lambda x: f"{x:.6f}", lambda x: f"{x:.9e}", lambda x: f"{x:.3E}", lambda x: f"{x:.3g}",
             lambda x: f" {x!r} ", lambda x: f'"{x!r}"', lambda x: str(int(x))]


def slow_values(src: CsvSource, k: int) -> np.ndarray:
    """Column k by the csv module's path (Arrow's columns set aside)."""
    numbers, src._numbers = src._numbers, None
    try:
        return src.column(k).values
    finally:
        src._numbers = numbers


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-1e12, 1e12, allow_nan=False), min_size=1, max_size=30),
       st.integers(0, len(SPELLINGS) - 1), st.sampled_from([(",", "."), (";", ","), ("\t", ".")]))
def test_arrow_and_the_csv_module_read_the_same_bits(tmp_path_factory, xs, spelling, dialect):
    sep, dec = dialect
    cells = [SPELLINGS[spelling](x) for x in xs]
    if dec == ",":
        cells = [c.replace(".", ",") for c in cells]
    path = tmp_path_factory.mktemp("csv") / "r.csv"
    path.write_text(f"t{sep}x [A]\n" + "".join(f"{n}{sep}{c}\n" for n, c in enumerate(cells)))
    src = CsvSource(path, {"\t": "tab"}.get(sep, sep), dec)
    got = src.resolve("x", "current").values
    assert got.tobytes() == slow_values(src, 1).tobytes()
    assert got.tobytes() == np.array([float(c.strip().strip('"').replace(",", ".")) for c in cells]).tobytes()
    assert src.resolve("x", "current").unit == "A"


def test_a_text_column_leaves_the_numbers_to_arrow_and_itself_to_the_csv_module(tmp_path):
    path = tmp_path / "r.csv"
    path.write_text("time,phase,i\n" + "".join(f"{0.001 * n!r},Layer {n % 3},{n / 7!r}\n" for n in range(200)))
    src = CsvSource(path)
    n_rows, numbers = arrow_numbers(path.read_bytes(), ",", ".")
    assert n_rows == 200 and sorted(numbers) == [0, 2]  # the text column is not Arrow's
    assert np.array_equal(src.resolve("i", "current").values, np.arange(200) / 7)
    with pytest.raises(DataError, match=r"column 'phase' row 2: 'Layer 0' is not a number"):
        src.resolve("phase", "speed")


@pytest.mark.parametrize("body, message", [
    ("0,1\n0.001,\n", r"column 'i' row 3: '' is not a number \(a truncated last line\?\)"),
    ("0,1\n0.001\n", r"column 'i' row 3: '' is not a number"),      # ragged: Arrow refuses, the csv module names it
    ("0,1\n\n0.002,3\n", r"column 'i' row 3: '' is not a number"),  # an empty line inside is not skipped
    ("0,1\n0.001,-\n0.002,3\n", r"column 'i' row 3: '-' is not a number"),
])
def test_a_bad_cell_is_still_named_by_its_row(tmp_path, body, message):
    path = tmp_path / "r.csv"
    path.write_text("time,i\n" + body)
    with pytest.raises(DataError, match=message):
        CsvSource(path).resolve("i", "current")


def test_trailing_empty_lines_and_iso_time_stamps_keep_the_csv_module_semantics(tmp_path):
    path = tmp_path / "r.csv"
    path.write_text("time,i\n" + "".join(f"2024-03-01T10:00:00.{n:03d},{n}\n" for n in range(5)) + "\n\n")
    src = CsvSource(path)
    t, i = src.resolve("time", "time"), src.resolve("i", "current")
    assert t.absolute and np.allclose(t.values, np.arange(5) * 1e-3, atol=1e-9) and np.array_equal(i.values, range(5))
    assert [v.shape for v in src.variables()] == [(5,), (5,)]
