"""The instruments' RK4 rollout as compiled C (issue 26): CasADi generates the step, gcc compiles it once.

``simulation.simulate`` integrates a model equation from sample to sample with a CasADi ``mapaccum`` of
the RK4 step, evaluated by CasADi's virtual machine: 1.8 ms per rollout of 2900 steps, and IV with the
model check run about ten per motion. The same step, generated as C by CasADi and called in a C loop,
computes the same floating-point operations in the same order (no fast-math, no contraction into fused
multiply-adds) in a few hundredths of that. The library is built once per (equations, inputs,
substeps) and kept in the FMU cache (``$FEEDDRIVE_CACHE`` or ``~/.cache/feeddrive``) under the hash of
its source; without a working C compiler the rollout stays with CasADi's virtual machine.
"""
from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import shlex
import subprocess
import tempfile
from functools import lru_cache
from pathlib import Path

import casadi as ca
import numpy as np

_LOOP = """
#include <string.h>
/* x_(k+1) = step(x_k, S[:, k], p, h) for k < steps; X holds x_1 .. x_steps (column k at X + k nx) */
int fd_rollout(long steps, const double* x0, const double* S, const double* p, double h, double* X) {{
  const casadi_real* arg[{sz_arg} + 1];
  casadi_real* res[{sz_res} + 1];
  casadi_int iw[{sz_iw} + 1];  /* work arrays on the stack: ctypes releases the GIL, calls may overlap */
  casadi_real w[{sz_w} + 1];
  long k;
  for (k = 0; k < steps; ++k) {{
    arg[0] = k ? X + (k - 1) * {nx} : x0;
    arg[1] = S + k * {ns};
    arg[2] = p;
    arg[3] = &h;
    res[0] = X + k * {nx};
    if (fd_step(arg, res, iw, w, 0)) return 1;
  }}
  return 0;
}}
"""


def _cache_root() -> Path:
    return Path(os.environ.get("FEEDDRIVE_CACHE") or Path.home() / ".cache" / "feeddrive") / "rollout"


def _build(source: str) -> Path:
    """The shared library of ``source``, compiled into the cache unless it is there (atomic rename)."""
    compiler = shlex.split(os.environ.get("CC") or "cc")  # as the FMU build's (estimator does not import it)
    # the machine and the compiler are part of the name: a cache shared between machines keeps one of each
    key = f"{source}/* {platform.machine()} {' '.join(compiler)} */"
    target = _cache_root() / f"{hashlib.sha256(key.encode()).hexdigest()[:20]}.so"
    if target.is_file():
        return target
    target.parent.mkdir(parents=True, exist_ok=True)
    import fcntl

    # one compile per library at a time (the PMSM closed loop's is 9 s of gcc): a process that waited finds it built
    with open(target.with_suffix(".lock"), "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes, or when a killed process ends
        if target.is_file():
            return target
        with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
            c = Path(tmp, "rollout.c")
            c.write_text(source, encoding="utf-8")
            so = Path(tmp, "rollout.so")
            # -ffp-contract=off: no fused multiply-add, so that the results are CasADi's to the last bit
            # its elapsed time on a terminal (a PMSM's closed loop takes 9 s, once): the FMU build's display, imported
            # only here, on a cache miss (fmu_build brings fmpy, which recorded data's estimation does not need)
            from feeddrive.fmu_build.build import run_with_progress

            done = run_with_progress([*compiler, "-O2", "-shared", "-fPIC", "-ffp-contract=off", "-o", str(so), str(c),
                                      "-lm"], None, f"compiling the estimator's model simulation ({compiler[0]}, once)", timeout=120)
            if done.returncode != 0:
                raise subprocess.CalledProcessError(done.returncode, done.args, done.stdout, done.stderr)
            os.replace(so, target)
    return target


def load_library(source: str, off: str, signatures: dict[str, list]) -> ctypes.CDLL | None:
    """``source`` built into the cache (``_build``) and loaded, each named function given its argument types
    (returning void); None without a compiler or with the environment variable ``off`` set: the caller keeps
    its numpy path (the filters of ``lti``, the spline of ``spline_c``)."""
    if os.environ.get(off):
        return None
    try:
        lib = ctypes.CDLL(str(_build(source)))
    except (OSError, subprocess.SubprocessError):
        return None
    for name, argtypes in signatures.items():
        fn = getattr(lib, name)
        fn.argtypes, fn.restype = argtypes, None
    return lib


@lru_cache(maxsize=32)
def compiled_step(step: ca.Function, key: str):
    """``run(x0 (nx,), S (ns, steps), p (np,), h) -> X (nx, steps)`` of the RK4 ``step`` compiled as C, or
    None when it cannot be built here (no compiler: the caller keeps CasADi's ``mapaccum``).

    ``key`` names the step (its equations, inputs and substeps) for the cache; the library's file name is
    the hash of its source, so a changed model is a new library.
    """
    if os.environ.get("FEEDDRIVE_NO_COMPILED_ROLLOUT"):
        return None
    nx, ns = step.size1_in(0), step.size1_in(1)
    gen = ca.CodeGenerator("rollout", {"with_header": False})
    gen.add(ca.Function("fd_step", step.sx_in(), step.call(step.sx_in())))
    source = gen.dump() + _LOOP.format(sz_iw=step.sz_iw(), sz_w=step.sz_w(), sz_arg=step.sz_arg(),
                                       sz_res=step.sz_res(), nx=nx, ns=ns) + f"/* {key} */\n"
    try:
        lib = ctypes.CDLL(str(_build(source)))
    except (OSError, subprocess.SubprocessError):
        return None
    fn = lib.fd_rollout
    dp = ctypes.c_void_p  # the arrays by address: ``data_as`` built a pointer object per argument and call
    fn.argtypes = [ctypes.c_long, dp, dp, dp, ctypes.c_double, dp]
    fn.restype = ctypes.c_int

    def run(x0: np.ndarray, S: np.ndarray, p: np.ndarray, h: float) -> np.ndarray:
        x0 = np.ascontiguousarray(x0, dtype=float)
        S = np.asarray(S, dtype=float)
        # column k of S contiguous: S transposed into a C array an input at a time (one strided copy each, where
        # ascontiguousarray called numpy's copy loop once per step for its 2-4 values)
        St = S.T
        if not St.flags.c_contiguous:
            St = np.empty(S.shape[::-1])
            for j, row in enumerate(S):
                St[:, j] = row
        p = np.ascontiguousarray(p, dtype=float)
        steps = St.shape[0]
        X = np.empty((steps, nx))
        if fn(steps, x0.ctypes.data, St.ctypes.data, p.ctypes.data, float(h), X.ctypes.data):
            raise ArithmeticError("compiled rollout: the step function failed")
        return X.T

    return run
