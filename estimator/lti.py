"""Linear time-invariant filters in numpy: the few ``scipy.signal`` functions the run path uses.

Importing ``scipy.signal`` loads ``scipy.stats``, ``scipy.interpolate`` and more (0.6-1.5 s, most of
``cosim run``'s start-up, issue 23) for a Butterworth design and a handful of recursive filters. This
module gives the same numbers (tests/estimator/test_lti.py: within 1e-12 relative of scipy):

* :func:`butter_sos`: the digital Butterworth low-pass as second-order sections, designed as scipy's
  ``butter(order, cutoff, fs=fs, output="sos")`` (analog prototype, pre-warped bilinear transform,
  sections ordered with the poles nearest the unit circle last, the gain in the first);
* :func:`sosfilt`, :func:`sosfilt_zi`, :func:`sosfiltfilt` (odd extension of ``3 * ntaps`` samples,
  steady-state initial conditions: scipy's defaults);
* :func:`lfilter`, :func:`lfilter_zi`, :func:`bilinear_first_order` (``cont2discrete`` of ``1 / (a1 s + a0)``,
  bit for bit).

The recursions run as C loops with scipy's own order of operations (estimator/lti_c.py, compiled once by
estimator.compiled's facility and cached): bit for bit scipy's numbers, which matters, since the model checks amplify a
1e-14 change of a filtered signal to 1e-3 of a p-value. Without a C compiler they are evaluated block by block: the filter in transposed direct form II is a state-space
system ``z[k+1] = A z[k] + B u[k]``, ``y[k] = C z[k] + D u[k]``; within a block of ``BLOCK`` samples the
output is the block's initial state through ``C A^j`` plus its inputs through the impulse response
(a Toeplitz matrix product), and only the state is carried from block to block in Python. A 35 000-sample
record then costs ~300 Python steps instead of 35 000, at the rounding of a sum of ``BLOCK`` terms.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from feeddrive.estimator.errors import EstimatorInputError

# the compiled loops: called through this module's names (the tests replace _library here for the numpy path)
from feeddrive.estimator.lti_c import ROWS_PER_CALL, _c_sosfilt, _library, _ptr, available  # noqa: F401

#: samples per block of the recursions (the Toeplitz product costs BLOCK multiply-adds per sample)
BLOCK = 128


def butter_sos(order: int, cutoff_hz: float, fs: float) -> np.ndarray:
    """Digital Butterworth low-pass as second-order sections (scipy's ``butter(..., output="sos")``).

    Parameters
    ----------
    order : int
        Filter order (>= 1).
    cutoff_hz : float
        -3 dB cut-off frequency [Hz], in (0, fs / 2).
    fs : float
        Sampling frequency [Hz].

    Returns
    -------
    ndarray, shape ((order + 1) // 2, 6)
        Rows ``[b0, b1, b2, 1, a1, a2]``.
    """
    order = int(order)
    if order < 1:
        raise EstimatorInputError(f"butter_sos: order must be >= 1, got {order}")
    wn = 2.0 * float(cutoff_hz) / float(fs)  # normalised to Nyquist
    if not 0.0 < wn < 1.0:
        raise EstimatorInputError(f"butter_sos: cut-off {cutoff_hz} Hz must be in (0, {fs / 2:g}) Hz")
    # analog prototype (unit cut-off), then pre-warped to the cut-off at the design rate fs = 2
    m = np.arange(-order + 1, order, 2)
    poles = -np.exp(1j * np.pi * m / (2 * order))
    warped = 4.0 * np.tan(np.pi * wn / 2.0)
    poles = poles * warped
    gain = warped ** order
    # bilinear transform at fs = 2 (2 fs = 4): the zeros at infinity go to z = -1
    digital = (4.0 + poles) / (4.0 - poles)
    gain = gain * np.real(1.0 / np.prod(4.0 - poles))
    # scipy's zpk2sos(pairing="nearest"): one pole of each conjugate pair and the real ones (odd order: with a
    # pole and a zero at the origin); the sections are filled from the last, each time with the pole nearest
    # the unit circle and the zeros nearest to it (every zero is real here: -1, and 0 for an odd order)
    tol = 100 * np.spacing(1.0)
    poles = [complex(p) for p in digital if p.imag > tol * abs(p)]
    poles += [complex(p.real, 0.0) for p in digital if abs(p.imag) <= tol * abs(p)] + [0j] * (order % 2)
    zeros = [-1.0] * order + [0.0] * (order % 2)
    sections = []
    while poles:
        p1 = poles.pop(int(np.argmin([abs(1 - abs(p)) for p in poles])))
        if p1.imag != 0:
            p2 = p1.conjugate()
        else:  # the real pole nearest the unit circle among the other real ones
            reals = [j for j, p in enumerate(poles) if p.imag == 0]
            p2 = poles.pop(reals[int(np.argmin([abs(1 - abs(poles[j])) for j in reals]))])
        z1 = zeros.pop(int(np.argsort([abs(z - p1) for z in zeros], kind="stable")[0]))
        z2 = zeros.pop(int(np.argsort([abs(z - p1) for z in zeros], kind="stable")[0]))
        sections.append([1.0, -(z2 + z1), z1 * z2, 1.0, -(p2 + p1).real, (p1 * p2).real])
    sos = np.array(sections[::-1], dtype=float)
    sos[0, :3] *= gain
    return sos


def sosfilt_zi(sos: np.ndarray) -> np.ndarray:
    """Initial states of :func:`sosfilt` for a unit step's steady state, shape (n_sections, 2)."""
    sos = np.asarray(sos, dtype=float)
    return _sosfilt_zi(sos.tobytes(), sos.shape).copy()


@lru_cache(maxsize=64)
def _sosfilt_zi(data: bytes, shape: tuple) -> np.ndarray:
    # one design per (sections): every zero-phase filtering asked for it twice, a motion's treatment dozens of
    # times (two linear solves each, ~0.2 ms); keyed by the coefficients' bytes, so the numbers are the same
    sos = np.frombuffer(data).reshape(shape)
    zi = np.empty((sos.shape[0], 2))
    scale = 1.0
    for s, row in enumerate(sos):
        b, a = row[:3], row[3:]
        zi[s] = scale * lfilter_zi(b, a)
        scale *= b.sum() / a.sum()
    return zi


def sosfilt(sos: np.ndarray, x: np.ndarray, zi: np.ndarray | None = None) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Filter ``x`` along its last axis by the cascade of second-order sections ``sos``.

    Parameters
    ----------
    sos : ndarray, shape (n_sections, 6)
    x : ndarray, shape (n,) or (m, n)
    zi : ndarray, shape (n_sections, 2) or (n_sections, m, 2), optional
        Initial states (transposed direct form II, as scipy's).

    Returns
    -------
    y : ndarray, shape of ``x``
    zf : ndarray, shape of ``zi``
        Final states; returned only with ``zi``.
    """
    sos = np.asarray(sos, dtype=float)
    x = np.asarray(x, dtype=float)
    rows = np.atleast_2d(x)
    states = np.zeros((sos.shape[0], rows.shape[0], 2))
    if zi is not None:
        states[...] = np.asarray(zi, dtype=float).reshape(sos.shape[0], -1, 2)
    lib = _library()
    if lib is not None:
        y = np.array(rows, dtype=float, order="C")
        z = np.ascontiguousarray(states.transpose(1, 0, 2))  # (m, n_sections, 2)
        coefs = np.ascontiguousarray(sos / sos[:, 3:4])
        _c_sosfilt(lib, coefs, y, z, 0)
        y = y.reshape(x.shape)
        return y if zi is None else (y, z.transpose(1, 0, 2).reshape(np.shape(zi)))
    # the sections as one state-space system (a section's state is the two entries of its zi)
    system = _state_space(tuple((tuple(r[:3] / r[3]), tuple(r[3:] / r[3])) for r in sos))
    y, final = _filter(system, rows, states.transpose(1, 0, 2).reshape(rows.shape[0], -1))
    final = final.reshape(rows.shape[0], sos.shape[0], 2).transpose(1, 0, 2)
    y = y.reshape(x.shape)
    if zi is None:
        return y
    return y, final.reshape(np.shape(zi))


def sosfiltfilt(sos: np.ndarray, x: np.ndarray | list[np.ndarray], keep_input: bool = False
                ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Zero-phase forward-backward filter of ``x`` along its last axis (scipy's ``sosfiltfilt`` defaults:
    odd extension by ``3 * ntaps`` samples at each end, each pass started in the steady state of its
    first sample).

    Parameters
    ----------
    sos : ndarray, shape (n_sections, 6)
    x : ndarray, shape (n,) or (m, n), or list of m ndarrays of shape (n,)
        ``n`` must exceed the extension. A list is filtered as its rows stacked (``FilterSpec.apply``'s signals),
        each written once into the extended array rather than stacked first.
    keep_input : bool
        Also return a copy of the input rows (``FilterSpec.apply``'s memo compares them with later calls'): the
        extended array the rows were written into, kept, for the forward pass writes into another (no second
        copy of each row).

    Returns
    -------
    ndarray, shape of ``x`` ((m, n) for a list)
    ndarray, shape of ``x``, read-only
        With ``keep_input``: the input's values.
    """
    sos = np.asarray(sos, dtype=float)
    if isinstance(x, list):
        rows = [np.asarray(r, dtype=float) for r in x]
        x = np.empty((len(rows), rows[0].size))  # its shape only
    else:
        x = np.asarray(x, dtype=float)
        rows = np.atleast_2d(x)
    ntaps = 2 * sos.shape[0] + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum()))
    edge = 3 * ntaps
    n = x.shape[-1]
    if n <= edge:
        raise EstimatorInputError(f"sosfiltfilt: the signal has {n} samples; the extension needs more than {edge}")
    ext = np.empty((len(rows), n + 2 * edge))
    for r, row in zip(ext, rows):  # the odd extension at both ends around the row: np.concatenate's values
        np.subtract(2 * row[:1], row[edge:0:-1], out=r[:edge])
        r[edge:edge + n] = row
        np.subtract(2 * row[-1:], row[-2:-(edge + 2):-1], out=r[edge + n:])
    zi = sosfilt_zi(sos)[:, None, :]
    lib = _library()
    if lib is not None:  # sosfilt's C loop on arrays of its own: no copy of the extension and none of the reversal
        coefs = np.ascontiguousarray(sos / sos[:, 3:4])
        out = np.empty_like(ext) if keep_input else ext  # the forward pass into another array: ext stays the input
        for backward in (0, 1):  # the backward pass starts in the steady state of the forward output's last sample
            z = np.ascontiguousarray((zi * out[None, :, -1:] if backward else zi * ext[None, :, :1]).transpose(1, 0, 2))
            _c_sosfilt(lib, coefs, out, z, backward, None if backward else ext)
        y = out[:, edge:-edge].reshape(x.shape)
    else:
        y, _ = sosfilt(sos, ext, zi * ext[None, :, :1])
        y = y[:, ::-1]
        y, _ = sosfilt(sos, y, zi * y[None, :, :1])
        y = y[:, ::-1][:, edge:-edge].reshape(x.shape)
    if not keep_input:
        return y
    kept = ext[:, edge:-edge].reshape(x.shape)
    kept.setflags(write=False)
    return y, kept


def lfilter_zi(b: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Initial states of :func:`lfilter` for a unit step's steady state, shape (max(len(a), len(b)) - 1,)."""
    b, a = _normalised(b, a)
    A, B, _, _ = _matrices(b, a)
    return np.linalg.solve(np.eye(A.shape[0]) - A, B)


def lfilter(b: np.ndarray, a: np.ndarray, x: np.ndarray, zi: np.ndarray | None = None
            ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Filter the 1-D ``x`` by ``b(z) / a(z)`` (transposed direct form II, scipy's ``lfilter``).

    Parameters
    ----------
    b, a : array_like
        Numerator and denominator coefficients (``a[0] != 0``; at least one pole or zero).
    x : ndarray, shape (n,)
    zi : array_like, shape (max(len(a), len(b)) - 1,), optional
        Initial states.

    Returns
    -------
    y : ndarray, shape (n,)
    zf : ndarray
        Final states; returned only with ``zi``.
    """
    b, a = _normalised(b, a)
    x = np.asarray(x, dtype=float)
    lib = _library()
    if lib is not None:
        u = np.ascontiguousarray(x)
        y = np.empty_like(u)
        z = np.zeros(b.size - 1) if zi is None else np.array(zi, dtype=float).reshape(b.size - 1)
        lib.fd_lfilter(u.size, b.size, _ptr(b), _ptr(a), _ptr(u), _ptr(y), _ptr(z))
        return y if zi is None else (y, z)
    system = _state_space(((tuple(b), tuple(a)),))
    k = system[0].shape[0]
    z0 = np.zeros((1, k)) if zi is None else np.asarray(zi, dtype=float).reshape(1, k)
    y, zf = _filter(system, x.reshape(1, -1), z0)
    return y[0] if zi is None else (y[0], zf[0])


def bilinear_first_order(a1: float, a0: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """``1 / (a1 s + a0)`` discretised by the bilinear (Tustin) transform at period ``h`` [s]: ``b``, ``a``
    (each shape (2,), ``a[0] = 1``), scipy's ``cont2discrete(([1], [a1, a0]), h, method="bilinear")`` bit for bit.

    scipy goes through the state-space model ``A = -a0 / a1``, ``C = 1 / a1`` and back; its rounding differs
    from the closed form ``h / (2 a1 + a0 h)`` by up to ~1e-11 relative, and the model checks' simulations
    over thousands of samples with a pole within 1e-5 of 1 carry that into their p-values (1e-3 relative in
    a PMSM motion's output-error check). Its scalar steps are therefore repeated here in its order."""
    A, C = -(a0 / a1), 1.0 / a1
    ima = 1.0 - (0.5 * h) * A  # I - alpha dt A
    ad, bd, cd = (1.0 + (0.5 * h) * A) / ima, h / ima, C / ima
    dd = 0.0 + 0.5 * (C * bd)
    # ss2tf: den = poly(ad), num = poly(ad - bd cd) + (dd - 1) den
    return np.array([1.0 + (dd - 1.0), -(ad - bd * cd) + (dd - 1.0) * -ad]), np.array([1.0, -ad])


def _normalised(b: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    b = np.atleast_1d(np.asarray(b, dtype=float))
    a = np.atleast_1d(np.asarray(a, dtype=float))
    if a.size == b.size >= 2 and a[0] != 0:  # the usual case, without trim_zeros' and pad's overhead (same numbers)
        return b / a[0], a / a[0]
    a = np.trim_zeros(a, "f")
    if a.size == 0:
        raise ValueError("lfilter: at least one coefficient of a must be non-zero")
    n = max(a.size, b.size)
    if n < 2:
        raise ValueError("lfilter: a filter without state (len(a) = len(b) = 1) is a product, not a filter")
    return np.pad(b / a[0], (0, n - b.size)), np.pad(a / a[0], (0, n - a.size))


def _matrices(b: tuple, a: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """``A, B, C, D`` of the transposed direct form II of ``b / a`` (``a[0] = 1``, same lengths)."""
    k = len(a) - 1
    A = np.zeros((k, k))
    A[:, 0] = -np.asarray(a[1:])
    A[np.arange(k - 1), np.arange(1, k)] = 1.0
    B = np.asarray(b[1:]) - np.asarray(a[1:]) * b[0]
    C = np.zeros(k)
    C[0] = 1.0
    return A, B, C, float(b[0])


def _cascade(sections: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """``A, B, C, D`` of the filters ``((b, a), ...)`` in series, the state the concatenation of theirs."""
    parts = [_matrices(b, a) for b, a in sections]
    k = sum(p[0].shape[0] for p in parts)
    A, B = np.zeros((k, k)), np.zeros(k)
    C_in, D_in = np.zeros(k), 1.0  # a section's input: C_in z + D_in u
    start = 0
    for Ai, Bi, Ci, Di in parts:
        rows = slice(start, start + Ai.shape[0])
        A[rows] = np.outer(Bi, C_in)
        A[rows, rows] += Ai
        B[rows] = Bi * D_in
        C_out = Di * C_in
        C_out[rows] += Ci
        C_in, D_in = C_out, Di * D_in
        start = rows.stop
    return A, B, C_in, D_in


@lru_cache(maxsize=128)
def _state_space(sections: tuple) -> tuple[np.ndarray, ...]:
    """The block operators of the filters ``((b, a), ...)`` in series: ``A^BLOCK`` (k, k), ``Obs`` (BLOCK, k)
    with rows ``C A^j``, the Toeplitz impulse-response matrix ``T`` (BLOCK, BLOCK), ``G`` (k, BLOCK) with
    columns ``A^(BLOCK-1-i) B`` and the powers ``A^r`` (BLOCK + 1, k, k)."""
    A, B, C, D = _cascade(sections)
    k = A.shape[0]
    if k == 1:  # a first-order filter (the model checks'): its powers at once, its parameters change per motion
        powers = (A[0, 0] ** np.arange(BLOCK + 1.0))[:, None, None]
    else:
        powers = np.empty((BLOCK + 1, k, k))
        powers[0] = np.eye(k)
        for j in range(1, BLOCK + 1):
            powers[j] = A @ powers[j - 1]
    Obs = np.einsum("i,jik->jk", C, powers[:BLOCK])
    impulse = np.concatenate(([D], Obs[:BLOCK - 1] @ B))
    j = np.arange(BLOCK)
    lag = j[:, None] - j[None, :]
    T = np.where(lag >= 0, impulse[np.clip(lag, 0, None)], 0.0)
    G = (powers[BLOCK - 1::-1] @ B).T
    out = (powers[BLOCK], Obs, T, G, powers)
    for arr in out:
        arr.setflags(write=False)
    return out


def _filter(system: tuple, u: np.ndarray, z0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The state-space recursion of ``system`` on the rows of ``u`` (m, n) from states ``z0`` (m, k):
    outputs (m, n) and final states (m, k)."""
    AB, Obs, T, G, powers = system
    m, n = u.shape
    nb, r = divmod(n, BLOCK)
    # every product is batched over the rows (m, ...) @ (...): each row's arithmetic is that of the row
    # filtered alone, so a signal's result does not depend on the signals filtered with it
    full = u[:, :nb * BLOCK].reshape(m, nb, BLOCK)
    gain = full @ G.T  # (m, nb, k): each block's inputs' share of the state at its end
    Z = np.empty((m, nb + 1, 1, z0.shape[1]))
    Z[:, 0, 0] = z0
    ABt = AB.T
    if m == 1 and ABt.shape == (1, 1):  # one first-order signal (the model checks'): a loop of floats
        pole, zk, carried = float(ABt[0, 0]), float(z0[0, 0]), gain[0, :, 0].tolist()
        for blk, g in enumerate(carried, 1):
            zk = pole * zk + g
            Z[0, blk, 0, 0] = zk
    else:
        for blk in range(nb):
            Z[:, blk + 1] = Z[:, blk] @ ABt + gain[:, blk, None]
    Z = Z[:, :, 0]
    y = np.empty((m, n))
    y[:, :nb * BLOCK] = (full @ T.T + Z[:, :nb] @ Obs.T).reshape(m, nb * BLOCK)
    z = Z[:, nb, None]  # (m, 1, k)
    if r:
        tail = u[:, None, nb * BLOCK:]  # (m, 1, r)
        y[:, nb * BLOCK:] = (tail @ T[:r, :r].T + z @ Obs[:r].T)[:, 0]
        z = z @ powers[r].T + tail @ G[:, BLOCK - r:].T
    return y, z[:, 0]
