"""A .mat that cannot be read says what is wrong with the file, not the reader's exception (cosim.readers.matlab).

A truncated MATLAB file said "not a readable MATLAB file (IndexError: index out of range)" or "(OSError: could not
read bytes)": scipy's internals. Now one line names what was found: the file's size, the variable whose declared
size runs past its end, or the missing header, with what was expected.
"""
from __future__ import annotations

import re

import h5py
import numpy as np
import pytest
import scipy.io

from feeddrive.cosim.cli import main

INTERNAL = re.compile(r"\b\w*(Error|Exception)\b|index out of range|could not read bytes")


@pytest.fixture(scope="module")
def v5(tmp_path_factory) -> bytes:
    path = tmp_path_factory.mktemp("mat") / "whole.mat"
    scipy.io.savemat(path, {"t": np.arange(500.0), "u": np.ones(500)})  # uncompressed: a 128-byte header, 2 x (an 8-byte tag + 4048)
    return path.read_bytes()


def read(tmp_path, capsys, content: bytes, name: str = "cut.mat") -> str:
    path = tmp_path / name
    path.write_bytes(content)
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(path) in err and not INTERNAL.search(err), err
    return err.split(f"{path}: ", 1)[1].strip()


@pytest.mark.parametrize("keep, why", [
    (20, "truncated: 20 bytes, shorter than the 128-byte MATLAB 5.0 header"),
    (130, "truncated: variable 1's 8-byte tag at byte 128 is cut by the end of the file (130 bytes)"),
    (3000, "truncated: variable 1 at byte 128 declares 4048 bytes, 1184 more than the file holds (3000 bytes)"),
    (6000, "truncated: variable 2 at byte 4184 declares 4048 bytes, 2240 more than the file holds (6000 bytes)"),
])
def test_a_truncated_v5_file_says_where_it_ends(tmp_path, capsys, v5, keep, why):
    assert len(v5) == 8240
    assert read(tmp_path, capsys, v5[:keep]) == f"not a readable MATLAB file: {why}; expected a .mat of version 4 to 7.3"


def test_empty_garbage_v4_and_hdf5(tmp_path, capsys):
    assert read(tmp_path, capsys, b"").startswith("not a readable MATLAB file: the file is empty (0 bytes)")
    assert read(tmp_path, capsys, bytes(range(256)) * 4).startswith(
        "not a readable MATLAB file: neither a MATLAB 5.0 header ('MATLAB 5.0 MAT-file' at its start) nor a MATLAB v4 "
        "matrix")
    scipy.io.savemat(tmp_path / "v4.mat", {"a": np.arange(1000.0)}, format="4")
    assert read(tmp_path, capsys, (tmp_path / "v4.mat").read_bytes()[:4000]).startswith(
        "not a readable MATLAB file: truncated: matrix 'a' ends past the end of the file (4000 bytes; read as MATLAB v4)")
    with h5py.File(tmp_path / "h5.mat", "w") as f:
        f["a"] = np.arange(10000.0)
    whole = (tmp_path / "h5.mat").read_bytes()
    assert read(tmp_path, capsys, whole[:len(whole) // 2]) == (
        f"not a readable MATLAB v7.3 file: truncated: {len(whole) // 2} bytes of the {len(whole)} its HDF5 header "
        f"declares")
