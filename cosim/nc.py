"""NC trajectory generator: the program of moves, the planned trajectory and the position loop.

The NC turns a part program (rapid moves G0, feed moves G1, dwells, tool changes) into a planned
table trajectory made of exact constant-acceleration pieces (trapezoidal speed profiles, or
triangular ones when a move is too short to reach its maximum speed), and closes the position loop::

    speed_ref [rad/s] = (v_ff + kv (x_planned(t_n) - x_measured(t_n))) * 2 pi belt_ratio / pitch

``v_ff`` is the mean planned speed over the coming step, ``(x_planned(t_{n+1}) - x_planned(t_n)) / h``,
which is the planned speed at mid-step: an ideal speed-controlled axis then follows the plan exactly
at every grid point. The plan is precomputed; per step the NC evaluates one polynomial.

Signals for the monitor: ``state`` (0 idle, 1 rapid, 2 feed) and ``motion`` (index of the current
high-speed motion, 1 for the first; it increments at every grid point where ``state`` becomes 1 and
stays until the next one). A tool change (rapid out, dwell, rapid back) and an identification motion
(out and back) report state 1 throughout, so each is one high-speed motion. A feed move applies its
cutting ``load`` torque [N.m] to the plant with the sign that opposes the motion.

Identification request (paper section IV.B.1): on each rising edge of the ``request`` input the NC
inserts, at the next boundary between program items (or at once when the program has ended), the
``identification`` motion out by ``distance`` and back, and shifts the rest of the program later.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from functools import lru_cache
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_serializer, model_validator

from feeddrive.cosim.component import Component
from feeddrive.cosim.errors import ScenarioError

#: NC ``state`` codes
IDLE, RAPID, FEED = 0, 1, 2

#: the paper's bench: 70 rad/s with a 20 mm pitch is 0.22 m/s; ramps of 0.6 m/s^2
BENCH_V_MAX = 0.22
BENCH_ACCEL = 0.6

_MESSAGES = {
    "greater_than": "must be > {gt:g}",
    "greater_than_equal": "must be >= {ge:g}",
    "tuple_type": "expected a list",
    "missing": "required key is missing",
    "extra_forbidden": "unknown key",
}

#: margin added to the NC program's duration for the default stop time [s]
SETTLING = 0.3


class StrictConfig(BaseModel):
    """Base of the scenario sections: frozen, no unknown keys, no inf/NaN."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    @classmethod
    def parse(cls, data: Any, where: str) -> StrictConfig:
        """Validate a scenario section, raising a one-line ``ScenarioError`` naming the key.

        Parameters
        ----------
        data : dict or instance of ``cls`` or None
            The section as read from YAML (None means all defaults).
        where : str
            Key path of the section, e.g. ``"nc"``, used as the prefix of the message.
        """
        if isinstance(data, cls):
            return data
        try:
            return cls.model_validate({} if data is None else data)
        except ValidationError as exc:
            raise ScenarioError(describe_validation_error(exc, where)) from None


def describe_validation_error(exc: ValidationError, where: str) -> str:
    """First error of a pydantic ``ValidationError`` as ``"nc.program[2].rapid.accel: must be > 0"``."""
    errors = exc.errors()
    err = errors[0]
    path = where + "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in err["loc"])
    ctx = err.get("ctx") or {}
    if err["type"] == "value_error":
        text = str(ctx.get("error", err["msg"]))
    elif err["type"] in _MESSAGES:
        text = _MESSAGES[err["type"]].format(**ctx)
    else:
        text = f"{err['msg']} (got {err['input']!r})"
    more = f" (and {len(errors) - 1} more error(s))" if len(errors) > 1 else ""
    return f"{path}: {text}{more}"


@lru_cache(maxsize=4)
def drive_chain_nominal(plant: str = "builtin") -> tuple[float, float]:
    """``(pitch [m], belt_ratio [1])``: the design values of ``models.feed_drive()``, or of
    ``models.pmsm_drive()`` for ``plant = "builtin-pmsm"`` (a 10 mm screw)."""
    from feeddrive.models import feed_drive, pmsm_drive

    nominal = (pmsm_drive if plant == "builtin-pmsm" else feed_drive)().nominal(("design",))
    return nominal["pitch"], nominal["belt_ratio"]


