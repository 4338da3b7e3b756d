"""The plant FMU and the standard sensors as one compiled block (``fineloop.c``), and when it applies.

:func:`plan` decides per run: the fast path needs the plant as an FMI 2.0 Co-Simulation FMU
(:class:`FMUComponent`, Real outputs only), the standard :class:`SensorsComponent` right after it in the
stepping order, both at the finest rate, the plant's inputs read from components outside the block (or
numbers) and the sensors' from the plant (or numbers). Anything else (Model Exchange, FMI 3.0, another
sensor class, a plant split into FMUs, ``FEEDDRIVE_FASTLOOP=0``, no C compiler) runs the Python loop, with
the reason in ``Master.loop``.
"""
from __future__ import annotations

import ctypes
import os
from typing import Any

from feeddrive.cosim import fmi_progress
from feeddrive.cosim.fastloop.build import BuildFailed, library

MAX_FILTERS, MAX_SECTIONS = 5, 4
DONE, FMI_ERROR, NON_FINITE, NEED_ROWS = 0, 1, 2, 3

_p, _i, _l, _d = ctypes.c_void_p, ctypes.c_int, ctypes.c_long, ctypes.c_double


class _Fine(ctypes.Structure):
    """Mirror of ``fine_t`` in fineloop.c (same order and types)."""

    _fields_ = [
        ("instance", _p), ("set_real", _p), ("get_real", _p), ("do_step", _p), ("set_der", _p), ("rec", _p),
        ("code_set_real", _i), ("code_get_real", _i), ("code_do_step", _i), ("code_set_der", _i),
        ("uvr", _p), ("nu", _l), ("u", _p), ("base", _p), ("yvr", _p), ("ny", _l), ("y", _p),
        ("out_scale", _p), ("out_offset", _p), ("out_identity", _i), ("t0", _d), ("h", _d),
        ("foh", _i), ("period", _l), ("dvr", _p), ("nd", _l), ("order", _p), ("du", _p), ("foh_input", _p),
        ("prev", _p), ("have_prev", _i),
        ("sensors", _i), ("m", _l), ("mean", _i), ("weights", _p), ("acc", _d * 4), ("inv_m", _d),
        ("nfilt", _i), ("filt_channel", _i * MAX_FILTERS), ("filt_source", _i * MAX_FILTERS),
        ("filt_sections", _i * MAX_FILTERS), ("coefs", _d * (MAX_FILTERS * MAX_SECTIONS * 5)),
        ("zst", _d * (MAX_FILTERS * MAX_SECTIONS * 2)), ("lp", _d * 5), ("kinds", _i * 5), ("any_kind", _i),
        ("true_index", _l * 5), ("true_const", _d * 5), ("rows", _p), ("krow", _l), ("block", _l),
        ("gains", _d * 6), ("q", _d), ("conv", _d), ("inv_wh", _d), ("buffer", _p), ("window", _l),
        ("jbuf", _l), ("have_buffer", _i), ("out", _p),
        ("rec_buf", _p), ("rec_m", _l), ("n_rec", _l), ("rec_rows", _l), ("rec_cap", _l), ("rec_src", _p), ("tick", _l), ("function", _i), ("status", _i), ("status_code", _i),
    ]


def _addr(obj: Any) -> int:
    return ctypes.addressof(obj)


def _fn(f: Any) -> int:
    return ctypes.cast(f, ctypes.c_void_p).value


def plan(master: Any) -> tuple[FineLoop | None, str]:
    """The compiled block of ``master``'s plant and sensors, or None and why the Python loop runs."""
    from feeddrive.cosim.fmu_adapter import FMUComponent
    from feeddrive.cosim.sensors import SensorsComponent

    if os.environ.get("FEEDDRIVE_FASTLOOP", "1") == "0":
        return None, "python loop: FEEDDRIVE_FASTLOOP=0"
    names = list(master.components)
    plant, sensors = master.components.get("plant"), master.components.get("sensors")
    if plant is None or sensors is None:
        return None, "python loop: no plant and sensors"
    if type(plant) is not FMUComponent or plant.config.interface != "cs":
        return None, "python loop: the plant is not an FMI 2.0 Co-Simulation FMU"
    if type(sensors) is not SensorsComponent or sensors.exact_means:
        return None, "python loop: not the standard sensors"
    if names.index("sensors") != names.index("plant") + 1 or master.rates["plant"] != 1 or master.rates["sensors"] != 1:
        return None, "python loop: the plant and the sensors are not consecutive at the finest rate"
    if plant.__dict__.get("get_outputs") is not None and plant.get_outputs.__name__ == "<lambda>":
        return None, "python loop: the plant has non-Real outputs"
    if len(plant._u) != plant._nu or len(plant._y) != plant._ny or plant._ny != len(plant.output_names):
        return None, "python loop: the plant has array variables"
    a, b = master._slices[plant]
    inside = range(a, master._slices[sensors][1])
    if any(i in inside for i in master._input_index["plant"]):
        return None, "python loop: a plant input is connected to the plant or the sensors"
    if not all(a <= i < b or i >= master.n_signals for i in master._input_index["sensors"]):
        return None, "python loop: a sensor input is not a plant output or a number"
    if len(sensors._filters) > MAX_FILTERS or any(len(c) > MAX_SECTIONS for _, _, c, _ in sensors._filters):
        return None, "python loop: a low-pass filter of more sections than the compiled loop holds"
    try:
        lib = library()
    except BuildFailed as exc:
        return None, f"python loop: {exc}"
    return FineLoop(lib, master, plant, sensors), "compiled fine loop (plant FMU, sensors)"


