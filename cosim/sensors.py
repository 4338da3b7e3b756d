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

Acquisition chain. The plant and the sensors step ``oversample`` times per recording step (the
scenario's ``plant.oversample``); each analogue channel hands the monitor one sample per recording
step, taken as its ``sampling`` says:

- ``instant``: the true signal at the recording instant t_(n+1) (a sample-and-hold ADC);
- ``mean`` (default): the mean over the recording interval (an integrating ADC, or a drive's per-cycle
  averaged voltage), from the m sub-samples at t_n + j h/m, j = 1..m, by the quadrature of
  ``interval_mean_weights`` (with ``interface: me`` the plant integrates its exact means over each of
  its steps with the states, and the sensors sum them); with ``oversample: 1`` it is the instantaneous
  sample, so the default changes nothing there;
- ``lowpass``: a Butterworth anti-aliasing filter of ``order`` and ``cutoff_hz`` (default a quarter
  of the recording rate) run at the plant's step, sampled at t_(n+1).

Gain, offset and noise act on the sample (noise: one draw per recorded sample). The encoder stays a
counter latched at the recording instant.

Noise is drawn from one ``numpy.random.Generator`` per channel, seeded from ``seed`` and the channel
name, in blocks of ``BLOCK`` steps; the output is the same for the same seed whatever the noise
levels. Faults change a channel's ``gain``, ``offset`` or ``noise`` during a run through events
``sensors.<channel>.<field>`` (channels ``Im1``, ``Im2``, ``u``, ``u_ref``, ``w_tach``, ``encoder``).
"""
from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator

from feeddrive.cosim.component import Component
from feeddrive.cosim.errors import ScenarioError, SimulationError
from feeddrive.cosim.nc import StrictConfig, drive_chain_nominal

#: noise samples drawn at once per channel
BLOCK = 4096


class ChannelConfig(StrictConfig):
    """One analogue channel: ``gain`` [1], ``offset`` and ``noise`` (std, >= 0) in the signal's unit, and how
    it is sampled: ``sampling`` (instant, mean, lowpass), with ``order`` and ``cutoff_hz`` [Hz] of the
    ``lowpass`` anti-aliasing filter (default cut-off: a quarter of the recording rate)."""

    gain: float = 1.0
    offset: float = 0.0
    noise: float = Field(0.0, ge=0)
    sampling: Literal["instant", "mean", "lowpass"] = "mean"
    order: int = Field(2, ge=1, le=8)
    cutoff_hz: float | None = Field(None, gt=0)

    @model_validator(mode="after")
    def _filter_only_for_lowpass(self) -> ChannelConfig:
        if self.sampling != "lowpass" and self.cutoff_hz is not None:
            raise ValueError(f"cutoff_hz is the lowpass filter's; sampling is {self.sampling!r}, expected lowpass")
        return self


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

    seed: int = Field(0, ge=0, strict=True)  # strict: a YAML `true` is not seed 1
    current: tuple[CurrentSensor, CurrentSensor] = (CurrentSensor(), CurrentSensor())
    voltage: VoltageSensor = VoltageSensor()
    voltage_ref: VoltageSensor = VoltageSensor()
    tachometer: Tachometer = Tachometer()
    encoder: EncoderConfig = Field(default_factory=EncoderConfig)

    def channels(self) -> dict[str, ChannelConfig | EncoderConfig]:
        """Event name -> configuration, in the order of the true signals they measure."""
        return {"Im1": self.current[0], "Im2": self.current[1], "u": self.voltage,
                "u_ref": self.voltage_ref, "w_tach": self.tachometer, "encoder": self.encoder}


#: the channel fields that events can change
_FIELDS = ("gain", "offset", "noise")
EVENT_FIELDS = _FIELDS
#: index of each analogue channel's true signal in the sensors' inputs
_SOURCE = {"Im1": 2, "Im2": 2, "u": 0, "u_ref": 1, "w_tach": 3}


def parse_event(component: str, name: str, value: Any, channels: Sequence[str]) -> tuple[str, str, float]:
    """``(channel, field, value)`` of a sensor event ``<channel>.<gain|offset|noise>``; a ScenarioError otherwise."""
    channel, _, field = name.partition(".")
    if channel not in channels or field not in _FIELDS:
        raise ScenarioError(f"{component}.{name}: expected <channel>.<field> with channel in "
                            f"{', '.join(channels)} and field in {', '.join(_FIELDS)}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ScenarioError(f"{component}.{name}: expected a number, got {value!r}") from None
    if not math.isfinite(v) or (field == "noise" and v < 0):
        raise ScenarioError(f"{component}.{name}: expected a finite number{' >= 0' * (field == 'noise')}, "
                            f"got {value!r}")
    return channel, field, v


def interval_mean_weights(m: int) -> tuple[float, ...]:
    """Quadrature weights (summing to m) of the m sub-samples y(t_n + j h/m), j = 1..m, for the interval mean.

    A plant holding its inputs jumps at t_n when they change, so the sample before t_n does not belong to
    the interval: its start value y(t_n+) is extrapolated from the first four sub-samples (exact for cubics),
    then Gregory's trapezoidal rule with end corrections up to third differences integrates the m + 1 values
    (m >= 5); for m <= 4 the weights integrate the polynomial through the m sub-samples exactly. On a jump
    relaxing with the 1 kHz current loop's time constant this is ~100 times closer to the exact mean than
    the trapezoidal rule at m = 10; the plain mean of the sub-samples is off by about the instantaneous
    sample's error divided by m (it weighs the jump as if it came h/m late).
    """
    if m <= 4:  # the polynomial of degree m - 1 through the sub-samples, integrated over [0, m]
        nodes = np.arange(1.0, m + 1)
        degrees = np.arange(m)
        return tuple(np.linalg.solve(nodes[None, :] ** degrees[:, None], m ** (degrees + 1.0) / (degrees + 1)))
    weights = np.zeros(m)
    for j in range(m):  # the rule is linear in the samples: apply it to each unit vector
        e = np.zeros(m)
        e[j] = 1.0
        y = np.concatenate([[4 * e[0] - 6 * e[1] + 4 * e[2] - e[3]], e])
        trapezoid = 0.5 * y[0] + y[1:-1].sum() + 0.5 * y[-1]
        d = [np.diff(y[:4], k)[0] for k in (1, 2, 3)]  # forward differences at the start
        b = [np.diff(y[-4:], k)[-1] for k in (1, 2, 3)]  # backward differences at the end
        weights[j] = trapezoid - (b[0] - d[0]) / 12 - (b[1] + d[1]) / 24 - 19 / 720 * (b[2] - d[2])
    return tuple(weights)


def antialias_sos(order: int, cutoff_hz: float, h: float) -> np.ndarray:
    """Second-order sections of a Butterworth low-pass of ``order`` and ``cutoff_hz`` [Hz] run every ``h`` [s].

    The analog prototype is discretised by the bilinear transform pre-warped at the cut-off (scipy's
    digital ``butter``): at the plant's fine step the difference to the analog filter is negligible.
    """
    from feeddrive.estimator.lti import butter_sos  # scipy.signal's butter, without its ~1 s of imports

    return butter_sos(order, cutoff_hz, 1.0 / h)


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

    def __init__(self, name: str, config: SensorsConfig | dict | None = None, oversample: int = 1,
                 exact_means: bool = False) -> None:
        super().__init__(name, SensorsConfig.parse(config, name))
        #: the plant also gives the exact mean of each signal over its step (Model Exchange): inputs
        #: ``<signal>_mean`` after the instantaneous ones, summed for ``mean`` instead of the quadrature
        self.exact_means = bool(exact_means)
        if self.exact_means:
            self.input_names = SensorsComponent.input_names + tuple(f"{n}_mean" for n in SensorsComponent.input_names[:4])
        if int(oversample) != oversample or oversample < 1:
            raise ScenarioError(f"{name}: oversample must be an integer >= 1, got {oversample!r}")
        #: sensor steps (plant steps) per recorded sample
        self.oversample = int(oversample)

    def setup(self, t0: float, h: float, n_steps: int) -> None:
        if not h > 0:
            raise ScenarioError(f"{self.name}: step must be > 0, got {h!r}")
        cfg = self.config
        channels = cfg.channels()
        self._names = tuple(channels)
        self._params = {c: {f: float(getattr(channels[c], f)) for f in _FIELDS} for c in self._names}
        self._rngs = [np.random.default_rng([cfg.seed, zlib.crc32(c.encode())]) for c in self._names]
        enc = cfg.encoder
        m = self.oversample
        self._q = 2 * math.pi / (4 * enc.lines)
        self._conv = 2 * math.pi * enc.belt_ratio / enc.pitch
        h_rec = h * m  # the encoder's speed window counts recorded samples
        self._t0, self._h, self._window = t0, h_rec, max(1, round(enc.speed_window / h_rec))
        self._inv_wh = 1.0 / (self._window * h_rec)
        self._setup_chain(channels, h)
        self._inputs: Sequence[float] = (0.0,) * len(self.input_names)
        self._buffer: list[float] | None = None
        self._j = 0
        self._new_block()
        self._measure(self._inputs)
        self._buffer, self._j = None, 0  # the speed window starts at the first plant sample, not at t0

    def _setup_chain(self, channels: dict, h: float) -> None:
        """Sampling of each analogue channel: sums of the sub-samples and the anti-aliasing filters."""
        m = self.oversample
        self._sampling = {c: channels[c].sampling for c in _SOURCE}
        # the mean of one sub-sample is the instantaneous sample: no sums needed
        self._mean = m > 1 and "mean" in self._sampling.values()
        self._acc = [0.0] * 4
        self._inv_m = 1.0 / m
        self._weights = interval_mean_weights(m)
        self._filters: list[tuple[int, int, list[tuple[float, ...]], list[list[float]]]] = []
        self._cutoffs: dict[str, float] = {}
        for j, c in enumerate(_SOURCE):
            cfg = channels[c]
            if cfg.sampling != "lowpass":
                continue
            fc = cfg.cutoff_hz or 0.25 / (h * m)
            if not fc < 0.45 / h:
                raise ScenarioError(f"{self.name}: {c}: lowpass cutoff_hz {fc:g} Hz must be below 0.9 x the Nyquist "
                                    f"frequency of the plant's step ({0.45 / h:g} Hz)")
            self._cutoffs[c] = fc
            sos = antialias_sos(cfg.order, fc, h)
            coefs = [(b0, b1, b2, a1, a2) for b0, b1, b2, _, a1, a2 in sos.tolist()]
            self._filters.append((j, _SOURCE[c], coefs, [[0.0, 0.0] for _ in coefs]))
        self._lp = [0.0] * 5
        # per channel: where its sample comes from (0 instant, 1 mean, 2 lowpass output)
        kind = {"instant": 0, "mean": 1 if m > 1 else 0, "lowpass": 2}
        self._kinds = tuple(kind[self._sampling[c]] for c in _SOURCE)

    def _new_block(self) -> None:
        self._z = np.column_stack([rng.standard_normal(BLOCK) for rng in self._rngs])
        self._k = 0
        self._refresh()

    def _refresh(self) -> None:
        """Precompute ``offset + noise z`` over the block and unpack the gains."""
        p = [self._params[c] for c in self._names]
        offsets = np.array([q["offset"] for q in p])
        noise = np.array([q["noise"] for q in p])
        self._noise = offsets + noise * self._z  # shape (BLOCK, 6): read as it is by the compiled fine loop
        self._rows = None  # its rows as lists, made on first use by the Python loop
        self._gains = tuple(q["gain"] for q in p)

    def set_parameter(self, name: str, value: Any) -> None:
        """Change ``<channel>.<gain|offset|noise>`` from the next output on (a sensor fault)."""
        channel, field, v = parse_event(self.name, name, value, tuple(self._params))
        self._params[channel][field] = v
        self._refresh()

    def set_inputs(self, values: Sequence[float]) -> None:
        self._inputs = values

    def _measure(self, true: Sequence[float]) -> None:
        """Outputs from the true signals at the sample instant and the next noise row."""
        if self._k == BLOCK:
            self._new_block()
        rows = self._rows
        if rows is None:
            rows = self._rows = self._noise.tolist()
        o1, o2, ou, our, ow, oe = rows[self._k]
        self._k += 1
        g1, g2, gu, gur, gw, ge = self._gains
        position = true[4]
        kinds = self._kinds
        if any(kinds):  # some channel is a mean or filtered: pick each channel's value
            acc, inv_m, lp = self._acc, self._inv_m, self._lp
            x = [true[s] if k == 0 else acc[s] * inv_m if k == 1 else lp[j]
                 for j, (k, s) in enumerate(zip(kinds, _SOURCE.values()))]
            acc[0] = acc[1] = acc[2] = acc[3] = 0.0
            i1, i2, voltage, voltage_ref, speed = x
        else:
            voltage, voltage_ref, i1, speed = true[:4]
            i2 = i1
        theta_enc = self._q * math.floor((ge * self._conv * position + oe) / self._q + 0.5)
        buffer = self._buffer
        if buffer is None:  # first plant sample: the axis is taken to have been at rest before
            buffer = self._buffer = [theta_enc] * self._window
        j = self._j
        w_enc = (theta_enc - buffer[j]) * self._inv_wh
        buffer[j] = theta_enc
        self._j = j + 1 if j + 1 < self._window else 0
        self._y = [g1 * i1 + o1, g2 * i2 + o2, gu * voltage + ou, gur * voltage_ref + our,
                   gw * speed + ow, theta_enc, w_enc, theta_enc / self._conv]

    def step(self, n: int) -> None:
        true = self._inputs
        if self._mean and self.exact_means:  # the plant's exact means over each of its steps
            acc = self._acc
            acc[0] += true[5]
            acc[1] += true[6]
            acc[2] += true[7]
            acc[3] += true[8]
        elif self._mean:
            acc, wt = self._acc, self._weights[n % self.oversample]
            acc[0] += wt * true[0]
            acc[1] += wt * true[1]
            acc[2] += wt * true[2]
            acc[3] += wt * true[3]
        for j, s, coefs, states in self._filters:  # direct form II transposed, per second-order section
            x = true[s]
            for (b0, b1, b2, a1, a2), z in zip(coefs, states):
                y = b0 * x + z[0]
                z[0] = b1 * x - a1 * y + z[1]
                z[1] = b2 * x - a2 * y
                x = y
            self._lp[j] = x
        if (n + 1) % self.oversample == 0:
            try:
                self._measure(true)
            except (OverflowError, ValueError):  # the encoder's count of an infinite or NaN position
                raise SimulationError(
                    f"{self.name}: the plant's position {true[4]:.4g} m cannot be counted by the encoder at "
                    f"t={self._t0 + (n + 1) * self._h / self.oversample:.6g} s: the plant diverged (it did not follow "
                    "the NC's speed reference: a plant that is not a feed drive, or a direction or unit of plant.map?)"
                ) from None

    def get_outputs(self) -> list[float]:
        return self._y

    def report(self) -> dict:
        return {"channels": self._params, "encoder_resolution_rad": self._q,
                "encoder_speed_window_s": self._window * self._h, "oversample": self.oversample,
                "sampling": self._sampling, "lowpass_cutoff_hz": self._cutoffs}
