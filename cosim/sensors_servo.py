"""The sensors of a servo drive (PMSM): phase currents, voltages in the dq frame, motor encoder and linear scale.

The servo counterpart of ``cosim.sensors`` (the DC drive's redundant sensors), with the same sensor model
(paper eq. 9, ``measured = gain * true + offset + noise * z``) and channel settings (``ChannelConfig``: gain,
offset, noise, and the sampling of each analogue channel)::

    channel        true signal                                   default noise (std)
    I_U I_V I_W    phase currents of i_d, i_q at phi_el = p theta  0.05 A (``CurrentSensor``)
    I_2            a second sensor on phase ``second_sensor_on``   0.05 A (material redundancy)
    u_d_ref u_q_ref  the regulator's voltage references            0.2 V (``VoltageSensor``)
    u_d u_q        the terminal voltages (measured or observed)     0.2 V
    encoder        motor angle, 4 x ``lines`` counts per turn       quantisation (``EncoderConfig``)
    scale          table position on a linear scale                quantisation to ``resolution`` [m] + noise

The phase currents come from the dq currents by the inverse amplitude-invariant Park/Clarke transform
(``estimator.redundancy_servo.inverse_park``): they sum to zero (the analytical redundancy), and the
second sensor on one phase is the paper's material redundancy. The lost motion between the motor and the
table lives in the plant (the vendor PMSM's ``lost_motion_mm``), not here: the encoder sees the motor
side, the linear scale the table.

Sampling, as the DC sensors' (``cosim.sensors``): with ``oversample`` m > 1 plant steps per recorded sample (the
scenario's ``plant.oversample``, set by the scenario), each analogue channel's ``sampling`` is ``instant`` (the
true signal at the recording instant), ``mean`` (the interval mean of the m sub-samples by
``sensors.interval_mean_weights``: an integrating ADC; the default, as the DC sensors') or ``lowpass`` (a
Butterworth anti-aliasing filter at the plant's step, sampled at the recording instant). The phase currents
are averaged as phase currents (what a phase's ADC integrates), not as dq values. The encoder and the linear
scale are counters latched at the recording instant. The component then steps at the plant's rate
(``fine_rate``); with m = 1, or every channel ``instant``, at the recording rate.

``measure_servo`` measures whole arrays of instantaneous samples (offline studies, benchmarks); ``ServoSensors`` is the same as a
co-simulation component (``class: feeddrive.cosim.sensors_servo:ServoSensors``) whose inputs are connected
to the plant's outputs; ``config.scales`` converts a plant's units on the way in (an rms current x sqrt(2),
mm -> m, an electrical angle / p).
"""
from __future__ import annotations

import math
import zlib
from collections.abc import Mapping, Sequence
from typing import Literal

import numpy as np
from pydantic import Field

from feeddrive.cosim.component import Component
from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.nc import StrictConfig, drive_chain_nominal
from feeddrive.cosim.sensors import (
    BLOCK,
    CurrentSensor,
    EncoderConfig,
    VoltageSensor,
    antialias_sos,
    interval_mean_weights,
    parse_event,
)
from feeddrive.estimator.redundancy_servo import PHASES, inverse_park

#: the component's inputs (SI, peak dq currents, mechanical motor angle, table position)
INPUTS = ("i_d", "i_q", "theta", "u_d_ref", "u_q_ref", "u_d", "u_q", "x_table")
INPUT_UNITS = ("A", "A", "rad", "V", "V", "V", "V", "m")
#: with ``phase_currents: measured``, the plant's own phase currents U, V, W (a vendor FMU's I_U, I_V, I_W outputs)
PHASE_INPUTS = ("i_u", "i_v", "i_w")
OUTPUTS = ("I_U", "I_V", "I_W", "I_2", "u_d_ref", "u_q_ref", "u_d", "u_q", "theta_enc", "x_mot", "x_lin")
OUTPUT_UNITS = ("A", "A", "A", "A", "V", "V", "V", "V", "rad", "m", "m")
_FIELDS = ("gain", "offset", "noise")
_SIN120 = math.sqrt(3.0) / 2


