"""MATLAB files: v4 to v7 through scipy.io.loadmat, v7.3 (HDF5) through h5py.

Matrices, structs (``rec.field``), struct arrays (``rec[1].field``) and numeric fields are read;
cell arrays and MATLAB objects (``MCOS`` opaque data, function handles) are listed as such and cannot
be mapped. v7.3 stores arrays column-major: h5py sees them with their dimensions reversed, which is
undone here, so that both versions give the same shapes.
"""
from __future__ import annotations

import re
import struct
from pathlib import Path

import numpy as np

from feeddrive.cosim.errors import DataError
from feeddrive.cosim.readers.source import (
    Signal,
    Source,
    Variable,
    as_signal,
    resolve_tree,
    samples_first,
    tree_variables,
)


class MatSource(Source):
    """A MATLAB file as a tree of variables (see :mod:`feeddrive.cosim.readers.source`)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.notes: dict[str, str] = {}
        try:
            import h5py

            hdf5 = h5py.is_hdf5(path)
        except OSError:
            hdf5 = False
        if hdf5:
            self.kind = "MATLAB v7.3 (HDF5)"
            self.tree = self._read_h5(path)
        else:
            self.kind, self.tree = self._read_mat(path)

    def _read_mat(self, path: Path) -> tuple[str, dict]:
        import scipy.io

        try:
            raw = scipy.io.loadmat(path, simplify_cells=True)
        except NotImplementedError:  # a v7.3 file h5py did not recognise
            raise DataError(f"{path}: a MATLAB v7.3 file that is not valid HDF5; expected a readable .mat") from None
        except Exception as exc:  # noqa: BLE001 - scipy raises ValueError, TypeError, OSError ... on bad files
            raise DataError(f"{path}: not a readable MATLAB file: {_why_unreadable(path, exc)}; expected a .mat of "
                            f"version 4 to 7.3") from None
        header = raw.get("__header__", b"")
        version = "v4" if not header else ("v5-v7" if b"MATLAB 5.0" in header else "v5-v7")
        tree = {}
        for name, value in raw.items():
            if name.startswith("__") or name == "None":  # metadata, MATLAB objects without a variable name
                continue
            tree[name] = self._normal(value, name)
        return f"MATLAB {version}", tree

    def _normal(self, value: object, name: str) -> object:
        """simplify_cells output -> dicts and samples-first arrays."""
        if isinstance(value, dict):
            return {k: self._normal(v, f"{name}.{k}") for k, v in value.items()}
        if isinstance(value, str):
            return np.array(value)
        arr = np.asarray(value) if not hasattr(value, "dtype") or isinstance(value, np.ndarray) else None
        if arr is None:  # MatlabOpaque, MatlabFunction
            self.notes[name] = "MATLAB object, not readable"
            return np.array(type(value).__name__)
        if arr.dtype == object:
            out = np.empty(arr.shape, dtype=object)
            for k, v in np.ndenumerate(arr):
                out[k] = self._normal(v, name)
            return out
        if arr.dtype.kind in "biuf" and arr.ndim == 2:
            arr, note = samples_first(arr)
            if note:
                self.notes[name] = note
        return arr

    def _read_h5(self, path: Path) -> dict:
        import h5py

        try:
            with h5py.File(path, "r") as f:
                return {k: self._h5(f, v, k) for k, v in f.items() if not k.startswith("#")}
        except OSError as exc:
            cut = re.search(r"truncated file: eof = (\d+).*stored_eof = (\d+)", str(exc))
            why = (f"truncated: {cut[1]} bytes of the {cut[2]} its HDF5 header declares" if cut else
                   " ".join(str(exc).replace("Unable to synchronously open file", "HDF5").split()))
            raise DataError(f"{path}: not a readable MATLAB v7.3 file: {why}") from None

    def _h5(self, f, node, name: str) -> object:  # noqa: ANN001 - h5py File, Group or Dataset
        import h5py

        cls = node.attrs.get("MATLAB_class", b"")
        cls = cls.decode() if isinstance(cls, bytes) else str(cls)
        if isinstance(node, h5py.Group):
            return {k: self._h5(f, v, f"{name}.{k}") for k, v in node.items() if not k.startswith("#")}
        if node.attrs.get("MATLAB_empty", 0):
            return np.zeros((0,))
        data = node[()]
        if data.dtype == h5py.ref_dtype:  # a cell array or the fields of a struct array
            data = np.asarray(data).T
            out = np.empty(data.shape, dtype=object)
            for k, ref in np.ndenumerate(data):
                out[k] = self._h5(f, f[ref], name)
            return out
        arr = np.asarray(data).T  # column-major: MATLAB's (m, n) is stored as (n, m)
        if cls == "char":
            return np.array("".join(map(chr, arr.reshape(-1, order="F"))))
        if arr.dtype.kind in "biuf" and arr.ndim == 2:
            arr, note = samples_first(arr)
            if note:
                self.notes[name] = note
        return arr

    def variables(self) -> list[Variable]:
        return tree_variables(self.tree, self.notes)

    def names(self) -> str:
        """The top-level variables (structs marked), for error messages; cosim info lists the fields."""
        def one(name: str, value: object) -> str:
            if isinstance(value, dict):
                return f"{name} (struct)"
            shape = np.shape(value)
            return f"{name} {shape}" if len(shape) > 1 else name
        return ", ".join(one(k, v) for k, v in self.tree.items())

    def resolve(self, expr: str, role: str) -> Signal:
        value, label = resolve_tree(self.tree, expr, role, self.path, self.names())
        return Signal(label, as_signal(value, label, f"{self.path}: role {role}"))


def _why_unreadable(path: Path, exc: Exception) -> str:
    """What is wrong with a .mat scipy cannot read, from its bytes (scipy's messages name its internals: "index out
    of range", "could not read bytes"): empty, truncated (the variable whose declared size runs past the end), a
    damaged MATLAB 5.0 file, or neither a v5 header nor a v4 matrix."""
    size = path.stat().st_size
    if size == 0:
        return "the file is empty (0 bytes)"
    with open(path, "rb") as f:
        head = f.read(128)
        if not head.startswith(b"MATLAB 5.0"):
            cut = re.search(r"Not enough bytes to read matrix '([^']*)'", str(exc))
            return (f"truncated: matrix {cut[1]!r} ends past the end of the file ({size} bytes; read as MATLAB v4)"
                    if cut else "neither a MATLAB 5.0 header ('MATLAB 5.0 MAT-file' at its start) nor a MATLAB v4 "
                                "matrix")
        if size < 128:
            return f"truncated: {size} bytes, shorter than the 128-byte MATLAB 5.0 header"
        order = {b"IM": "<", b"MI": ">"}.get(head[126:128])
        if order is None:
            return "damaged: the MATLAB 5.0 header's byte-order mark (bytes 127-128) is neither 'IM' nor 'MI'"
        pos, k = 128, 1
        while pos < size:  # each variable: an 8-byte tag (type, byte count), its data padded to 8 bytes
            f.seek(pos)
            tag = f.read(8)
            if len(tag) < 8:
                return f"truncated: variable {k}'s 8-byte tag at byte {pos} is cut by the end of the file ({size} bytes)"
            kind, nbytes = struct.unpack(order + "II", tag)
            if kind >> 16:  # a small element: its data inside the tag
                nbytes = 0
            elif pos + 8 + nbytes > size:
                return (f"truncated: variable {k} at byte {pos} declares {nbytes} bytes, {pos + 8 + nbytes - size} more "
                        f"than the file holds ({size} bytes)")
            pos, k = pos + 8 + nbytes + (0 if kind == 15 else -nbytes % 8), k + 1  # 15: compressed, not padded
    return f"damaged: a MATLAB 5.0 file of {k - 1} variable(s) whose content cannot be decoded"
