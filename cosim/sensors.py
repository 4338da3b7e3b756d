"""Redundant sensors of the feed drive (paper section IV.B): the plant's true signals -> measurements.

Each analogue channel follows the paper's sensor model (eq. 9)::

    measured = gain * true + offset + noise * z,      z ~ N(0, 1), white

========  ================  ============================  ==========================================
output    from (true)       default noise (std)           why
========  ================  ============================  ==========================================
Im1, Im2  current [A]       0.05 A                        Hall-effect sensors, ~0.1 % of a 50 A range
u         voltage [V]       0.2 V                         isolated divider on a ~150 V bus
u_ref     voltage_ref [V]   0.2 V                         the regulator's analogue output
w_tach    speed [rad/s]     0.05 rad/s                    DC tachometer ripple, ~0.07 % of 70 rad/s
========  ================  ============================  ==========================================

The incremental encoder (``encoder``) counts ``4 lines`` edges per motor turn (x4 quadrature), so
``theta_enc`` [rad] is the motor angle rounded to the nearest multiple of ``2 pi / (4 lines)``; the
motor angle is ``gain * 2 pi belt_ratio / pitch * position + offset + noise * z`` (gain: a scale
error, offset [rad], noise [rad]: edge jitter; defaults 1, 0, 0). ``x`` [m] is ``theta_enc`` converted
back to the table, ``w_enc`` [rad/s] the backward difference of ``theta_enc`` over ``speed_window``
seconds (W = round(speed_window / h) steps)::

    w_enc(t_n) = (theta_enc(t_n) - theta_enc(t_n - W h)) / (W h)

i.e. the mean speed over the window, the speed at ``t_n - W h / 2`` for a smooth motion, with a
resolution of ``2 pi / (4 lines W h)`` (0.63 rad/s for 2500 lines and 1 ms).

Noise is drawn from one ``numpy.random.Generator`` per channel, seeded from ``seed`` and the channel
name, in blocks of ``BLOCK`` steps; the output is the same for the same seed whatever the noise
levels. Faults change a channel's ``gain``, ``offset`` or ``noise`` during a run through events
``sensors.<channel>.<field>`` (channels ``Im1``, ``Im2``, ``u``, ``u_ref``, ``w_tach``, ``encoder``).
"""
from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from typing import Any

import numpy as np
from pydantic import Field

from feeddrive.cosim.component import Component
from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.nc import StrictConfig, drive_chain_nominal

#: noise samples drawn at once per channel
BLOCK = 4096


class ChannelConfig(StrictConfig):
    """One analogue channel: ``gain`` [1], ``offset`` and ``noise`` (std, >= 0) in the signal's unit."""

    gain: float = 1.0
    offset: float = 0.0
    noise: float = Field(0.0, ge=0)


class CurrentSensor(ChannelConfig):
    noise: float = Field(0.05, ge=0)


class VoltageSensor(ChannelConfig):
    noise: float = Field(0.2, ge=0)


class Tachometer(ChannelConfig):
    noise: float = Field(0.05, ge=0)


class EncoderConfig(StrictConfig):
    """Incremental encoder on the motor shaft.

    Attributes
    ----------
    lines : int
        Lines per motor turn (x4 quadrature: 4 lines counts per turn).
    pitch, belt_ratio : float
        Drive chain [m per screw turn, motor turns per screw turn] converting the table position to
        the motor angle; default: the built-in model's design values.
    speed_window : float
        Differencing window of ``w_enc`` [s].
    gain, offset, noise : float
        Scale error [1], angle offset [rad] and angle noise std [rad] before quantisation.
    """

    lines: int = Field(2500, gt=0)
    pitch: float = Field(default_factory=lambda: drive_chain_nominal()[0], gt=0)
    belt_ratio: float = Field(default_factory=lambda: drive_chain_nominal()[1], gt=0)
    speed_window: float = Field(1.0e-3, gt=0)
    gain: float = 1.0
    offset: float = 0.0
    noise: float = Field(0.0, ge=0)


class SensorsConfig(StrictConfig):
    """The ``sensors:`` section of a scenario; every key is optional, a channel's omitted keys keep
    their defaults (noise levels: see the module docstring)."""

    seed: int = Field(0, ge=0)
    current: tuple[CurrentSensor, CurrentSensor] = (CurrentSensor(), CurrentSensor())
    voltage: VoltageSensor = VoltageSensor()
    voltage_ref: VoltageSensor = VoltageSensor()
    tachometer: Tachometer = Tachometer()
    encoder: EncoderConfig = Field(default_factory=EncoderConfig)

    def channels(self) -> dict[str, ChannelConfig | EncoderConfig]:
        """Event name -> configuration, in the order of the true signals they measure."""
        return {"Im1": self.current[0], "Im2": self.current[1], "u": self.voltage,
                "u_ref": self.voltage_ref, "w_tach": self.tachometer, "encoder": self.encoder}


