"""One synthetic drive record written in every format the readers take (shared by the reader tests).

The closed-loop model's round trip (tests/estimator/plant_data.py) with 40 dB noise, every 5th sample
(h = 0.5 ms). Every writer stores the same float64 values (text with 17 significant digits), so that
every format must give the same estimates to the last printed digit.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "estimator"))
from plant_data import add_noise, closed_loop  # noqa: E402

#: decimation of the 0.1 ms model output
STEP = 5
NAMES = ("t", "u", "i", "w")


def record() -> dict[str, np.ndarray]:
    """``t`` [s], ``u`` [V], ``i`` [A], ``w`` [rad/s], shape (n,), h = 0.5 ms."""
    d = add_noise(closed_loop(), 40.0, seed=7)
    return {k: np.asarray(d[k][::STEP], dtype=float) for k in NAMES}


def write_csv(path: Path, d: dict, header: str = "time [s],u [V],i [A],w [rad/s]") -> Path:
    np.savetxt(path, np.column_stack([d[k] for k in NAMES]), delimiter=",", header=header, comments="",
               fmt="%.17g")
    return path


def write_mat_matrix(path: Path, d: dict, transposed: bool = False) -> Path:
    """``data``: n x 4 (or 4 x n, one channel per row, as many loggers write)."""
    import scipy.io

    m = np.column_stack([d[k] for k in NAMES])
    scipy.io.savemat(path, {"data": m.T if transposed else m, "J": 0.1})
    return path


def write_mat_struct(path: Path, d: dict) -> Path:
    """``rec.t`` (1 x n), ``rec.sig`` (n x 3: u, i, w) and a scalar field, as a MATLAB struct."""
    import scipy.io

    scipy.io.savemat(path, {"rec": {"t": d["t"][None, :], "sig": np.column_stack([d["u"], d["i"], d["w"]]),
                                    "name": "axis 1"}})
    return path


def write_mat73(path: Path, d: dict) -> Path:
    """MATLAB v7.3 layout written with h5py: a 512-byte user block with the MATLAB header, column-major
    arrays (MATLAB's n x 4 is the HDF5 dataset (4, n)), ``MATLAB_class`` attributes, a struct as a group."""
    import h5py

    m = np.column_stack([d[k] for k in NAMES])
    with h5py.File(path, "w", userblock_size=512) as f:
        f.create_dataset("data", data=m.T).attrs["MATLAB_class"] = np.bytes_("double")
        g = f.create_group("rec")
        g.attrs["MATLAB_class"] = np.bytes_("struct")
        g.create_dataset("t", data=d["t"][None, :].T).attrs["MATLAB_class"] = np.bytes_("double")
        sig = np.column_stack([d["u"], d["i"], d["w"]])
        g.create_dataset("sig", data=sig.T).attrs["MATLAB_class"] = np.bytes_("double")
        name = np.array([ord(c) for c in "axis 1"], dtype=np.uint16)[:, None]
        g.create_dataset("name", data=name).attrs["MATLAB_class"] = np.bytes_("char")
    with path.open("r+b") as f:  # MATLAB's own header text in the user block
        f.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Tue Nov 24 12:00:00 2026 HDF5 schema 1.00 .")
    return path


def write_parquet(path: Path, d: dict, timestamps: float | None = None) -> Path:
    """Columns ``time`` (seconds, or timestamps from ``timestamps`` s since 1970), ``u`` with a ``unit``
    field metadata entry, ``i [A]`` with the unit in its name, ``w [rad/s]``."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    if timestamps is None:
        time = pa.array(d["t"])
    else:
        ns = int(round(timestamps * 1e9)) + np.round(d["t"] * 1e9).astype("int64")  # exact nanoseconds
        time = pa.array(ns, pa.int64()).cast(pa.timestamp("ns", tz="UTC"))
    schema = pa.schema([pa.field("time", time.type), pa.field("u", pa.float64(), metadata={"unit": "V"}),
                        pa.field("i [A]", pa.float64()), pa.field("w [rad/s]", pa.float64())])
    pq.write_table(pa.table([time, pa.array(d["u"]), pa.array(d["i"]), pa.array(d["w"])], schema=schema), path)
    return path


def write_text_log(path: Path, d: dict) -> Path:
    """A REGBOT-style log: ``%`` comment lines that name the columns by number, whitespace-separated rows."""
    lines = ["%% logfile from a test bench", "%  1    time 0.000 sec", "%  2  3 Motor voltage [V], current [A]: 0 0",
             "%  4    Motor speed [rad/s]: 0"]
    rows = [" ".join(f"{x!r}" for x in row) for row in zip(*(d[k].tolist() for k in NAMES))]
    path.write_text("\n".join(lines + rows) + "\n", encoding="utf-8")
    return path