class RapidMove(StrictConfig):
    """G0: trapezoidal speed profile to ``to`` [m] with ``v_max`` [m/s] and ``accel`` [m/s^2]."""

    to: float
    v_max: float = Field(BENCH_V_MAX, gt=0)
    accel: float = Field(BENCH_ACCEL, gt=0)


class FeedMove(StrictConfig):
    """G1: move to ``to`` [m] at ``feed`` [m/s] (ramped at ``nc.accel``) under a cutting ``load`` [N.m]."""

    to: float
    feed: float = Field(gt=0)
    load: float = Field(0.0, ge=0)


class Dwell(StrictConfig):
    """Stand still for ``time`` [s]."""

    time: float = Field(ge=0)


class ToolChange(StrictConfig):
    """Rapid to ``position`` [m], wait ``time`` [s], rapid back: one high-speed motion."""

    position: float
    v_max: float = Field(BENCH_V_MAX, gt=0)
    accel: float = Field(BENCH_ACCEL, gt=0)
    time: float = Field(ge=0)


class Identification(StrictConfig):
    """Identification motion: rapid out by ``distance`` [m] (signed) and back."""

    distance: float = 0.2
    v_max: float = Field(BENCH_V_MAX, gt=0)
    accel: float = Field(BENCH_ACCEL, gt=0)

    @field_validator("distance")
    @classmethod
    def _moves(cls, distance: float) -> float:
        if distance == 0:
            raise ValueError("must be non-zero (signed length of the out-and-back motion, m)")
        return distance


_KINDS = ("rapid", "feed", "dwell", "tool_change")
_EXAMPLE = {"rapid": "to: 0.4", "feed": "to: 0.45, feed: 0.01", "dwell": "time: 0.2", "tool_change": "position: 0.27"}


class ProgramItem(StrictConfig):
    """One program line: exactly one of ``rapid``, ``feed``, ``dwell``, ``tool_change``."""

    rapid: RapidMove | None = None
    feed: FeedMove | None = None
    dwell: Dwell | None = None
    tool_change: ToolChange | None = None

    @model_validator(mode="before")
    @classmethod
    def _one_kind(cls, data: Any) -> Any:
        if not isinstance(data, dict) or len(data) != 1 or next(iter(data)) not in _KINDS:
            got = list(data) if isinstance(data, dict) else repr(data)
            raise ValueError(f"expected a mapping with exactly one of {', '.join(_KINDS)}, got {got}")
        kind = next(iter(data))
        if data[kind] is None:  # `- dwell:` with nothing under it validated as no move at all (StopIteration later)
            raise ValueError(f"{kind}: expected its settings, e.g. {{{kind}: {{{_EXAMPLE[kind]}}}}}, got nothing")
        return data

    @model_serializer(mode="wrap")
    def _dump(self, handler: Any) -> dict:
        return {k: v for k, v in handler(self).items() if v is not None}  # the YAML shape round-trips

    @property
    def move(self) -> tuple[str, StrictConfig]:
        kind = next(k for k in _KINDS if getattr(self, k) is not None)
        return kind, getattr(self, kind)


class NCConfig(StrictConfig):
    """The ``nc:`` section of a scenario.

    Attributes
    ----------
    start : float
        Initial table position [m] (the plant must start there).
    kv : float
        Position-loop gain [1/s].
    feed_forward : bool
        Add the planned speed to the position loop's output.
    pitch, belt_ratio : float
        Drive chain used to convert table speed [m/s] to motor speed [rad/s]; default: the
        built-in model's design values.
    accel : float
        Acceleration of feed moves [m/s^2].
    identification : Identification
        The motion inserted on an identification request.
    program : tuple of ProgramItem
        The moves, in order.
    cycle : float or None
        Interpolation and position-loop cycle [s], an integer multiple of the plant's step
        (``step / plant.oversample``); default: the recording ``step``. Between cycles the outputs
        are held (the plant's ``input_hold`` decides whether it sees them held or ramped).
    """

    start: float = 0.0
    kv: float = Field(30.0, ge=0)
    feed_forward: bool = True
    pitch: float = Field(default_factory=lambda: drive_chain_nominal()[0], gt=0)
    belt_ratio: float = Field(default_factory=lambda: drive_chain_nominal()[1], gt=0)
    accel: float = Field(BENCH_ACCEL, gt=0)
    identification: Identification = Identification()
    program: tuple[ProgramItem, ...] = ()
    cycle: float | None = Field(None, gt=0)


