"""The plant FMU and the standard sensors as one compiled block (``fineloop.c``), and when it applies.

:func:`plan` decides per run: the fast path needs the plant as an FMI 2.0 Co-Simulation FMU
(:class:`FMUComponent`, Real outputs only), the standard :class:`SensorsComponent` right after it in the
stepping order, both at the finest rate, the plant's inputs read from components outside the block (or
numbers) and the sensors' from the plant (or numbers). Anything else (Model Exchange, FMI 3.0, another
sensor class, a plant split into FMUs, ``FEEDDRIVE_FASTLOOP=0``, no C compiler) runs the Python loop, with
the reason in ``Master.loop``. The standard NC, a PMSM's servo sensors (``servo.candidate``) and the monitor's
buffering join the block where their ports allow (:func:`_absorbed`); ``Master.loop`` names them.
"""
from __future__ import annotations

import ctypes
import os
from typing import Any

from feeddrive.cosim import fmi_progress
from feeddrive.cosim.fastloop import servo as servo_loop
from feeddrive.cosim.fastloop.build import BuildFailed, library

MAX_FILTERS, MAX_SECTIONS = 5, 4
DONE, FMI_ERROR, NON_FINITE, NEED_ROWS, NEED_NC, MONITOR, NEED_SERVO_ROWS = 0, 1, 2, 3, 4, 5, 6

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
        ("rec_buf", _p), ("rec_m", _l), ("n_rec", _l), ("rec_rows", _l), ("rec_cap", _l), ("rec_src", _p),
        ("tick", _l), ("function", _i), ("status", _i), ("status_code", _i), ("pout", _p),
        ("nc", _i), ("nc_d", _l), ("nc_done", _l), ("nc_h", _d), ("nc_tol", _d), ("nc_inv_h", _d), ("nc_conv", _d),
        ("nc_kv", _d), ("nc_ff", _d), ("segs", _p), ("nseg", _l), ("nc_k", _l), ("ts", _d), ("x0", _d), ("v0", _d),
        ("a", _d), ("nstate", _d), ("nload", _d), ("t_next", _d), ("nmotion", _d), ("x_prev", _d), ("t_now", _d),
        ("x_meas", _d), ("request_high", _i), ("pending", _i), ("request", _d), ("nc_pos", _l), ("nc_pos_const", _d),
        ("u_src", _p), ("u_const", _p), ("u_scale", _p), ("u_offset", _p), ("u_identity", _i),
        ("mon", _i), ("mon_d", _l), ("n_mon", _l), ("mon_src", _p), ("mon_const", _p), ("mon_state", _l),
        ("mon_motion_in", _l), ("mon_active", _i), ("mon_motion", _d), ("age_step", _d), ("mon_buf", _p),
        ("mon_rows", _l), ("mon_cap", _l),
        ("sv", _i), ("sv_fine", _i), ("sv_kinds", _i * 8), ("sv_second", _i), ("sv_copy_iu", _i), ("sv_src", _p),
        ("sv_const", _p), ("sv_scale", _p), ("sv_p", _d), ("sv_angle", _d * 3), ("sv_sin120", _d), ("sv_inv_m", _d),
        ("sv_weights", _p), ("sv_acc", _d * 8), ("sv_lp", _d * 8), ("sv_nfilt", _i), ("sv_filt_channel", _i * 8),
        ("sv_filt_sections", _i * 8), ("sv_coefs", _d * (8 * MAX_SECTIONS * 5)), ("sv_zst", _d * (8 * MAX_SECTIONS * 2)),
        ("sv_gain", _d * 10), ("sv_offset", _d * 10), ("sv_noise", _d * 10), ("sv_z", _p), ("sv_k", _l),
        ("sv_block", _l), ("sv_q", _d), ("sv_conv", _d), ("sv_res", _d), ("sv_out", _p),
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
    servo = servo_loop.candidate(master, plant, sensors, MAX_SECTIONS)
    nc, monitor = _absorbed(master, plant, sensors if servo is None else servo)
    fine = FineLoop(lib, master, plant, sensors, nc, monitor, servo)
    parts = ["NC"] * (nc is not None) + ["plant FMU", "sensors"] + ["servo sensors"] * (servo is not None) + \
        ["monitor's buffering"] * (monitor is not None)
    return fine, f"compiled fine loop ({', '.join(parts)})"