class LinearScale(StrictConfig):
    """A linear scale on the table: ``gain`` [1], ``offset`` [m], ``noise`` [m] (interpolation error), read to
    ``resolution`` [m] (0.1 um: a sealed glass scale with interpolation electronics)."""

    resolution: float = Field(1.0e-7, gt=0)
    gain: float = 1.0
    offset: float = 0.0
    noise: float = Field(2.0e-7, ge=0)


class ServoSensorsConfig(StrictConfig):
    """The servo drive's sensors; every key optional.

    Attributes
    ----------
    seed : int
        Seed of the noise (one generator per channel, from the seed and the channel name).
    pole_pairs : int
        ``p``: the electrical angle is ``p theta``.
    phases : (CurrentSensor, CurrentSensor, CurrentSensor)
        Phase current sensors U, V, W.
    second_sensor_on : {"U", "V", "W"} or None
        The phase with a second current sensor (output ``I_2``; None: no second sensor, ``I_2`` repeats ``I_U``).
    second : CurrentSensor
    voltage_ref, voltage : VoltageSensor
        Channels of the dq voltage references and of the terminal voltages (the same settings for d and q).
    encoder : EncoderConfig
        The motor encoder (``lines``, ``pitch`` and ``belt_ratio`` give ``x_mot`` [m]; default: the built-in
        PMSM's 10 mm screw, direct drive).
    scale : LinearScale
    scales : dict
        Input name -> factor applied to the connected value (a plant's units: 1.4142 for an rms current,
        0.001 for mm, 1/p for an electrical angle); unknown names are refused.
    phase_currents : {"dq", "measured"}
        ``dq`` (default): the phase channels measure the inverse Park transform of the inputs ``i_d, i_q`` (a plant
        that gives only its dq currents); ``measured``: they measure the plant's own phase currents, the extra
        inputs ``i_u, i_v, i_w``. A vendor FMU that has them should be wired so: its i_q mapped without the rms
        factor (x 0.707) then disagrees with Park(phase currents) (``dq_current_consistency``), where phases made
        from that same i_q agreed with it and the monitor validated R +41 %, L_q +41 %, Jt -29 %.
    oversample : int
        Plant steps per recorded sample (the scenario sets it to ``plant.oversample``): the sub-samples of the
        ``mean`` and ``lowpass`` sampling.
    """

    seed: int = Field(0, ge=0, strict=True)  # strict: a YAML `true` is not seed 1
    pole_pairs: int = Field(4, ge=1)
    phases: tuple[CurrentSensor, CurrentSensor, CurrentSensor] = (CurrentSensor(), CurrentSensor(), CurrentSensor())
    second_sensor_on: Literal["U", "V", "W"] | None = "U"
    second: CurrentSensor = CurrentSensor()
    voltage_ref: VoltageSensor = VoltageSensor()
    voltage: VoltageSensor = VoltageSensor()
    encoder: EncoderConfig = Field(default_factory=lambda: EncoderConfig(
        pitch=drive_chain_nominal("builtin-pmsm")[0], belt_ratio=drive_chain_nominal("builtin-pmsm")[1]))
    scale: LinearScale = LinearScale()
    scales: dict[Literal[INPUTS + PHASE_INPUTS], float] = {}  # type: ignore[valid-type]
    phase_currents: Literal["dq", "measured"] = "dq"
    oversample: int = Field(1, ge=1)

    def channels(self) -> dict[str, object]:
        """Event name -> channel configuration."""
        u, v, w = self.phases
        return {"I_U": u, "I_V": v, "I_W": w, "I_2": self.second, "u_d_ref": self.voltage_ref,
                "u_q_ref": self.voltage_ref, "u_d": self.voltage, "u_q": self.voltage, "encoder": self.encoder,
                "scale": self.scale}