class FineLoop:
    """The plant and the sensors stepped by ``fine_run``; their Python objects are synced by :meth:`sync`.

    ``run(k, n, hold)`` steps ticks k .. k + n - 1 and leaves the outputs (plant's, then the sensors' 8)
    in ``out``; failures raise the same errors as the Python loop (through the plant's own methods).
    """

    def __init__(self, lib: Any, master: Any, plant: Any, sensors: Any) -> None:
        self.plant, self.sensors = plant, sensors
        #: ``fine_run(address, k, n, hold)``: the compiled loop, its state's address (the master calls it directly)
        self.crun = lib.fine_run
        self.s = s = _Fine()
        self.address = ctypes.addressof(s)
        self._keep: list[Any] = []
        fmu = plant._fmu
        code = fmi_progress.CODE
        s.instance = plant._c
        s.set_real, s.get_real, s.do_step = _fn(plant._set_real), _fn(plant._get_real), _fn(plant._do_step)
        s.rec = _addr(plant._rec)
        s.code_set_real, s.code_get_real = code["fmi2SetReal"], code["fmi2GetReal"]
        s.code_do_step, s.code_set_der = code["fmi2DoStep"], code["fmi2SetRealInputDerivatives"]
        nu, ny = plant._nu, plant._ny
        s.uvr, s.nu, s.u = _addr(plant._uvr), nu, _addr(plant._u)
        self._base = (_d * max(nu, 1))()
        s.base = _addr(self._base)
        s.yvr, s.ny, s.y = _addr(plant._yvr), ny, _addr(plant._y)
        self._scale = (_d * max(ny, 1))(*[sc for sc, _ in plant._out_lin])
        self._offset = (_d * max(ny, 1))(*[o for _, o in plant._out_lin])
        s.out_scale, s.out_offset = _addr(self._scale), _addr(self._offset)
        s.out_identity = int(all(sc == 1 and o == 0 for sc, o in plant._out_lin))  # as FMUComponent.setup decides
        s.t0, s.h = plant._t0, plant._h
        if plant.input_hold == "foh":
            s.foh, s.period = 1, plant.input_period
            s.set_der = _fn(fmu.dll.fmi2SetRealInputDerivatives)
            s.dvr, s.nd, s.order, s.du = _addr(plant._dvr), len(plant._du), _addr(plant._order), _addr(plant._du)
            self._foh_input = (_l * max(len(plant._foh), 1))(*[k for k, _ in sorted(plant._foh, key=lambda p: p[1])])
            self._prev = (_d * max(nu, 1))()
            s.foh_input, s.prev = _addr(self._foh_input), _addr(self._prev)
            if plant._u_prev is not None:
                self._prev[:] = plant._u_prev
                s.have_prev = 1
        a = master._slices[plant][0]
        self.out = (_d * (ny + 8))()
        s.out = _addr(self.out)
        self._load_sensors(master, a)
        self._load_recorder(master, a)

    def _load_recorder(self, master: Any, a: int) -> None:
        """Recorded columns from the block (``rec_src``) and from the rest of the bus (``static``)."""
        import numpy as np

        from feeddrive.cosim.master import BLOCK

        s, width = self.s, self.plant._ny + 8
        cols = master._rec_index
        self._rec_src = (_l * max(len(cols), 1))(*[i - a if a <= i < a + width else -1 for i in cols])
        #: recorded columns not from the block, and their index in the master's bus Y
        self.static_cols = [j for j, i in enumerate(cols) if not a <= i < a + width]
        self.static_src = [cols[j] for j in self.static_cols]
        self.rec_buf = np.empty((BLOCK, max(len(cols), 1)))
        s.rec_buf, s.rec_m, s.n_rec, s.rec_cap = self.rec_buf.ctypes.data, master.m, len(cols), BLOCK
        s.rec_src = _addr(self._rec_src)

    def take_rows(self, Y: list, rows: list, recorder: Any) -> None:
        """Hand the rows the block recorded to ``recorder`` after ``rows`` (the master's, in order), the columns
        from outside the block taken from ``Y`` (constant over the block: no Python component stepped in it)."""
        s = self.s
        block = self.rec_buf[:s.rec_rows]
        s.rec_rows = 0
        if self.static_cols:
            block[:, self.static_cols] = [Y[i] for i in self.static_src]
        recorder.extend(rows)
        rows.clear()
        recorder.extend(block)

    def _load_sensors(self, master: Any, a: int) -> None:
        sn, s = self.sensors, self.s
        s.sensors, s.m, s.mean = 1, sn.oversample, int(sn._mean)
        self._weights = (_d * len(sn._weights))(*sn._weights)
        s.weights = _addr(self._weights)
        s.acc[:] = sn._acc
        s.inv_m = sn._inv_m
        s.nfilt = len(sn._filters)
        for f, (j, src, coefs, states) in enumerate(sn._filters):
            s.filt_channel[f], s.filt_source[f], s.filt_sections[f] = j, src, len(coefs)
            for k, (c, z) in enumerate(zip(coefs, states)):
                s.coefs[(f * MAX_SECTIONS + k) * 5:(f * MAX_SECTIONS + k + 1) * 5] = c
                s.zst[(f * MAX_SECTIONS + k) * 2:(f * MAX_SECTIONS + k + 1) * 2] = z
        s.lp[:] = sn._lp
        s.kinds[:] = sn._kinds
        s.any_kind = int(any(sn._kinds))
        for i, j in enumerate(master._input_index["sensors"]):
            if j >= master.n_signals:  # a number
                s.true_index[i], s.true_const[i] = -1, master._constants[j - master.n_signals]
            else:
                s.true_index[i] = j - a
        from feeddrive.cosim.sensors import BLOCK

        s.block = BLOCK
        s.q, s.conv, s.inv_wh = sn._q, sn._conv, sn._inv_wh
        self._buffer = (_d * sn._window)()
        s.buffer, s.window, s.jbuf = _addr(self._buffer), sn._window, sn._j
        if sn._buffer is not None:
            self._buffer[:] = sn._buffer
            s.have_buffer = 1
        self.out[self.plant._ny:] = sn._y
        self.out[:self.plant._ny] = self.plant.get_outputs()
        self.noise_changed(reset=True)

    def noise_changed(self, reset: bool = False) -> None:
        """The sensors drew a new block of noise (``reset``: from its first row) or an event changed a channel."""
        sn, s = self.sensors, self.s
        self._rows = sn._noise  # kept alive while the loop reads it
        s.rows = self._rows.ctypes.data
        if reset:
            s.krow = sn._k
        s.gains[:] = sn._gains

    def run(self, k: int, n: int, hold: int) -> None:
        """Step ticks k .. k + n - 1 (``hold``: the plant's inputs were set since the last call)."""
        if self.crun(self.address, k, n, hold):
            self.resume(k, n)

    def resume(self, k: int, n: int) -> None:
        """After ``fine_run`` stopped at ``s.tick`` inside ticks k .. k + n - 1: draw new noise rows and go on,
        or raise the failure as the Python loop would."""
        s = self.s
        while True:
            status = s.status_code
            self._failure(status)
            self.sensors._k = s.krow  # a new block of noise rows: drawn by the sensors as the Python loop would
            self.sensors._new_block()
            self.noise_changed(reset=True)
            n -= s.tick - k
            k = s.tick
            if not self.crun(self.address, k, n, 0):
                self.plant._k = k + n
                return

    def _failure(self, status: int) -> None:
        s, plant = self.s, self.plant
        if status == FMI_ERROR:
            plant._k = s.tick
            self.sync()
            plant._raise(fmi_progress.FUNCTIONS[s.function], s.status)
        if status == NON_FINITE:
            plant._k = s.tick + 1
            self.sync()
            plant._non_finite(list(self.out[:plant._ny]))
            raise AssertionError("unreachable: a non-finite output")  # pragma: no cover

    def sync(self) -> None:
        """Copy the loop's state back into the plant and the sensors objects (after the run, or a failure)."""
        s, plant, sn = self.s, self.plant, self.sensors
        plant._k = max(plant._k, s.tick)
        if s.foh and s.have_prev:
            plant._u_prev = self._prev[:plant._nu]
        sn._acc = list(s.acc)
        sn._lp = list(s.lp)
        for f, (_, _, coefs, states) in enumerate(sn._filters):
            for k, z in enumerate(states):
                z[:] = s.zst[(f * MAX_SECTIONS + k) * 2:(f * MAX_SECTIONS + k + 1) * 2]
        if s.have_buffer:
            sn._buffer = self._buffer[:]
        sn._j, sn._k = s.jbuf, s.krow
        sn._y = self.out[plant._ny:]