def _absorbed(master: Any, plant: Any, last: Any) -> tuple[Any, Any]:
    """The NC and the monitor that the compiled loop steps too, or None each (``last``: the block's last
    component, the sensors or the servo sensors after them).

    The NC (:class:`NCComponent`): right before the plant, which is the first component at the finest rate
    (or the NC at the finest rate too: it steps at the start of its cycle), its position from the plant or a number, its request from
    outside the block (constant over it) and the plant's inputs from the NC or numbers. The monitor
    (:class:`Monitor`): after the sensors, every input from the block or a number; the compiled loop
    buffers a motion's samples and stops where the monitor's step does more (cosim/monitor.py ``step_block``).
    """
    from feeddrive.cosim.monitor import Monitor
    from feeddrive.cosim.nc import NCComponent

    names, rates, n_sig = list(master.components), master.rates, master.n_signals
    nc, monitor = master.components.get("nc"), master.components.get("monitor")
    ip, b = names.index("plant"), master._slices[last][1]
    first_fine = next(j for j, n in enumerate(names) if rates[n] == 1)
    if type(nc) is NCComponent and names.index("nc") == ip - 1 and (first_fine == ip or rates["nc"] == 1):
        na, nb = master._slices[nc]
        pos, request = master._input_index["nc"]
        if (master._slices[plant][0] <= pos < b or pos >= n_sig) and not na <= request < b and all(
                na <= i < nb or i >= n_sig for i in master._input_index["plant"]):
            a = na
        else:
            nc = None
    else:
        nc = None
    if nc is None:
        a = master._slices[plant][0]
    if type(monitor) is not Monitor or names.index("monitor") < names.index("sensors") or not all(
            a <= i < b or i >= n_sig for i in master._input_index["monitor"]) or not all(
            a <= i < b for i in master._input_index["monitor"][7:9]):
        monitor = None
    return nc, monitor