def _noise(seed: int, channel: str, n: int) -> np.ndarray:
    return np.random.default_rng([seed, zlib.crc32(channel.encode())]).standard_normal(n)


def measure_servo(true: Mapping[str, np.ndarray], config: ServoSensorsConfig | dict | None = None,
                  params: Mapping[str, Mapping[str, float]] | None = None,
                  z: Mapping[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """Measure whole arrays of true signals with the servo sensors.

    Parameters
    ----------
    true : mapping of str to ndarray, shape (n,)
        ``i_d, i_q`` [A, peak], ``theta`` [rad, motor], ``u_d_ref, u_q_ref, u_d, u_q`` [V], ``x_table`` [m]
        (already in these units: ``config.scales`` is the component's, not applied here).
    config : ServoSensorsConfig or dict or None
    params : mapping, optional
        Channel -> ``{gain, offset, noise}`` overriding the configuration (a fault), as the component's events.
    z : mapping, optional
        Channel -> standard normal draws, shape (n,); default: drawn from ``config.seed`` and the channel name.

    Returns
    -------
    dict of str to ndarray, shape (n,)
        ``OUTPUTS``: ``I_U, I_V, I_W, I_2`` [A], the four voltages [V], ``theta_enc`` [rad], ``x_mot`` and
        ``x_lin`` [m].
    """
    cfg = ServoSensorsConfig.parse(config, "sensors_servo")
    z = z or {c: _noise(cfg.seed, c, np.size(true.get("i_d", 0.0))) for c in cfg.channels()}
    missing = [k for k in INPUTS if k not in true]
    if missing:
        raise ScenarioError(f"measure_servo: missing true signals {', '.join(missing)}; expected {', '.join(INPUTS)}")
    x = {k: np.asarray(true[k], dtype=float) for k in INPUTS}
    p = _params(cfg)
    for channel, fields in (params or {}).items():  # a fault: some fields of some channels
        p[channel] = p[channel] | dict(fields)
    phi = cfg.pole_pairs * x["theta"]
    abc = inverse_park(x["i_d"], x["i_q"], phi)
    raw = dict(zip(PHASES, abc))
    second = raw[cfg.second_sensor_on] if cfg.second_sensor_on else raw["U"]
    sources = {"I_U": raw["U"], "I_V": raw["V"], "I_W": raw["W"], "I_2": second, "u_d_ref": x["u_d_ref"],
               "u_q_ref": x["u_q_ref"], "u_d": x["u_d"], "u_q": x["u_q"]}
    out = {c: p[c]["gain"] * s + p[c]["offset"] + p[c]["noise"] * z[c] for c, s in sources.items()}
    if cfg.second_sensor_on is None:
        out["I_2"] = out["I_U"]
    enc, sc = cfg.encoder, cfg.scale
    q = 2 * math.pi / (4 * enc.lines)
    pe = p["encoder"]
    angle = pe["gain"] * x["theta"] + pe["offset"] + pe["noise"] * z["encoder"]
    out["theta_enc"] = q * np.floor(angle / q + 0.5)
    out["x_mot"] = out["theta_enc"] / (2 * math.pi * enc.belt_ratio) * enc.pitch
    ps = p["scale"]
    pos = ps["gain"] * x["x_table"] + ps["offset"] + ps["noise"] * z["scale"]
    out["x_lin"] = sc.resolution * np.floor(pos / sc.resolution + 0.5)
    return out


def _params(cfg: ServoSensorsConfig) -> dict[str, dict[str, float]]:
    return {c: {f: float(getattr(ch, f)) for f in _FIELDS} for c, ch in cfg.channels().items()}


class ServoSensors(Component):
    """``measure_servo`` sample by sample in a co-simulation, each analogue channel sampled as its ``sampling`` says
    (module docstring; at the plant's rate when ``fine_rate``, else instantaneous at the recording step).

    Inputs ``INPUTS`` (each multiplied by ``config.scales.get(name, 1)``), outputs ``OUTPUTS``. Events
    ``<channel>.<gain|offset|noise>`` with the channels of ``ServoSensorsConfig.channels`` change a
    channel from the next sample on.
    """

    input_names = INPUTS
    output_names = OUTPUTS
    output_units = OUTPUT_UNITS

    def __init__(self, name: str, config: ServoSensorsConfig | dict | None = None) -> None:
        super().__init__(name, ServoSensorsConfig.parse(config, name))
        cfg = self.config
        channels = cfg.channels()
        #: per analogue channel (``OUTPUTS[:8]``): 0 instant, 1 interval mean, 2 low-pass filtered
        self._kinds = tuple({"instant": 0, "mean": 1, "lowpass": 2}[channels[c].sampling] for c in OUTPUTS[:8])
        #: the master steps the component at the plant's rate (every sub-sample), not at the recording rate
        self.fine_rate = cfg.oversample > 1 and any(self._kinds)
        self._measured = cfg.phase_currents == "measured"
        if self._measured:  # the plant's own phase currents (not the compiled loop's: cosim/fastloop/servo.py)
            self.input_names = INPUTS + PHASE_INPUTS

    def setup(self, t0: float, h: float, n_steps: int) -> None:
        self._params = _params(self.config)
        self._scales = tuple(self.config.scales.get(k, 1.0) for k in self.input_names)
        self._inputs: Sequence[float] = (0.0,) * len(self.input_names)
        cfg = self.config
        self._rngs = {c: np.random.default_rng([cfg.seed, zlib.crc32(c.encode())]) for c in cfg.channels()}
        self._p, self._second = cfg.pole_pairs, PHASES.index(cfg.second_sensor_on or "U")
        self._q = 2 * math.pi / (4 * cfg.encoder.lines)
        self._conv = cfg.encoder.pitch / (2 * math.pi * cfg.encoder.belt_ratio)
        self._k = BLOCK
        self._m = cfg.oversample if self.fine_rate else 1
        self._acc = [0.0] * 8
        self._weights = interval_mean_weights(self._m)
        self._averaged = tuple(j for j, k in enumerate(self._kinds) if k == 1)  # the interval-mean channels
        self._lp = [0.0] * 8
        self._filters = []
        for j, c in enumerate(OUTPUTS[:8]):
            chan = cfg.channels()[c]
            if self.fine_rate and chan.sampling == "lowpass":
                fc = chan.cutoff_hz or 0.25 / (h * self._m)
                if not fc < 0.45 / h:
                    raise ScenarioError(f"{self.name}: {c}: lowpass cutoff_hz {fc:g} Hz must be below 0.9 x the "
                                        f"Nyquist frequency of the plant's step ({0.45 / h:g} Hz)")
                sos = antialias_sos(chan.order, fc, h)
                self._filters.append((j, [(b0, b1, b2, a1, a2) for b0, b1, b2, _, a1, a2 in sos.tolist()],
                                      [[0.0, 0.0] for _ in sos]))
        self._sample()

    def set_parameter(self, name: str, value: object) -> None:
        channel, field, v = parse_event(self.name, name, value, tuple(self._params))
        self._params[channel][field] = v

    def set_inputs(self, values: Sequence[float]) -> None:
        self._inputs = values

    def _sample(self) -> None:
        """``measure_servo`` on one sample, written with scalars (the master's loop calls it every step)."""
        if self._k == BLOCK:
            self._new_block()
        if self._z is None:
            self._z = self._zarr.tolist()
        z = self._z[self._k]
        self._k += 1
        true, theta, x_table = self._true()
        if self.fine_rate:  # each channel's sample: instantaneous, its interval mean or its filter's output
            acc, lp, inv_m = self._acc, self._lp, 1.0 / self._m
            true = [x if k == 0 else acc[j] * inv_m if k == 1 else lp[j]
                    for j, (k, x) in enumerate(zip(self._kinds, true))]
            self._acc = [0.0] * 8
        p = self._params
        y = [p[c]["gain"] * x + p[c]["offset"] + p[c]["noise"] * zc for c, x, zc in zip(OUTPUTS[:8], true, z)]
        if self.config.second_sensor_on is None:
            y[3] = y[0]
        pe, ps, q, res = p["encoder"], p["scale"], self._q, self.config.scale.resolution
        theta_enc = q * math.floor((pe["gain"] * theta + pe["offset"] + pe["noise"] * z[8]) / q + 0.5)
        x_lin = res * math.floor((ps["gain"] * x_table + ps["offset"] + ps["noise"] * z[9]) / res + 0.5)
        self._y = [*y, theta_enc, theta_enc * self._conv, x_lin]

    def _new_block(self) -> None:
        """Noise drawn in blocks, one draw per channel and sample: ``_zarr`` (BLOCK, 10), which the compiled
        fine loop reads (cosim/fastloop/servo.py)."""
        self._zarr = np.column_stack([rng.standard_normal(BLOCK) for rng in self._rngs.values()])
        self._z = None  # its rows as lists, made on first use by the Python loop
        self._k = 0

    def _true(self) -> tuple[list[float], float, float]:
        """The analogue channels' true values at this instant (``OUTPUTS[:8]``), the motor angle and the table."""
        i_d, i_q, theta, u_d_ref, u_q_ref, u_d, u_q, x_table, *phases = (v * s for v, s in zip(self._inputs,
                                                                                                 self._scales))
        phi = self._p * theta
        raw = phases if self._measured else [i_d * math.cos(phi - a) - i_q * math.sin(phi - a)
                                              for a in (0.0, 2 * math.pi / 3, 4 * math.pi / 3)]
        return [*raw, raw[self._second], u_d_ref, u_q_ref, u_d, u_q], theta, x_table

    def _fine(self) -> list[float]:
        """``_true``'s analogue channels, written for the plant-rate loop: one cos and one sin per step
        (``cos(phi - a) = cos phi cos a + sin phi sin a``), the scales unpacked."""
        v, s = self._inputs, self._scales
        if self._measured:
            raw = (v[8] * s[8], v[9] * s[9], v[10] * s[10])
            return [raw[0], raw[1], raw[2], raw[self._second], v[3] * s[3], v[4] * s[4], v[5] * s[5], v[6] * s[6]]
        i_d, i_q = v[0] * s[0], v[1] * s[1]
        phi = self._p * v[2] * s[2]
        c, sn = math.cos(phi), math.sin(phi)
        a, b = i_d * c - i_q * sn, i_d * sn + i_q * c  # phase U; and the quadrature term
        raw = (a, -0.5 * a + _SIN120 * b, -0.5 * a - _SIN120 * b)  # U, V (a = 120 deg), W (240 deg)
        return [raw[0], raw[1], raw[2], raw[self._second], v[3] * s[3], v[4] * s[4], v[5] * s[5], v[6] * s[6]]

    def step(self, n: int) -> None:
        if self.fine_rate:  # every plant step: the sub-sample into the sums and the filters
            x = self._fine()
            w = self._weights[n % self._m]
            acc = self._acc
            for j in self._averaged:
                acc[j] += w * x[j]
            for j, coefs, states in self._filters:  # direct form II transposed, per second-order section
                v = x[j]
                for (b0, b1, b2, a1, a2), st in zip(coefs, states):
                    y = b0 * v + st[0]
                    st[0] = b1 * v - a1 * y + st[1]
                    st[1] = b2 * v - a2 * y
                    v = y
                self._lp[j] = v
            if (n + 1) % self._m:
                return
        self._sample()

    def get_outputs(self) -> list[float]:
        return self._y

    def report(self) -> dict:
        return {"channels": self._params, "pole_pairs": self.config.pole_pairs,
                "second_sensor_on": self.config.second_sensor_on, "oversample": self._m,
                "sampling": {c: ("instant", "mean", "lowpass")[k] for c, k in zip(OUTPUTS[:8], self._kinds)}}
