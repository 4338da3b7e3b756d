"""The one description of an axis's drive chain, and the units that follow from it.

A feed axis is a motor driving either a linear table through a ball screw (``kind: linear``, table
position in m) or a rotary table (``kind: rotary``, table angle in rad), possibly through a belt or
gear (``ratio``: motor turns per screw or table turn). The scenario states it once, in its ``axis:``
section; the NC (table -> motor speed), the encoder (table position -> motor angle), the monitor,
``report.json``, the history and the recorded-data commands all read it from there.

The parameters ``R, L, K, Jt, ft, Cd`` (and the offset ``T0``) are estimated on the *side* the data
are on. On the motor side the mechanical equation is ``K i = Jt dw/dt + ft w + Cd sign(w)`` with w in
rad/s, so Jt is in kg.m2, ft in N.m.s/rad and Cd in N.m. On the table side of a linear axis recorded
as position [m] and force [N], the same equation reads ``F = M dv/dt + Fv v + Fc sign(v)``: Jt is a
mass in kg, ft is in N.s/m and Cd in N. The JSON keys stay ``Jt, ft, Cd``; each value carries its
``unit``.
"""
from __future__ import annotations

import math
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from feeddrive.cosim.drive import Drive

Kind = Literal["linear", "rotary"]
Side = Literal["motor", "table"]

#: Units of the physical parameters on each side; K is N.m/A (= V.s/rad) on the motor side and N/A
#: (= V.s/m) on the table side of a linear axis.
_MOTOR_UNITS = {"R": "Ohm", "L": "H", "K": "N.m/A", "Jt": "kg.m2", "ft": "N.m.s/rad", "Cd": "N.m", "T0": "N.m"}
_LINEAR_TABLE_UNITS = {"R": "Ohm", "L": "H", "K": "N/A", "Jt": "kg", "ft": "N.s/m", "Cd": "N", "T0": "N"}
#: Units of the signal roles (position, speed, torque) on each side.
_MOTOR_SIGNALS = {"position": "rad", "speed": "rad/s", "torque": "N.m"}
_LINEAR_TABLE_SIGNALS = {"position": "m", "speed": "m/s", "torque": "N"}


def parameter_units(side: Side = "motor", kind: Kind = "rotary") -> dict[str, str]:
    """Unit of each physical parameter (``R, L, K, Jt, ft, Cd, T0``) estimated on ``side`` of a ``kind`` axis.

    A rotary table is described in rad on both sides, so only the table side of a linear axis differs.
    """
    return dict(_LINEAR_TABLE_UNITS if side == "table" and kind == "linear" else _MOTOR_UNITS)


def signal_units(side: Side = "motor", kind: Kind = "rotary") -> dict[str, str]:
    """Unit of the ``position``, ``speed`` and ``torque`` roles on ``side`` of a ``kind`` axis."""
    return dict(_LINEAR_TABLE_SIGNALS if side == "table" and kind == "linear" else _MOTOR_SIGNALS)


