"""The compiled loops of estimator.lti: scipy's sosfilt and lfilter recursions in C, in scipy's order of operations.

Built once into the cache by estimator.compiled's facility; ``_library`` is None without a C compiler (or with
``$FEEDDRIVE_NO_COMPILED_FILTERS``), and estimator.lti then evaluates the recursions block by block in numpy.
"""
from __future__ import annotations

import ctypes
from functools import lru_cache

import numpy as np

_SOURCE = r"""
/* scipy's sosfilt (signal/_sosfilt.pyx), in its order of operations: the rows of x (m, n) in place,
   zi (m, ns, 2) updated; sections normalised (a0 = 1); reverse != 0: from the last sample to the first (the
   backward pass of a zero-phase filter, on the forward pass's output without a reversed copy) */
typedef double fd_v2 __attribute__((vector_size(16)));
/* two sections (the 4th-order low-pass), up to three row pairs at a time with their states in local variables
   (registers) rather than in the array indexed by the pair: the same operations in the same order per row, a
   third of the loads and stores; three pairs keep three independent chains in flight, as the loop below */
#define FD_DECL(p) fd_v2 s##p##a = z[4 * (p)], s##p##b = z[4 * (p) + 1], s##p##c = z[4 * (p) + 2], \
                         s##p##d = z[4 * (p) + 3];
#define FD_STEP(p) { double* q = x + 2 * (p) * n + k; const double* r = in + 2 * (p) * n + k; \
    fd_v2 xc = {r[0], r[n]}, xn; \
    xn = c0 * xc + s##p##a; s##p##a = c1 * xc - c3 * xn + s##p##b; s##p##b = c2 * xc - c4 * xn; xc = xn; \
    xn = d0 * xc + s##p##c; s##p##c = d1 * xc - d3 * xn + s##p##d; s##p##d = d2 * xc - d4 * xn; \
    q[0] = xn[0]; q[n] = xn[1]; }
#define FD_SAVE(p) z[4 * (p)] = s##p##a; z[4 * (p) + 1] = s##p##b; z[4 * (p) + 2] = s##p##c; z[4 * (p) + 3] = s##p##d;
static void fd_sos2_pairs(long g, long n, const fd_v2* c, const double* in, double* x, fd_v2* z, long reverse) {
  const fd_v2 c0 = c[0], c1 = c[1], c2 = c[2], c3 = c[3], c4 = c[4], d0 = c[5], d1 = c[6], d2 = c[7], d3 = c[8],
              d4 = c[9];
  long j, k;
  if (g == 3) {
    FD_DECL(0) FD_DECL(1) FD_DECL(2)
    for (j = 0; j < n; ++j) { k = reverse ? n - 1 - j : j; FD_STEP(0) FD_STEP(1) FD_STEP(2) }
    FD_SAVE(0) FD_SAVE(1) FD_SAVE(2)
  } else if (g == 2) {
    FD_DECL(0) FD_DECL(1)
    for (j = 0; j < n; ++j) { k = reverse ? n - 1 - j : j; FD_STEP(0) FD_STEP(1) }
    FD_SAVE(0) FD_SAVE(1)
  } else {
    FD_DECL(0)
    for (j = 0; j < n; ++j) { k = reverse ? n - 1 - j : j; FD_STEP(0) }
    FD_SAVE(0)
  }
}
static void fd_sos2_row(long n, const double* sos, const double* in, double* x, double* z, long reverse) {
  const double c0 = sos[0], c1 = sos[1], c2 = sos[2], c3 = sos[4], c4 = sos[5];
  const double d0 = sos[6], d1 = sos[7], d2 = sos[8], d3 = sos[10], d4 = sos[11];
  double sa = z[0], sb = z[1], sc = z[2], sd = z[3], xc, xn;
  long j, k;
  for (j = 0; j < n; ++j) {
    k = reverse ? n - 1 - j : j;
    xc = in[k];
    xn = c0 * xc + sa; sa = c1 * xc - c3 * xn + sb; sb = c2 * xc - c4 * xn; xc = xn;
    xn = d0 * xc + sc; sc = d1 * xc - d3 * xn + sd; sd = d2 * xc - d4 * xn;
    x[k] = xn;
  }
  z[0] = sa; z[1] = sb; z[2] = sc; z[3] = sd;
}
void fd_sosfilt(long m, long n, long ns, const double* sos, double* x, double* zi, long reverse, const double* in) {
  /* in: the rows read (m, n), x: the rows written; in == x filters in place, else in is left as it was */
  long i, j, k, s, pairs = m / 2;
  /* sample k of every row before sample k + 1 of any: each row's recursion is a chain of dependent
     multiply-adds, and the rows' chains, independent, then overlap in the processor (6 rows: 2.3x faster
     than row after row). Two rows share the two lanes of a vector: the same multiplications, additions and
     subtractions, each rounded as the scalar ones (no fused multiply-add: -ffp-contract=off), in the same
     order, so each row's numbers are unchanged; a last odd row runs alone */
  fd_v2 c[ns * 5 + 1], z[pairs * ns * 2 + 1];
  for (s = 0; s < ns; ++s) {
    const double* cs = sos + 6 * s;
    c[5 * s] = (fd_v2){cs[0], cs[0]};
    c[5 * s + 1] = (fd_v2){cs[1], cs[1]};
    c[5 * s + 2] = (fd_v2){cs[2], cs[2]};
    c[5 * s + 3] = (fd_v2){cs[4], cs[4]};
    c[5 * s + 4] = (fd_v2){cs[5], cs[5]};
  }
  for (i = 0; i < pairs; ++i)
    for (j = 0; j < 2 * ns; ++j)
      z[i * ns * 2 + j] = (fd_v2){zi[2 * i * ns * 2 + j], zi[(2 * i + 1) * ns * 2 + j]};
  if (ns == 2) {
    for (i = 0; i < pairs; i += 3)
      fd_sos2_pairs(pairs - i < 3 ? pairs - i : 3, n, c, in + 2 * i * n, x + 2 * i * n, z + i * 4, reverse);
    for (i = 2 * pairs; i < m; ++i)
      fd_sos2_row(n, sos, in + i * n, x + i * n, zi + i * 4, reverse);
  } else
  for (j = 0; j < n; ++j) {
    k = reverse ? n - 1 - j : j;
    for (i = 0; i < pairs; ++i) {
      double* a = x + 2 * i * n + k;
      const double* r = in + 2 * i * n + k;
      fd_v2* zp = z + i * ns * 2;
      fd_v2 x_cur = {r[0], r[n]}, x_new;
      for (s = 0; s < ns; ++s) {
        const fd_v2* cs = c + 5 * s;
        x_new = cs[0] * x_cur + zp[2 * s];
        zp[2 * s] = cs[1] * x_cur - cs[3] * x_new + zp[2 * s + 1];
        zp[2 * s + 1] = cs[2] * x_cur - cs[4] * x_new;
        x_cur = x_new;
      }
      a[0] = x_cur[0];
      a[n] = x_cur[1];
    }
    for (i = 2 * pairs; i < m; ++i) {
      double* zs = zi + i * ns * 2;
      double x_cur = in[i * n + k], x_new;
      for (s = 0; s < ns; ++s) {
        const double* cs = sos + 6 * s;
        x_new = cs[0] * x_cur + zs[2 * s];
        zs[2 * s] = cs[1] * x_cur - cs[4] * x_new + zs[2 * s + 1];
        zs[2 * s + 1] = cs[2] * x_cur - cs[5] * x_new;
        x_cur = x_new;
      }
      x[i * n + k] = x_cur;
    }
  }
  for (i = 0; i < pairs; ++i)
    for (j = 0; j < 2 * ns; ++j) {
      zi[2 * i * ns * 2 + j] = z[i * ns * 2 + j][0];
      zi[(2 * i + 1) * ns * 2 + j] = z[i * ns * 2 + j][1];
    }
}
/* scipy's lfilter (transposed direct form II, a[0] = 1, len(a) = len(b) = nb >= 2) of one signal */
void fd_lfilter(long n, long nb, const double* b, const double* a, const double* x, double* y, double* z) {
  long k, j;
  for (k = 0; k < n; ++k) {
    double xn = x[k];
    double yn = z[0] + b[0] * xn;
    for (j = 0; j < nb - 2; ++j)
      z[j] = z[j + 1] + xn * b[j + 1] - yn * a[j + 1];
    z[nb - 2] = xn * b[nb - 1] - yn * a[nb - 1];
    y[k] = yn;
  }
}
"""


