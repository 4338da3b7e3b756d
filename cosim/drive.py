"""The axis's drive: which motor the scenario's plant is, stated once (``axis: {drive: {kind: pmsm, pole_pairs: 4}}``).

``kind`` selects the defaults that depend on the motor:

=======  ====================  ==========================  =============================================
kind     default plant         role map                    sensors
=======  ====================  ==========================  =============================================
dc       ``builtin``           ``scenario.BUILTIN_MAP``    ``sensors:`` (two current sensors, u, u_ref,
                                                           tachometer, encoder; the paper's)
pmsm     ``builtin-pmsm``      ``scenario.PMSM_MAP``       ``sensors:`` on the q axis, plus the servo
                                                           sensors (``cosim.sensors_servo.ServoSensors``,
                                                           component ``servo``): phase currents with a
                                                           second sensor, dq voltages, motor encoder and
                                                           linear scale
=======  ====================  ==========================  =============================================

The servo sensors are added, wired to the built-in PMSM's outputs (``SERVO_WIRING``), when the plant is
``builtin-pmsm`` and the scenario has no component named ``servo``; for a vendor's PMSM FMU the scenario adds
them itself (``components: [{name: servo, class: feeddrive.cosim.sensors_servo:ServoSensors, inputs: ...,
config: {scales: ...}}]``, its units converted by ``scales``). ``pole_pairs`` is checked against the plant
FMU's parameter ``p`` (``check_pole_pairs``) and handed to the servo sensors. A scenario without ``drive``
keeps its plant (``builtin`` by default) and gets no servo sensors.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

#: the plant each drive kind defaults to, and the built-in plants of each kind
DEFAULT_PLANT = {"dc": "builtin", "pmsm": "builtin-pmsm"}
BUILTIN_KIND = {"builtin": "dc", "builtin-backlash": "dc", "builtin-pmsm": "pmsm"}
SERVO = "servo"
SERVO_CLASS = "feeddrive.cosim.sensors_servo:ServoSensors"
PHASES = ("U", "V", "W")
#: the servo sensors' inputs from the built-in PMSM's outputs (SI, peak dq currents: no scales); the q axis and
#: the position are the plant's roles (``scenario.PMSM_MAP``), the other outputs keep their FMU names
SERVO_WIRING = {"i_d": "plant.i_d", "i_q": "plant.current", "theta": "plant.theta", "u_d_ref": "plant.u_d_ref",
                "u_q_ref": "plant.voltage_ref", "u_d": "plant.u_d", "u_q": "plant.voltage", "x_table": "plant.position"}


class Drive(BaseModel):
    """An axis's drive.

    Attributes
    ----------
    kind : {"dc", "pmsm"}
        DC motor with its converter (the paper's) or permanent-magnet synchronous servo motor with its FOC drive.
    pole_pairs : int or None
        ``p`` of a PMSM; None: the plant FMU's ``p``. Checked against the FMU.
    second_sensor_on : {"U", "V", "W"} or None
        The phase a PMSM's second current sensor measures (the material redundancy); None: the servo
        sensors' ``second_sensor_on`` (default U). Handed to the servo sensors and to the monitor.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    kind: Literal["dc", "pmsm"] = "dc"
    pole_pairs: int | None = Field(None, ge=1)
    second_sensor_on: Literal["U", "V", "W"] | None = None


def apply_drive(data: dict, error: Callable[[tuple, str], Exception]) -> dict:
    """The scenario data with the drive's defaults filled in (before the sections are validated).

    Parameters
    ----------
    data : dict
        The scenario as read from YAML (not modified).
    error : callable
        ``error(key_path, message) -> ScenarioError`` naming the file and line.

    Returns
    -------
    dict
        A copy whose ``plant.fmu`` defaults to the drive's plant and, for a PMSM on the built-in plant, whose
        ``components`` hold the servo sensors.

    Raises
    ------
    ScenarioError
        A malformed ``axis.drive``, or a built-in plant of the other kind of motor.
    """
    axis = data.get("axis")
    raw = axis.get("drive") if isinstance(axis, dict) else None
    if raw is None:
        return data
    if not isinstance(raw, dict):
        raise error(("axis", "drive"), f"expected a mapping {{kind: dc | pmsm, pole_pairs: <int>}}, got {raw!r}")
    bad = sorted(set(raw) - set(Drive.model_fields))
    if bad:
        raise error(("axis", "drive", bad[0]), f"unknown key; expected {', '.join(Drive.model_fields)}")
    kind, pp = raw.get("kind", "dc"), raw.get("pole_pairs")
    if kind not in DEFAULT_PLANT:
        raise error(("axis", "drive", "kind"), f"expected dc or pmsm, got {kind!r}")
    if pp is not None and (isinstance(pp, bool) or not isinstance(pp, int) or pp < 1):
        raise error(("axis", "drive", "pole_pairs"), f"expected an integer >= 1, got {pp!r}")
    if pp is not None and kind != "pmsm":
        raise error(("axis", "drive", "pole_pairs"), "a DC motor has no pole pairs; expected kind: pmsm")
    second = raw.get("second_sensor_on")
    if second is not None and second not in PHASES:
        raise error(("axis", "drive", "second_sensor_on"), f"expected the phase U, V or W, got {second!r}")
    if second is not None and kind != "pmsm":
        raise error(("axis", "drive", "second_sensor_on"), "a DC motor's second current sensor is "
                                                          "sensors.current[1]; expected kind: pmsm")
    data = dict(data)
    plant = data.get("plant")
    plant = dict(plant) if isinstance(plant, dict) else {}
    fmu = plant.setdefault("fmu", DEFAULT_PLANT[kind])
    if BUILTIN_KIND.get(fmu, kind) != kind:
        raise error(("plant", "fmu"), f"{fmu} is the built-in {BUILTIN_KIND[fmu].upper()} plant but axis.drive.kind "
                                      f"is {kind}; expected plant.fmu: {DEFAULT_PLANT[kind]} (or a {kind} FMU)")
    data["plant"] = plant
    components = data.get("components") or []
    if fmu == "builtin-pmsm" and isinstance(components, list) and not any(
            isinstance(c, dict) and c.get("name") == SERVO for c in components):
        sensors = data.get("sensors")
        seed = sensors.get("seed", 0) if isinstance(sensors, dict) else 0
        params = plant.get("parameters") if isinstance(plant.get("parameters"), dict) else {}
        p = pp or params.get("p") or 4
        config = {"seed": seed, "pole_pairs": int(p)} | ({"second_sensor_on": second} if second else {})
        if isinstance(axis.get("pitch"), (int, float)) or isinstance(axis.get("ratio"), (int, float)):
            config["encoder"] = {k: axis[a] for k, a in (("pitch", "pitch"), ("belt_ratio", "ratio"))
                                 if isinstance(axis.get(a), (int, float))}
        data["components"] = [*components, {"name": SERVO, "class": SERVO_CLASS,
                                            "config": config, "inputs": dict(SERVO_WIRING)}]
    elif second is not None:  # the scenario's own servo sensors: the phase stated once, or twice alike
        data["components"] = _second_phase(components, second, error)
    return data


def _second_phase(components: list, second: str, error: Callable[[tuple, str], Exception]) -> list:
    """``components`` with the ``servo`` component's ``second_sensor_on`` set to the drive's ``second``;
    a contradicting value is an error naming both keys."""
    out = list(components) if isinstance(components, list) else components
    for k, c in enumerate(out):
        if not (isinstance(c, dict) and c.get("name") == SERVO):
            continue
        config = c.get("config") if isinstance(c.get("config"), dict) else {}
        given = config.get("second_sensor_on", second)
        if given != second:
            raise error(("components", k, "config", "second_sensor_on"),
                        f"{given!r} contradicts axis.drive.second_sensor_on = {second!r}; expected {second!r} "
                        "(or the key left out: the drive states it)")
        out[k] = c | {"config": config | {"second_sensor_on": second}}
    return out


def second_sensor_phase(components: Any) -> str | None:
    """The phase of the second current sensor of the scenario's ``servo`` component (raw YAML data): its
    ``config.second_sensor_on`` (default U; None: no second sensor); U when there is no servo component."""
    for c in components if isinstance(components, list) else ():
        if isinstance(c, dict) and c.get("name") == SERVO:
            config = c.get("config") if isinstance(c.get("config"), dict) else {}
            return config.get("second_sensor_on", "U")
    return "U"


def servo_oversample(data: dict, error: Callable[[tuple, str], Exception]) -> dict:
    """The scenario with its ``servo`` sensors' ``config.oversample`` set to ``plant.oversample`` (their sampling's
    sub-samples, as the DC sensors'); a different value stated in the servo's config is an error."""
    components, plant = data.get("components"), data.get("plant")
    m = plant.get("oversample", 1) if isinstance(plant, dict) else 1
    if not isinstance(components, list) or not isinstance(m, int) or isinstance(m, bool):
        return data
    out = list(components)
    for k, c in enumerate(out):
        if not (isinstance(c, dict) and c.get("name") == SERVO and c.get("class") == SERVO_CLASS):
            continue
        config = c.get("config") if isinstance(c.get("config"), dict) else {}
        if config.get("oversample", m) != m:
            raise error(("components", k, "config", "oversample"), f"{config['oversample']!r} contradicts "
                        f"plant.oversample = {m}; expected {m} (or the key left out: the plant states it)")
        out[k] = c | {"config": config | {"oversample": m}}
    return data | {"components": out}


def check_pole_pairs(drive: Drive | None, variables: dict[str, Any], parameters: dict[str, float],
                     error: Callable[[tuple, str], Exception]) -> None:
    """``axis.drive.pole_pairs`` against the plant FMU's ``p`` (``plant.parameters.p`` or its start value)."""
    if drive is None or drive.pole_pairs is None:
        return
    v = variables.get("p")
    value = parameters.get("p", getattr(v, "start", None) if v is not None else None)
    if value in (None, ""):
        return
    if not math.isclose(float(value), drive.pole_pairs, rel_tol=1e-12):
        where = "plant.parameters.p" if "p" in parameters else "the FMU's p"
        raise error(("axis", "drive", "pole_pairs"), f"{drive.pole_pairs} contradicts {where} = {float(value):g}; "
                                                     f"expected pole_pairs: {float(value):g}")