# A segment is [t_start (s, relative to t0), x0 (m), v0 (m/s), a (m/s^2), state, load (N.m), item];
# it lasts until the next segment's t_start; the last one (item -1) is the idle end of the program,
# item -2 marks an inserted identification motion.
Segment = list


def _travel(x_from: float, x_to: float, v_max: float, accel: float, t: float, state: int, load: float,
            item: int) -> tuple[list[Segment], float]:
    """Segments of a trapezoidal (or triangular) move starting at rest at time ``t``; returns (segments, end)."""
    d = x_to - x_from
    if d == 0:
        return [], t
    s = math.copysign(1.0, d)
    v = min(v_max, math.sqrt(accel * abs(d)))  # triangular when the move is too short for v_max
    t_acc = v / accel
    d_acc = 0.5 * v * t_acc
    t_cruise = (abs(d) - 2 * d_acc) / v
    segments = [[t, x_from, 0.0, s * accel, state, load, item]]
    if t_cruise > 0:
        segments.append([t + t_acc, x_from + s * d_acc, s * v, 0.0, state, load, item])
    # the decelerating piece is written from the target so that every move ends exactly on it
    segments.append([t + t_acc + t_cruise, x_to - s * d_acc, s * v, -s * accel, state, load, item])
    return segments, t + 2 * t_acc + t_cruise


def _plan_item(kind: str, move: StrictConfig, x: float, t: float, item: int,
               feed_accel: float) -> tuple[list[Segment], float, float]:
    """Segments of one program item from position ``x`` at time ``t``; returns (segments, end time, end x)."""
    if kind == "rapid":
        segs, t_end = _travel(x, move.to, move.v_max, move.accel, t, RAPID, 0.0, item)
        return segs, t_end, move.to
    if kind == "feed":
        load = math.copysign(move.load, move.to - x)  # a load torque opposes the motion
        segs, t_end = _travel(x, move.to, move.feed, feed_accel, t, FEED, load, item)
        return segs, t_end, move.to
    if kind == "dwell":
        return [[t, x, 0.0, 0.0, IDLE, 0.0, item]], t + move.time, x
    out, t1 = _travel(x, move.position, move.v_max, move.accel, t, RAPID, 0.0, item)
    back, t2 = _travel(move.position, x, move.v_max, move.accel, t1 + move.time, RAPID, 0.0, item)
    stay = [[t1, move.position, 0.0, 0.0, RAPID, 0.0, item]] if move.time > 0 else []
    return out + stay + back, t2, x


def plan_program(config: NCConfig) -> list[Segment]:
    """The planned trajectory of a program, ending with the idle segment at the last position.

    Returns
    -------
    list of Segment
        ``[t_start, x0, v0, a, state, load, item]`` per constant-acceleration piece, times [s]
        relative to the start of the run; a piece lasts until the next one starts.
    """
    segments: list[Segment] = []
    t, x = 0.0, config.start
    for item, line in enumerate(config.program):
        kind, move = line.move
        segs, t_end, x = _plan_item(kind, move, x, t, item, config.accel)
        segments += [s for s in segs if s[0] < t_end]  # zero-length dwells leave nothing
        t = t_end
    segments.append([t, x, 0.0, 0.0, IDLE, 0.0, -1])
    return segments