@lru_cache(maxsize=1)
def _library() -> ctypes.CDLL | None:
    """The C loops, built once into the cache (estimator.compiled); None without a compiler or with
    ``$FEEDDRIVE_NO_COMPILED_FILTERS`` set (the block-wise numpy evaluation then)."""
    from feeddrive.estimator.compiled import load_library  # casadi with it: only when first filtering

    dp, n = ctypes.c_void_p, ctypes.c_long  # the arrays by address (_ptr)
    return load_library(_SOURCE, "FEEDDRIVE_NO_COMPILED_FILTERS",
                        {"fd_sosfilt": [n, n, n, dp, dp, dp, n, dp], "fd_lfilter": [n, n, dp, dp, dp, dp, dp]})


def available() -> bool:
    """True when the C loops could be built here."""
    return _library() is not None


#: rows per call of the C sosfilt: its states live on the C stack (a vector per row pair and section state)
ROWS_PER_CALL = 64


def _c_sosfilt(lib: ctypes.CDLL, coefs: np.ndarray, x: np.ndarray, z: np.ndarray, reverse: int,
               source: np.ndarray | None = None) -> None:
    """``fd_sosfilt`` on the rows of ``x`` (m, n) in place, ``z`` (m, n_sections, 2) (both C-contiguous), in blocks
    of ``ROWS_PER_CALL`` rows (each row's recursion is its own: the same numbers in one call or several). With
    ``source`` (m, n) C-contiguous, its rows are filtered into ``x`` and ``source`` is left as it was."""
    for i in range(0, x.shape[0], ROWS_PER_CALL):
        rows, states = x[i:i + ROWS_PER_CALL], z[i:i + ROWS_PER_CALL]  # contiguous blocks of rows
        read = rows if source is None else source[i:i + ROWS_PER_CALL]
        lib.fd_sosfilt(rows.shape[0], x.shape[1], coefs.shape[0], _ptr(coefs), _ptr(rows), _ptr(states), reverse,
                       _ptr(read))


def _ptr(a: np.ndarray) -> int:
    # the address itself (the arguments are declared void *): ``ctypes.data_as`` builds a pointer object per
    # call, ~5 us, and a motion's model check makes ~100 of these calls. The caller keeps ``a`` alive.
    return a.ctypes.data