_FIELDS = ("gain", "offset", "noise")


class SensorsComponent(Component):
    """Redundant measurements from the plant's true signals (see the module docstring).

    Inputs: ``voltage`` [V], ``voltage_ref`` [V], ``current`` [A], ``speed`` [rad/s], ``position`` [m].
    Outputs: ``Im1``, ``Im2`` [A], ``u``, ``u_ref`` [V], ``w_tach`` [rad/s], ``theta_enc`` [rad],
    ``w_enc`` [rad/s], ``x`` [m]. The outputs at t0 measure zero true signals (no plant value has been
    received yet); the encoder speed window starts filled with the first angle received.
    """

    input_names = ("voltage", "voltage_ref", "current", "speed", "position")
    output_names = ("Im1", "Im2", "u", "u_ref", "w_tach", "theta_enc", "w_enc", "x")
    output_units = ("A", "A", "V", "V", "rad/s", "rad", "rad/s", "m")

    def __init__(self, name: str, config: SensorsConfig | dict | None = None) -> None:
        super().__init__(name, SensorsConfig.parse(config, name))

    def setup(self, t0: float, h: float, n_steps: int) -> None:
        if not h > 0:
            raise ScenarioError(f"{self.name}: step must be > 0, got {h!r}")
        cfg = self.config
        channels = cfg.channels()
        self._names = tuple(channels)
        self._params = {c: {f: float(getattr(channels[c], f)) for f in _FIELDS} for c in self._names}
        self._rngs = [np.random.default_rng([cfg.seed, zlib.crc32(c.encode())]) for c in self._names]
        enc = cfg.encoder
        self._q = 2 * math.pi / (4 * enc.lines)
        self._conv = 2 * math.pi * enc.belt_ratio / enc.pitch
        self._h, self._window = h, max(1, round(enc.speed_window / h))
        self._inv_wh = 1.0 / (self._window * h)
        self._inputs: Sequence[float] = (0.0,) * 5
        self._buffer: list[float] | None = None
        self._j = 0
        self._new_block()
        self._measure()
        self._buffer, self._j = None, 0  # the speed window starts at the first plant sample, not at t0

    def _new_block(self) -> None:
        self._z = np.column_stack([rng.standard_normal(BLOCK) for rng in self._rngs])
        self._k = 0
        self._refresh()

    def _refresh(self) -> None:
        """Precompute ``offset + noise z`` over the block and unpack the gains."""
        p = [self._params[c] for c in self._names]
        offsets = np.array([q["offset"] for q in p])
        noise = np.array([q["noise"] for q in p])
        self._rows = (offsets + noise * self._z).tolist()
        self._gains = tuple(q["gain"] for q in p)

    def set_parameter(self, name: str, value: Any) -> None:
        """Change ``<channel>.<gain|offset|noise>`` from the next output on (a sensor fault)."""
        channel, _, field = name.partition(".")
        if channel not in self._params or field not in _FIELDS:
            raise ScenarioError(f"{self.name}.{name}: expected <channel>.<field> with channel in "
                                f"{', '.join(self._names)} and field in {', '.join(_FIELDS)}")
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise ScenarioError(f"{self.name}.{name}: expected a number, got {value!r}") from None
        if not math.isfinite(value) or (field == "noise" and value < 0):
            raise ScenarioError(f"{self.name}.{name}: expected a finite number{' >= 0' * (field == 'noise')}, "
                                f"got {value!r}")
        self._params[channel][field] = value
        self._refresh()

    def set_inputs(self, values: Sequence[float]) -> None:
        self._inputs = values

    def _measure(self) -> None:
        """Outputs from the stored true signals and the next noise row."""
        if self._k == BLOCK:
            self._new_block()
        o1, o2, ou, our, ow, oe = self._rows[self._k]
        self._k += 1
        g1, g2, gu, gur, gw, ge = self._gains
        voltage, voltage_ref, current, speed, position = self._inputs
        theta_enc = self._q * math.floor((ge * self._conv * position + oe) / self._q + 0.5)
        buffer = self._buffer
        if buffer is None:  # first plant sample: the axis is taken to have been at rest before
            buffer = self._buffer = [theta_enc] * self._window
        j = self._j
        w_enc = (theta_enc - buffer[j]) * self._inv_wh
        buffer[j] = theta_enc
        self._j = j + 1 if j + 1 < self._window else 0
        self._y = [g1 * current + o1, g2 * current + o2, gu * voltage + ou, gur * voltage_ref + our,
                   gw * speed + ow, theta_enc, w_enc, theta_enc / self._conv]

    def step(self, n: int) -> None:
        self._measure()

    def get_outputs(self) -> list[float]:
        return self._y

    def report(self) -> dict:
        return {"channels": self._params, "encoder_resolution_rad": self._q,
                "encoder_speed_window_s": self._window * self._h}