class NCComponent(Component):
    """NC trajectory generator and position loop (see the module docstring).

    Inputs: ``position`` [m] (measured table position), ``request`` (1.0: identification wanted).
    Outputs: ``speed_ref`` [rad/s], ``load`` [N.m], ``x_ref`` [m], ``v_ref`` [m/s], ``a_ref`` [m/s^2],
    ``state`` (0 idle, 1 rapid, 2 feed), ``motion`` (index of the current high-speed motion).
    ``x_ref``, ``v_ref``, ``a_ref``, ``state``, ``motion`` and ``load`` are the plan at the output time
    (pieces are right-continuous: at a breakpoint the next piece holds); ``speed_ref`` at t_{n+1} is the
    command for [t_n, t_{n+1}].
    """

    input_names = ("position", "request")
    output_names = ("speed_ref", "load", "x_ref", "v_ref", "a_ref", "state", "motion")
    output_units = ("rad/s", "N.m", "m", "m/s", "m/s^2", "1", "1")

    def __init__(self, name: str, config: NCConfig | dict | None = None) -> None:
        config = NCConfig.parse(config, name)
        super().__init__(name, config)
        self._plan = plan_program(config)
        self._ident, self._ident_time = self._identification_segments(config.identification)

    @staticmethod
    def _identification_segments(ident: Identification) -> tuple[list[Segment], float]:
        """The identification motion from x = 0 at t = 0, shifted when inserted."""
        out, t1 = _travel(0.0, ident.distance, ident.v_max, ident.accel, 0.0, RAPID, 0.0, -2)
        back, t2 = _travel(ident.distance, 0.0, ident.v_max, ident.accel, t1, RAPID, 0.0, -2)
        return out + back, t2

    def duration(self) -> float:
        """Planned program length [s], without identification motions inserted on request."""
        return self._plan[-1][0]

    def setup(self, t0: float, h: float, n_steps: int) -> None:
        if not h > 0:
            raise ScenarioError(f"{self.name}: step must be > 0, got {h!r}")
        cfg = self.config
        self._h, self._inv_h, self._tol = h, 1.0 / h, 1e-9 * h
        self._conv = 2 * math.pi * cfg.belt_ratio / cfg.pitch
        self._kv, self._ff = cfg.kv, 1.0 if cfg.feed_forward else 0.0
        self._segs = [list(s) for s in self._plan]
        self._inserted: list[float] = []
        self._pending = self._request_high = False
        self._x_meas = self._x_prev = cfg.start
        self._t_now, self._state, self._motion = 0.0, IDLE, 0
        self._load_segment(0)
        self._y = [0.0, self._load, self._x0, self._v0, self._a, self._state, self._motion]

    def _load_segment(self, k: int) -> None:
        self._k = k
        seg = self._segs[k]
        self._ts, self._x0, self._v0, self._a, state, self._load = seg[:6]
        self._t_next = self._segs[k + 1][0] - self._tol if k + 1 < len(self._segs) else math.inf
        if state == RAPID and self._state != RAPID:
            self._motion += 1
        self._state = state

    def _advance(self, t: float) -> None:
        """Move to the piece that holds at relative time ``t``, inserting a pending identification."""
        segs, k = self._segs, self._k
        while k + 1 < len(segs) and t >= segs[k + 1][0] - self._tol:
            if self._pending and segs[k + 1][6] != segs[k][6]:
                self._insert(k + 1, segs[k + 1][0])
            k += 1
        self._load_segment(k)

    def _insert(self, j: int, t: float) -> None:
        """Insert the identification motion before piece ``j``, starting at rest at time ``t``."""
        segs = self._segs
        x = segs[j][1]
        ident = [[s[0] + t, s[1] + x] + s[2:] for s in self._ident]
        for s in segs[j:]:
            s[0] += self._ident_time
        segs[j:j] = ident
        self._pending = False
        self._inserted.append(t)

    def set_inputs(self, values: Sequence[float]) -> None:
        self._x_meas, request = values
        high = request >= 0.5
        if high and not self._request_high:
            self._pending = True
            if self._k == len(self._segs) - 1:  # program ended: identify at once, from t_n
                self._segs[-1][0] = self._t_now
                self._insert(self._k, self._t_now)
                self._load_segment(self._k)
        self._request_high = high

    def step(self, n: int) -> None:
        t = (n + 1) * self._h
        if t >= self._t_next:
            self._advance(t)
        tau = t - self._ts
        a, v0 = self._a, self._v0
        x = self._x0 + tau * (v0 + 0.5 * a * tau)
        x_prev = self._x_prev
        w = (self._ff * (x - x_prev) * self._inv_h + self._kv * (x_prev - self._x_meas)) * self._conv
        self._y = [w, self._load, x, v0 + a * tau, a, self._state, self._motion]
        self._x_prev, self._t_now = x, t

    def get_outputs(self) -> list[float]:
        return self._y

    def report(self) -> dict:
        return {"duration_s": self.duration(), "motions": self._motion,
                "identifications_inserted_s": list(self._inserted)}