class Axis(BaseModel):
    """An axis: its name in the history and its drive chain.

    Attributes
    ----------
    name : str
        History key (``X``, ``Y``, ...). ``axis: X`` in a scenario is short for ``axis: {name: X}``.
    kind : {"linear", "rotary"}
        Linear table on a ball screw (table position in m) or rotary table (table angle in rad).
    pitch : float or None
        Ball-screw pitch, table travel per screw turn [m]; linear axes only. None: not stated here
        (the plant's value, or the built-in model's design value, is used).
    ratio : float or None
        Belt or gear ratio, motor turns per screw turn (linear) or per table turn (rotary) [1].
        None: not stated here.
    side : {"motor", "table"}
        Side of the drive chain the mechanical parameters are estimated on (the data's side).
    drive : Drive or None
        The motor and its drive (``{kind: dc | pmsm, pole_pairs}``, ``cosim.drive``); None: not stated.
    """

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    name: str = Field("X", min_length=1)
    kind: Kind = "linear"
    pitch: float | None = Field(None, gt=0, description="table travel per screw turn [m]")
    ratio: float | None = Field(None, gt=0, description="motor turns per screw (or table) turn [1]")
    side: Side = "motor"
    drive: Drive | None = None

    @model_validator(mode="before")
    @classmethod
    def _name_only(cls, data: object) -> object:
        """``axis: X`` (the old form, a name only) is ``axis: {name: X}``."""
        return {"name": data} if isinstance(data, str) else data

    @model_validator(mode="after")
    def _rotary_has_no_pitch(self) -> Axis:
        if self.kind == "rotary" and self.pitch is not None:
            raise ValueError("a rotary axis has no ball-screw pitch; expected no 'pitch' (or kind: linear)")
        return self

    def travel_per_motor_turn(self, pitch: float | None = None, ratio: float | None = None) -> float:
        """Table travel per motor turn [m for linear, rad for rotary], given defaults for unstated values."""
        p = self.pitch if self.pitch is not None else pitch
        r = self.ratio if self.ratio is not None else ratio
        if r is None or (self.kind == "linear" and p is None):
            raise ValueError(f"axis {self.name}: the drive chain is not fully stated (pitch {p}, ratio {r})")
        return (p if self.kind == "linear" else 2 * math.pi) / r

    def motor_rad_per_unit(self, pitch: float | None = None, ratio: float | None = None) -> float:
        """Motor angle per unit of table position [rad/m or rad/rad]: ``2 pi ratio / pitch`` or ``ratio``."""
        return 2 * math.pi / self.travel_per_motor_turn(pitch, ratio)

    def parameter_units(self, side: Side | None = None) -> dict[str, str]:
        """Units of the physical parameters on ``side`` (default: the axis's own ``side``)."""
        return parameter_units(side or self.side, self.kind)

    def signal_units(self, side: Side | None = None) -> dict[str, str]:
        """Units of the position, speed and torque roles on ``side`` (default: the axis's own ``side``)."""
        return signal_units(side or self.side, self.kind)

    @property
    def effective_pitch(self) -> float | None:
        """The pitch the NC and encoder formulas ``2 pi ratio / pitch`` need: 2 pi rad per turn for rotary."""
        return 2 * math.pi if self.kind == "rotary" else self.pitch


# -- the scenario's drive chain: stated once, copied to the NC, the encoder and the built-in plant ---------

#: Where a scenario may (still) state each drive-chain value, besides ``axis:``; the first of these that
#: is given is the value, any other one must agree with it.
_PLACES = {
    "pitch": (("axis", "pitch"), ("plant", "parameters", "pitch"), ("nc", "pitch"), ("sensors", "encoder", "pitch")),
    "ratio": (("axis", "ratio"), ("plant", "parameters", "belt_ratio"), ("nc", "belt_ratio"),
              ("sensors", "encoder", "belt_ratio")),
}


def _get(data: object, path: tuple) -> object:
    for key in path:
        if not isinstance(data, dict) or key not in data:
            return None
        data = data[key]
    return data


def _set(data: dict, path: tuple, value: object) -> None:
    for key in path[:-1]:
        sub = data.get(key)
        data[key] = sub = dict(sub) if isinstance(sub, dict) else {}
        data = sub
    data[path[-1]] = value


