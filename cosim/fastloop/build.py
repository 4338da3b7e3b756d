"""Compile ``fineloop.c`` with the system C compiler once per source and compiler, and load it.

The library is cached as ``<cache>/fastloop/<hash>/fineloop.so`` (``$FEEDDRIVE_CACHE`` or
``~/.cache/feeddrive``, as the built-in FMU); the hash covers the source, the compiler command and the
flags. ``-ffp-contract=off`` keeps the compiler from fusing a multiply and an add into one rounding (the
Python loop rounds each), so the compiled loop gives the same bits as the Python one.
"""
from __future__ import annotations

import ctypes
import hashlib
import os
import subprocess
import tempfile
from functools import lru_cache
from pathlib import Path

SOURCE = Path(__file__).with_name("fineloop.c")
CFLAGS = ("-O2", "-fPIC", "-shared", "-ffp-contract=off", "-fno-fast-math", "-std=c99")


class BuildFailed(RuntimeError):
    """The compiled fine loop could not be built or loaded; the master runs its Python loop."""


def _cache_root() -> Path:
    return Path(os.environ.get("FEEDDRIVE_CACHE") or Path.home() / ".cache" / "feeddrive") / "fastloop"


def _compile(cc: list[str], target: Path) -> None:
    with tempfile.TemporaryDirectory(dir=target.parent) as tmp:  # private: parallel builds do not collide
        out = Path(tmp) / "fineloop.so"
        done = subprocess.run([*cc, *CFLAGS, "-o", str(out), str(SOURCE), "-lm"], capture_output=True,
                              text=True, check=False)
        if done.returncode != 0:
            first = (done.stderr or done.stdout).strip().splitlines()[:1]
            raise BuildFailed(f"{' '.join(cc)} failed on {SOURCE.name}: {first[0] if first else '?'}")
        os.replace(out, target)  # atomic: another process sees the whole library or none


@lru_cache(maxsize=1)
def library() -> ctypes.CDLL:
    """The compiled fine loop (built on first use, then cached on disk and in this process).

    Raises
    ------
    BuildFailed
        No C compiler, a compiler error or an unwritable cache: the message says which.
    """
    from feeddrive.fmu_build.build import build_lock, compiler

    cc = compiler()
    text = SOURCE.read_bytes()
    key = hashlib.sha256(b"\0".join([text, *(s.encode() for s in cc), *(s.encode() for s in CFLAGS)])).hexdigest()[:16]
    target = _cache_root() / key / "fineloop.so"
    if not target.is_file():
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            with build_lock(_cache_root(), key):  # one compile at a time: a process that waited finds it built
                if not target.is_file():
                    _compile(cc, target)
        except FileNotFoundError:
            raise BuildFailed(f"no C compiler {cc[0]!r} (set $CC)") from None
        except OSError as exc:
            raise BuildFailed(f"cannot write {target.parent}: {exc.strerror}") from None
    lib = ctypes.CDLL(str(target))
    lib.fine_run.argtypes = [ctypes.c_void_p, ctypes.c_long, ctypes.c_long, ctypes.c_int]
    lib.fine_run.restype = ctypes.c_int
    lib.fd_format_rows.argtypes = [ctypes.c_void_p, ctypes.c_long, ctypes.c_long, ctypes.c_void_p, ctypes.c_long]
    lib.fd_format_rows.restype = ctypes.c_long
    return lib
