"""Reading a large CSV recording: Arrow's reader (the default for numeric columns) against the csv module's
path (the one that names a bad cell's row, used for text columns and files Arrow cannot read).

A record of ``--rows`` rows (default 250 000: 25 s at 10 kHz) and 8 columns, written with 17 significant
digits; every column is read as a role would. Prints CPU seconds of each path, best of ``--repeat``, and
their ratio, and checks that both give the same bits.

    python benchmarks/bench_csv.py [--rows 250000] [--repeat 3]
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from feeddrive.cosim.readers.csvfile import CsvSource


def read(path: Path, arrow: bool) -> tuple[float, list[np.ndarray]]:
    t = time.process_time()
    src = CsvSource(path)
    if not arrow:
        src._numbers = None  # every column through the csv module, as before Arrow
    values = [src.column(k).values for k in range(len(src.header))]
    return time.process_time() - t, values


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=250_000)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    x = np.random.default_rng(0).normal(size=(a.rows, 8))
    x[:, 0] = np.arange(a.rows) * 1e-4
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "record.csv"
        np.savetxt(path, x, delimiter=",", fmt="%.17g", comments="",
                   header="time [s],u [V],Im1 [A],Im2 [A],w [rad/s],x [m],v_ref [V],w_ref [rad/s]")
        best = {}
        for _ in range(a.repeat):
            for arrow in (True, False):
                t, values = read(path, arrow)
                best[arrow] = min(best.get(arrow, np.inf), t)
                assert all(v.tobytes() == c.tobytes() for v, c in zip(values, x.T)), "a value changed"
        size = path.stat().st_size / 1e6
    print(f"CSV of {a.rows} rows x 8 columns ({size:.0f} MB), CPU best of {a.repeat}:")
    print(f"  Arrow (default)  {best[True]:.3f} s")
    print(f"  csv module       {best[False]:.3f} s")
    print(f"  ratio Arrow / csv module = {best[True] / best[False]:.2f}; both give every value to the last bit")


if __name__ == "__main__":
    main()
