"""MATLAB files: v4 to v7 through scipy.io.loadmat, v7.3 (HDF5) through h5py.

Matrices, structs (``rec.field``), struct arrays (``rec[1].field``) and numeric fields are read;
cell arrays and MATLAB objects (``MCOS`` opaque data, function handles) are listed as such and cannot
be mapped. v7.3 stores arrays column-major: h5py sees them with their dimensions reversed, which is
undone here, so that both versions give the same shapes.
"""
from __future__ import annotations

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
            raise DataError(f"{path}: not a readable MATLAB file ({type(exc).__name__}: "
                            f"{' '.join(str(exc).split()) or 'unreadable'}); expected a .mat of version 4 to 7.3") from None
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
            raise DataError(f"{path}: not a readable MATLAB v7.3 file ({exc})") from None

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