def resolve_drive_chain(data: dict, builtin: bool, nominal: tuple[float, float], error) -> dict:  # noqa: ANN001
    """The scenario data with the axis's drive chain stated once and copied where it is used.

    Parameters
    ----------
    data : dict
        The scenario as read from YAML (not modified).
    builtin : bool
        The plant is a built-in FMU: its ``pitch`` and ``belt_ratio`` parameters are part of the chain
        (taken from ``axis:`` when stated there, checked against it when stated in both places).
    nominal : (float, float)
        The built-in model's design ``(pitch [m], belt_ratio [1])``, used for values stated nowhere.
    error : callable
        ``error(key_path, message) -> ScenarioError`` (names the file and line).

    Returns
    -------
    dict
        A copy of ``data`` whose ``axis`` is a complete mapping (name, kind, pitch, ratio, side) and whose
        ``nc`` and ``sensors.encoder`` (and, for a built-in plant, ``plant.parameters``) hold the same
        drive chain. A rotary axis hands ``2 pi`` (rad per turn) to the NC's and encoder's pitch.

    Raises
    ------
    ScenarioError
        A malformed ``axis:`` section, or two places giving different values (both keys are named).
    """
    data = dict(data)
    axis = Axis.model_validate(data.get("axis", "X"))  # a pydantic error is located by the caller
    stated = {}
    for what, places in _PLACES.items():
        found = [(p, _get(data, p)) for p in places if (builtin or p[0] != "plant") and _get(data, p) is not None]
        for p, v in found:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
                raise error(p, f"expected a positive number [{'m' if what == 'pitch' else '1'}], got {v!r}")
        if axis.kind == "rotary" and what == "pitch":
            # 2 pi is what a resolved rotary scenario holds there (rad per turn): it reads back
            bad = [p for p, v in found if p[0] != "axis" and not math.isclose(float(v), 2 * math.pi, rel_tol=1e-12)]
            if bad:
                raise error(bad[0], f"{'.'.join(bad[0])} contradicts axis.kind = rotary (no ball screw); expected "
                                    "no pitch, or axis.kind: linear")
            continue
        for p, v in found[1:]:
            if not math.isclose(float(v), float(found[0][1]), rel_tol=1e-12):
                first = ".".join(found[0][0])
                raise error(p, f"{'.'.join(p)} = {v:g} contradicts {first} = {found[0][1]:g}; state the drive "
                               f"chain once, in axis.{what}")
        if found:
            stated[what] = float(found[0][1])
    pitch = stated.get("pitch", nominal[0]) if axis.kind == "linear" else None
    ratio = stated.get("ratio", nominal[1])
    axis = axis.model_copy(update={"pitch": pitch, "ratio": ratio})
    data["axis"] = axis.model_dump()
    chain = {"pitch": axis.effective_pitch, "belt_ratio": ratio}
    # a missing ``nc`` stays missing (the loader names it); the other sections are optional
    targets = [("nc",)] * isinstance(data.get("nc"), dict) + [("sensors", "encoder")]
    # the built-in plant's x is theta / (2 pi ratio) * pitch: with pitch 2 pi it is the rotary table's angle
    targets += [("plant", "parameters")] * builtin
    for section in targets:
        if isinstance(_get(data, section[:1]) or {}, dict) and isinstance(_get(data, section) or {}, dict):
            for key, value in chain.items():
                _set(data, section + (key,), value)
    return data


def following_note(signals: dict, unit: str = "m") -> str | None:
    """Why the axis did not follow its NC, when its position spanned less than a tenth of the NC's travel (a plant
    that did not move: its motions' verdicts only said "the second signal is constant") or its final position is
    further from the NC's target than a tenth of the programmed travel (at least 1 mm or 1 mrad), else None.

    ``signals``: the run's ``plant.position`` and ``nc.x_ref`` [m, or rad on a rotary axis] and ``nc.speed_ref``
    [rad/s], arrays of shape (n,). A position that moves against the speed reference is a sign convention (a
    vendor FMU that counts the direction negative): the position loop closed with the wrong sign runs away."""
    import numpy as np

    pos, ref = np.asarray(signals["plant.position"], float), np.asarray(signals["nc.x_ref"], float)
    travel, moved = float(np.ptp(ref)), float(np.ptp(pos))
    if travel > 1e-3 and moved < 0.1 * travel:  # an out-and-back motion ends at its target whether it moved or not
        return (f"the axis did not move: its position spanned {moved:.4g} {unit} where the NC's spanned {travel:.4g} "
                f"{unit}; its speed did not follow the NC's speed reference (loops the plant's parameters open, a "
                "limit, a fault or plant.map)")
    error = abs(pos[-1] - ref[-1])
    if not error > max(0.1 * float(np.ptp(ref)), 1e-3):  # NaN: the failed run says why
        return None
    text = f"the axis did not follow the NC: it ended {error:.4g} {unit} from the NC's target"
    speed_ref = signals.get("nc.speed_ref")
    if speed_ref is not None and float(np.diff(pos) @ np.asarray(speed_ref, float)[1:]) < 0:
        return (text + "; its position moved against the NC's speed reference: a direction the plant FMU counts "
                "negative? (map it with the opposite sign: plant.map.position.scale, see cosim info --map)")
    return text + "; its speed did not follow the NC's speed reference (a limit, a fault or plant.map)"