class FineLoop:
    """The plant and the sensors (and the NC, the monitor's buffering) stepped by ``fine_run``; their Python
    objects are synced by :meth:`sync` (the NC's also around its steps in Python, the monitor's by
    :meth:`flush_monitor` after each block).

    ``run(k, n, Y)`` steps ticks k .. k + n - 1 (or to a monitor's stop) and leaves the outputs (the NC's 7
    when it steps here, the plant's, then the sensors' 8: the bus ``Y[a:b]``) in ``out``; failures raise the
    same errors as the Python loop (through the plant's own methods).
    """

    def __init__(self, lib: Any, master: Any, plant: Any, sensors: Any, nc: Any = None, monitor: Any = None,
                 servo: Any = None) -> None:
        self.plant, self.sensors, self.nc, self.monitor, self.servo = plant, sensors, nc, monitor, servo
        self.max_sections = MAX_SECTIONS
        #: the components the compiled loop steps (the master keeps the NC out of its Python steps inside a
        #: block and gives the monitor the samples the block buffered, see cosim/fastloop/blocks.py)
        self.absorbed = {c for c in (nc, monitor) if c is not None}
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
        #: the block's part of the master's bus Y: [a, b), the NC's outputs first when it steps here
        self.a = a = master._slices[nc if nc is not None else plant][0]
        self.b = master._slices[sensors if servo is None else servo][1]
        self.p = p = master._slices[plant][0] - a  # the plant's first output in out
        self.out = (_d * (self.b - a))()
        s.out, s.pout = _addr(self.out), _addr(self.out) + p * ctypes.sizeof(_d)
        s.nc_done = -1
        self._load_sensors(master, master._slices[plant][0])
        if servo is not None:
            servo_loop.load(self, master, servo)
        self._load_recorder(master, a)
        if nc is not None:
            self._load_nc_ports(master)
            self.load_nc()
        if monitor is not None:
            self._load_monitor(master)

    def _load_recorder(self, master: Any, a: int) -> None:
        """Recorded columns from the block (``rec_src``) and from the rest of the bus (``static``)."""
        import numpy as np

        s, width = self.s, self.b - self.a
        cols = master._rec_index
        self._rec_src = (_l * max(len(cols), 1))(*[i - a if a <= i < a + width else -1 for i in cols])
        #: recorded columns not from the block, and their index in the master's bus Y
        self.static_cols = [j for j, i in enumerate(cols) if not a <= i < a + width]
        self.static_src = [cols[j] for j in self.static_cols]
        BLOCK = master.block
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
        p, ny = self.p, self.plant._ny
        self.out[p + ny:p + ny + 8] = sn._y
        self.out[p:p + ny] = self.plant.get_outputs()
        self.noise_changed(reset=True)

    def noise_changed(self, reset: bool = False) -> None:
        """The sensors drew a new block of noise (``reset``: from its first row) or an event changed a channel."""
        sn, s = self.sensors, self.s
        self._rows = sn._noise  # kept alive while the loop reads it
        s.rows = self._rows.ctypes.data
        if reset:
            s.krow = sn._k
        s.gains[:] = sn._gains

    def run(self, k: int, n: int, Y: list) -> int:
        """Step ticks k .. k + n - 1, or to a tick whose monitor step the master takes (the block's last then):
        returns the tick after the last one stepped. The plant's inputs were set (``plant.set_inputs``) from
        ``Y``, the master's bus, which also holds the NC's request and the monitor's state."""
        s = self.s
        if self.nc is not None:
            s.request = Y[self._request] if self._request < len(Y) else self._request_const
        if self.monitor is not None:
            motion, age = self.monitor.block_state()
            s.mon_active, s.mon_motion, s.age_step = motion is not None, motion or 0.0, age
        hold = 1
        while True:
            status = self.crun(self.address, k, n, hold)
            if status == DONE:
                return k + n
            if status == MONITOR:
                return s.tick + 1
            self._failure(status)
            n -= s.tick - k
            k = s.tick
            if status == NEED_NC:  # the NC's step at tick k inserts pieces: in Python, as the Python loop
                self._nc_in_python(k, Y)
                hold = 1
            elif status == NEED_SERVO_ROWS:  # the servo sensors' next block of noise, drawn by them
                servo_loop.new_rows(self, self.servo)
                hold = 0
            else:  # a new block of noise rows: drawn by the sensors as the Python loop would
                self.sensors._k = s.krow
                self.sensors._new_block()
                self.noise_changed(reset=True)
                hold = 0
            self.plant._k = k

    def flush_monitor(self) -> None:
        """Give the monitor the samples the block buffered (its steps inside the block)."""
        s = self.s
        if self.monitor is not None and s.mon_rows:
            self.monitor.step_block(self.mon_buf[:s.mon_rows])
            s.mon_rows = 0

    def _nc_in_python(self, k: int, Y: list) -> None:
        """The NC's set_inputs and step at tick k in Python (the C loop goes on from the plant's step)."""
        nc, s = self.nc, self.s
        self.sync_nc()
        Y[self.a:self.b] = self.out[:]
        nc.set_inputs(self._nc_get(Y))
        nc.step(k // self._nc_d)
        Y[self.a:self.a + 7] = self.out[:7] = nc.get_outputs()
        self.plant.set_inputs(self._plant_get(Y))
        self.load_nc()
        s.nc_done = k

    def _load_nc_ports(self, master: Any) -> None:
        """Where the NC's inputs and the plant's come from (indices in out, or numbers)."""
        s, nc, plant, a, n_sig = self.s, self.nc, self.plant, self.a, master.n_signals
        names = list(master.components)
        self._nc_get = master._getters[names.index("nc")]
        self._plant_get = master._getters[names.index("plant")]
        self._nc_d = s.nc_d = master.rates["nc"]
        Y0 = master._constants
        pos, self._request = master._input_index["nc"]
        s.nc_pos, s.nc_pos_const = (-1, Y0[pos - n_sig]) if pos >= n_sig else (pos - a, 0.0)
        self._request_const = Y0[self._request - n_sig] if self._request >= n_sig else 0.0
        src = master._input_index["plant"]
        self._u_src = (_l * max(len(src), 1))(*[-1 if i >= n_sig else i - a for i in src])
        self._u_const = (_d * max(len(src), 1))(*[Y0[i - n_sig] if i >= n_sig else 0.0 for i in src])
        lin = {k: (sc, o) for k, sc, o in getattr(plant, "_in_lin", [])}
        self._u_scale = (_d * max(len(src), 1))(*[lin.get(k, (1.0, 0.0))[0] for k in range(len(src))])
        self._u_offset = (_d * max(len(src), 1))(*[lin.get(k, (1.0, 0.0))[1] for k in range(len(src))])
        s.u_src, s.u_const = _addr(self._u_src), _addr(self._u_const)
        s.u_scale, s.u_offset = _addr(self._u_scale), _addr(self._u_offset)
        s.u_identity = int(plant.__dict__.get("set_inputs") is not None)  # FMUComponent._set_inputs_identity
        s.nc_h, s.nc_tol, s.nc_inv_h, s.nc_conv = nc._h, nc._tol, nc._inv_h, nc._conv
        s.nc_kv, s.nc_ff = nc._kv, nc._ff
        self.out[:7] = nc.get_outputs()
        s.nc = 1

    def load_nc(self) -> None:
        """The NC's state (its pieces included: an inserted identification changes them) into the loop."""
        s, nc = self.s, self.nc
        self._segs = (_d * (7 * len(nc._segs)))(*[float(v) for seg in nc._segs for v in seg[:7]])
        s.segs, s.nseg, s.nc_k = _addr(self._segs), len(nc._segs), nc._k
        s.ts, s.x0, s.v0, s.a, s.nstate, s.nload = nc._ts, nc._x0, nc._v0, nc._a, nc._state, nc._load
        s.t_next, s.nmotion, s.x_prev, s.t_now, s.x_meas = nc._t_next, nc._motion, nc._x_prev, nc._t_now, nc._x_meas
        s.request_high, s.pending = nc._request_high, nc._pending

    def sync_nc(self) -> None:
        """The loop's NC state back into the NCComponent (state and motion as the ints it keeps)."""
        s, nc = self.s, self.nc
        nc._k, nc._ts, nc._x0, nc._v0, nc._a, nc._load = s.nc_k, s.ts, s.x0, s.v0, s.a, s.nload
        nc._state, nc._motion = int(s.nstate), int(s.nmotion)
        nc._t_next, nc._x_prev, nc._t_now, nc._x_meas = s.t_next, s.x_prev, s.t_now, s.x_meas
        nc._request_high = bool(s.request_high)
        nc._y = self.nc_outputs()

    def nc_outputs(self) -> list:
        """The NC's outputs as the NCComponent gives them (state and motion as ints)."""
        y = self.out[:7]
        y[5], y[6] = int(y[5]), int(y[6])
        return y

    def _load_monitor(self, master: Any) -> None:
        """The monitor's inputs (indices in out, or numbers) and the buffer of the samples a block buffers."""
        import numpy as np

        s, a, n_sig, Y0 = self.s, self.a, master.n_signals, master._constants
        src = master._input_index["monitor"]
        self._mon_src = (_l * len(src))(*[-1 if i >= n_sig else i - a for i in src])
        self._mon_const = (_d * len(src))(*[Y0[i - n_sig] if i >= n_sig else 0.0 for i in src])
        s.mon_src, s.mon_const, s.n_mon = _addr(self._mon_src), _addr(self._mon_const), len(src)
        s.mon_state, s.mon_motion_in = src[7] - a, src[8] - a
        s.mon_d = d = master.rates["monitor"]
        self.mon_buf = np.empty((master.block * master.m // d + 2, len(src)))
        s.mon_buf, s.mon_cap = self.mon_buf.ctypes.data, self.mon_buf.shape[0]
        s.mon = 1

    def _failure(self, status: int) -> None:
        s, plant = self.s, self.plant
        if status == FMI_ERROR:
            plant._k = s.tick
            self.sync()
            plant._raise(fmi_progress.FUNCTIONS[s.function], s.status)
        if status == NON_FINITE:
            plant._k = s.tick + 1
            self.sync()
            plant._non_finite(list(self.out[self.p:self.p + plant._ny]))
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
        sn._y = self.out[self.p + plant._ny:self.p + plant._ny + 8]
        if self.servo is not None:
            servo_loop.sync(self, self.servo)
        if self.nc is not None:
            self.sync_nc()
