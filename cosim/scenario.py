"""Scenario files: YAML -> typed, frozen objects, parsed and checked once.

A scenario names the plant FMU and how its variables map onto the master's roles, the NC program,
the sensors, the monitor, optional user components, the connections between ports, timed events
and what to record. Every error is a :class:`cosim.errors.ScenarioError` whose message starts with
``file:line: key.path:`` and says what was expected.

Roles (the plant's ports, always in SI units)::

    inputs   speed_ref [rad/s]  load [N.m]
    outputs  voltage [V]  voltage_ref [V] (optional)  current [A]  speed [rad/s]  position [m]

A map entry ``{var, scale, offset}`` converts between a role and an FMU variable: for an input
role the FMU receives ``scale * x + offset``; for an output role the master reads
``scale * y + offset``. The built-in plant has a default map. The drive chain (ball-screw pitch, belt
ratio, rotary or linear table) is stated once, in ``axis:`` (``cosim.axis``); the NC, the encoder and
the built-in plant's ``pitch`` and ``belt_ratio`` parameters get it from there. The older places
(``plant.parameters.pitch``, ``nc.pitch``, ``sensors.encoder.pitch``) still work; two of them that
disagree are a ScenarioError naming both keys.
"""
from __future__ import annotations

import importlib.util
import math
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, Field, PrivateAttr, ValidationError

from feeddrive.cosim import scenario_plant
from feeddrive.cosim.axis import Axis, resolve_drive_chain
from feeddrive.cosim.drive import (
    SERVO,
    SERVO_CLASS,
    apply_drive,
    check_pole_pairs,
    second_sensor_phase,
    servo_oversample,
)
from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.fmu_inspect import REAL_TYPES
from feeddrive.cosim.fmu_inspect import fmi_version as fmi_version  # re-exported: cosim info, the tests
from feeddrive.cosim.fmu_inspect import model_description as model_description
from feeddrive.cosim.fmu_inspect import sha256 as sha256
from feeddrive.cosim.nc import SETTLING, NCConfig, drive_chain_nominal, plan_program
from feeddrive.cosim.scenario_plant import BUILTIN_MAP as BUILTIN_MAP
from feeddrive.cosim.scenario_plant import BUILTIN_MAPS as BUILTIN_MAPS
from feeddrive.cosim.scenario_plant import BUILTIN_PLANTS as BUILTIN_PLANTS
from feeddrive.cosim.scenario_plant import PMSM_MAP as PMSM_MAP
from feeddrive.cosim.scenario_plant import FMUConfig, MapEntry, PlantConfig
from feeddrive.cosim.scenario_plant import Strict as _Strict
from feeddrive.cosim.sensors import EVENT_FIELDS, SensorsConfig
from feeddrive.cosim.unit_map import INPUT_ROLES as INPUT_ROLES
from feeddrive.cosim.unit_map import OUTPUT_ROLES as OUTPUT_ROLES
from feeddrive.cosim.unit_map import REQUIRED_ROLES as REQUIRED_ROLES
from feeddrive.cosim.unit_map import ROLE_UNITS as ROLE_UNITS
from feeddrive.cosim.unit_map import check_map
from feeddrive.cosim.yaml_source import KeyPath, from_validation, located_error, read_yaml

STANDARD_COMPONENTS = ("nc", "plant", "sensors", "monitor")
DEFAULT_MONITOR = "feeddrive.cosim.monitor:Monitor"



class ComponentSpec(_Strict):
    """A user component: ``class: package.module:ClassName``; ``inputs`` maps its ports to sources."""

    name: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")
    class_: str | None = Field(None, alias="class")
    fmu: str | None = None  # an FMU component instead of a class (cosim/fmu_components.py)
    config: Any = {}
    inputs: dict[str, str | float] = {}


class Event(_Strict):
    """At the first grid point ``t_n >= time``, ``component.set_parameter(name, value)`` (target ``component.name``)."""

    time: float = Field(ge=0)
    target: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*\..+$")
    value: float | str


class Scenario(_Strict):
    """A validated scenario; build it with :func:`load_scenario` or :func:`scenario_from_dict`."""

    name: str = Field(pattern=r"^[A-Za-z0-9_.-]+$")
    axis: Axis = Axis()  # ``axis: X`` (a name) or the drive chain ``{name, kind, pitch, ratio, side}``
    step: float = Field(1.0e-4, gt=0, description="communication step [s]")
    stop_time: float | None = Field(None, gt=0, description="[s]; default: NC program duration + 0.3 s")
    plant: PlantConfig = PlantConfig()
    sensors: SensorsConfig = Field(default_factory=SensorsConfig)
    nc: NCConfig | None = None  # None: a system of components only (cosim/fmu_components.py)
    monitor: Any = None  # ComponentSpec or None, built by the loader from the ``monitor:`` section
    components: list[ComponentSpec] = []
    connections: dict[str, str | float] = {}
    events: list[Event] = []
    record: Literal["all"] | list[str] = "all"

    _source: str = PrivateAttr("<dict>")
    _lines: dict = PrivateAttr(default_factory=dict)
    _base_dir: Path = PrivateAttr(default_factory=Path.cwd)
    _conversions: dict = PrivateAttr(default_factory=dict)

    @property
    def unit_notes(self) -> list[str]:
        """The plant map's stated unit assumptions (``unit not declared: taken as rad/s``), one per entry; and a
        voltage pair without redundancy: ``voltage_ref`` unmapped (the sensors' u_ref then measures the plant's
        voltage, the master's fallback) or read from the voltage's own variable, whose check passes by construction
        (the run said "measurements valid" with nothing to say it compared a signal with itself)."""
        notes = [c.note for c in self._conversions.values() if c.note]
        roles = self.plant.map
        parts = {r for c in self.components if c.fmu is not None and isinstance(c.config, dict)
                 for r in c.config.get("map") or {}} | {r for c in self.components if c.fmu is not None
                                                        and not isinstance(c.config, dict) for r in c.config.map}
        if not self._conversions or self.nc is None or self.monitor is None or "voltage_ref" in parts:
            return notes
        if "voltage_ref" not in roles:
            notes.append("voltage_ref not mapped: the sensors' u_ref measures the plant's voltage, so the voltage "
                         "pair (u against u_ref) has no redundancy and its check passes by construction")
        elif "voltage" in roles and roles["voltage_ref"].var == roles["voltage"].var:
            notes.append(f"voltage and voltage_ref both read {roles['voltage'].var}: the voltage pair (u against u_ref) "
                         "has no redundancy and its check passes by construction")
        return notes

    @property
    def servo_drive(self) -> bool:
        """A PMSM axis (``axis.drive.kind: pmsm``, or the default monitor's ``drive`` not ``dc``): only then does
        a component named ``servo`` (the servo drive's sensors) step before the monitor and feed its servo inputs."""
        drive = self.axis.drive
        spec = self.monitor
        monitor_drive = getattr(spec.config, "drive", "dc") if spec is not None else "dc"
        return (drive is not None and drive.kind == "pmsm") or monitor_drive != "dc"

    @property
    def source(self) -> str:
        """The scenario file (or ``<dict>``)."""
        return self._source

    @property
    def base_dir(self) -> Path:
        """Directory against which relative paths of the scenario are resolved."""
        return self._base_dir

    def nc_cycle_ticks(self) -> int:
        """The NC's cycle in ticks of the plant's step ``step / plant.oversample`` (default: one ``step``)."""
        m = self.plant.oversample
        if self.nc.cycle is None:
            return m
        ticks = self.nc.cycle * m / self.step
        return max(1, round(ticks))

    def error(self, path: KeyPath, message: str) -> ScenarioError:
        """A ScenarioError naming the file, the YAML line of ``path`` (or its nearest parent) and the key."""
        return located_error(self._source, self._lines, path, message)

    def to_dict(self) -> dict:
        """Everything as plain YAML-able data, defaults filled; ``scenario_from_dict`` reads it back."""
        data = self.model_dump(mode="json", by_alias=True, exclude={"monitor"}, exclude_none=True)
        spec = self.monitor
        if spec is not None:
            cfg = spec.config.model_dump(mode="json", exclude_none=True) if isinstance(spec.config, BaseModel) \
                else spec.config
            data["monitor"] = cfg if spec.class_ == DEFAULT_MONITOR else {"class": spec.class_, "config": cfg}
        return data


# -- loading -------------------------------------------------------------------------------------


def load_scenario(path: str | Path) -> Scenario:
    """Read and check a scenario file.

    Parameters
    ----------
    path : str or Path
        The YAML file. Relative FMU paths in it are resolved against its directory.

    Returns
    -------
    Scenario
        Frozen, with the plant FMU resolved (absolute path, sha256, complete role map).

    Raises
    ------
    ScenarioError
        Unreadable or malformed file; the message has ``file:line: key:`` and what was expected.
    """
    path = Path(path)
    data, lines = read_yaml(path)
    return scenario_from_dict(data, source=str(path), base_dir=path.resolve().parent, lines=lines)


def load_plant_map(path: str | Path) -> tuple[dict[str, MapEntry], Callable[[KeyPath, str], ScenarioError]]:
    """The role map of a scenario file's ``plant:`` section (with the built-in defaults when its FMU is
    ``builtin``), without resolving its FMU; and a factory of errors naming that file and line."""
    path = Path(path)
    data, lines = read_yaml(path)
    if isinstance(data, dict):  # axis.drive chooses the default plant (builtin-pmsm for kind: pmsm)
        data = apply_drive(data, lambda key, message: located_error(str(path), lines, key, message))
    raw = data.get("plant") or {} if isinstance(data, dict) else {}
    try:
        plant = PlantConfig.model_validate(raw)
    except ValidationError as exc:
        raise from_validation(exc, raw, str(path), lines, prefix=("plant",), model=PlantConfig) from None
    axis = data.get("axis") if isinstance(data, dict) else None
    rotary = isinstance(axis, dict) and axis.get("kind") == "rotary"  # the built-in x is then in rad
    defaults = {r: MapEntry(var=v, unit="rad" if rotary and r == "position" else None)
                for r, v in BUILTIN_MAPS.get(plant.fmu, {}).items()}
    return defaults | dict(plant.map), lambda key, message: located_error(str(path), lines, key, message)


def scenario_from_dict(data: Any, *, source: str = "<dict>", base_dir: str | Path | None = None,
                       lines: Mapping[KeyPath, int] | None = None) -> Scenario:
    """Check a scenario given as plain data (as read from YAML); see :func:`load_scenario`.

    Campaigns use it on modified copies of a base scenario; ``base_dir`` resolves relative FMU paths
    (default: the current directory) and ``lines`` (key path -> YAML line) improves messages.
    """
    lines = dict(lines or {})
    if not isinstance(data, dict):
        raise located_error(source, lines, (), f"expected a mapping of scenario keys, got {type(data).__name__}")
    data = apply_drive(dict(data), lambda key, message: located_error(source, lines, key, message))
    data = servo_oversample(data, lambda key, message: located_error(source, lines, key, message))
    given, data = dict(data), _drive_chain(data, source, lines)
    base_dir = Path(base_dir or ".").resolve()
    data["monitor"] = _monitor_spec(data.get("monitor"), data, base_dir, source, lines)
    try:
        scenario = Scenario.model_validate(data)
    except ValidationError as exc:
        raise from_validation(exc, data, source, lines, model=Scenario) from None
    scenario._source = source
    scenario._lines = lines
    scenario._base_dir = base_dir
    from feeddrive.cosim import fmu_components

    if scenario.stop_time is not None:  # the master runs whole steps: 1.0 s at 0.03 s would run 1.02 s, unsaid
        n = scenario.stop_time / scenario.step
        if abs(n - round(n)) > 1e-6 * max(1.0, n) and n > 1:
            lo, hi = math.floor(n) * scenario.step, math.ceil(n) * scenario.step
            raise scenario.error(("stop_time",), f"{scenario.stop_time:g} s is not a whole number of steps of "
                                                 f"{scenario.step:g} s; expected e.g. {lo:.10g} or {hi:.10g}")
    if scenario.nc is None:
        fmu_components.check_components_only(scenario, given)
        return scenario.model_copy(update={"components": fmu_components.resolve_components(scenario, FMUConfig, check_map)})
    # the master runs ceil(stop / step) steps: a longer step would be one step past the stop time, no motion sampled
    if scenario.stop_time is not None:
        stop, what = scenario.stop_time, "stop_time"
    else:
        stop = plan_program(scenario.nc)[-1][0] + SETTLING
        what = f"the default stop time: the NC program + {SETTLING:g} s"
    if scenario.step > stop:
        raise scenario.error(("step",), f"{scenario.step:g} s is longer than the run ({stop:g} s, {what}); "
                                        "expected a communication step <= the stop time")
    if scenario.nc.cycle is not None:
        ticks, hf = scenario.nc.cycle * scenario.plant.oversample / scenario.step, scenario.step / scenario.plant.oversample
        if ticks < 1 - 1e-9 or abs(ticks - round(ticks)) > 1e-6 * max(1.0, ticks):
            raise scenario.error(("nc", "cycle"), f"{scenario.nc.cycle:g} s is not an integer multiple of the plant's "
                                                  f"step {hf:g} s (step / plant.oversample); expected e.g. "
                                                  f"{max(1, round(ticks)) * hf:g}")
    _check_lowpass(scenario)
    plant, md = scenario_plant.resolve_plant(scenario)
    scenario_plant.check_drive_chain(scenario, md)
    scenario_plant.check_input_ranges(scenario.model_copy(update={"plant": plant}), md)
    check_pole_pairs(scenario.axis.drive, {v.name: v for v in md.modelVariables}, scenario.plant.parameters,
                     scenario.error)
    _check_events(scenario, md)
    _check_stop(scenario, stop, what)
    return scenario.model_copy(update={"plant": plant, "connections": _servo_connections(scenario),
                                       "components": fmu_components.resolve_components(scenario, FMUConfig, check_map)})


def _servo_connections(s: Scenario) -> dict[str, str | float]:
    """The connections with a PMSM monitor's servo inputs wired to the ``servo`` component's outputs of the same
    names (those the scenario leaves unconnected); on a DC axis, or without a ``servo`` component, unchanged."""
    servo_monitor = s.monitor is not None and getattr(s.monitor.config, "drive", "dc") != "dc"
    if not servo_monitor:
        return dict(s.connections)
    from feeddrive.cosim.monitor_servo import SERVO_INPUTS

    if not any(c.name == SERVO for c in s.components):
        # a vendor FMU on a PMSM axis without the servo sensors: the master's "input 'monitor.I_U' is not
        # connected" named the symptom, not the missing component (nor a DC FMU on a PMSM axis)
        missing = [p for p in SERVO_INPUTS if f"monitor.{p}" not in s.connections]
        if missing:
            key = ("axis", "drive", "kind") if s.axis.drive is not None else ("monitor", "drive")
            raise s.error(key, f"a PMSM axis's monitor reads the servo drive's sensors ({', '.join(missing[:3])}, ...), "
                               f"and no component provides them: expected a component named {SERVO} (class "
                               f"{SERVO_CLASS}) wired to the plant FMU's dq outputs (README: A vendor's PMSM FMU), "
                               f"or kind: dc if {Path(s.plant.fmu).name} is a DC drive")
        return dict(s.connections)

    return {f"monitor.{port}": f"{SERVO}.{port}" for port in SERVO_INPUTS} | dict(s.connections)


def _drive_chain(data: dict, source: str, lines: dict) -> dict:
    """The scenario with its axis's drive chain stated once (``cosim.axis.resolve_drive_chain``)."""
    plant = data.get("plant")
    fmu = plant.get("fmu", "builtin") if isinstance(plant, dict) else "builtin"
    try:
        return resolve_drive_chain(data, fmu in BUILTIN_PLANTS, drive_chain_nominal(str(fmu)),
                                   lambda key, message: located_error(source, lines, key, message))
    except ValidationError as exc:
        raw = data.get("axis")
        raise from_validation(exc, raw, source, lines, prefix=("axis",), model=Axis) from None


def _monitor_spec(raw: Any, data: dict, base_dir: Path, source: str, lines: dict) -> ComponentSpec | None:
    """``monitor: {...}`` is the default monitor's config; ``{class: ..., config: ...}`` replaces it.

    The default monitor's ``axis`` and ``scenario`` default to the scenario's ``axis`` and ``name``, and a
    relative history ``db`` is resolved against the scenario's directory (as FMU paths are); ``:memory:``
    keeps the history in memory. Without ``db``, ``run_scenario`` puts it beside the output directory."""
    if raw is None:
        return None
    if not isinstance(raw, dict):
        raise located_error(source, lines, ("monitor",), f"expected a mapping, got {type(raw).__name__}")
    if "class" in raw and raw["class"] != DEFAULT_MONITOR:
        try:
            return ComponentSpec.model_validate({"name": "monitor", **raw})
        except ValidationError as exc:
            raise from_validation(exc, raw, source, lines, prefix=("monitor",), model=ComponentSpec) from None
    try:
        from feeddrive.cosim.monitor_config import MonitorConfig, resolve_files

        # the component's module is imported by the run that makes it (with scipy: 1.3 s); here, whether it exists
        if importlib.util.find_spec("feeddrive.cosim.monitor") is None:
            raise ImportError("feeddrive.cosim.monitor")
    except ImportError:
        warnings.warn(f"{source}: monitor: cosim.monitor is not available; running without a monitor",
                      stacklevel=3)
        return None
    prefix: KeyPath = ("monitor",)
    if "class" in raw:
        raw, prefix = raw.get("config") or {}, ("monitor", "config")
    fields = MonitorConfig.model_fields
    name = data.get("axis", "X")
    name = name.get("name", "X") if isinstance(name, dict) else name
    implied = {k: v for k, v in (("axis", name), ("scenario", data.get("name")))
               if k in fields and isinstance(v, str)}
    if "sampling" in fields:
        implied["sampling"] = _implied_sampling(data)
    drive = data.get("axis", {}).get("drive") if isinstance(data.get("axis"), dict) else None
    if isinstance(drive, dict) and "drive" in fields:  # the axis's motor, stated once (validated by apply_drive)
        implied |= {"drive": drive.get("kind", "dc")} | ({"pole_pairs": drive["pole_pairs"]}
                                                          if drive.get("pole_pairs") else {})
    components = data.get("components") if isinstance(data.get("components"), list) else []
    stated = raw.get("drive") if isinstance(raw, dict) else None
    if (stated or implied.get("drive", "dc")) != "dc" and "second_sensor_on" in fields and any(isinstance(c, dict) and c.get("name") == SERVO for c in components):
        second = second_sensor_phase(data.get("components"))  # the servo sensors' (set from axis.drive)
        given = raw.get("second_sensor_on", second) if isinstance(raw, dict) else second
        if given != second:
            raise located_error(source, lines, (*prefix, "second_sensor_on"),
                                f"{given!r} contradicts the servo sensors' second_sensor_on = {second!r}; "
                                f"expected {second!r} (or the key left out: the servo component states it)")
        implied["second_sensor_on"] = second
    raw = resolve_files(raw, base_dir) if isinstance(raw, dict) else raw  # a relative db or baseline FILE
    plant = data.get("plant") if isinstance(data.get("plant"), dict) else {}
    motor = scenario_plant.BUILTIN_DRIVES.get(plant.get("fmu", "builtin"), ())
    if "nominal" in fields and (stated or implied.get("drive", "dc")) in motor:  # a built-in plant's design values
        from feeddrive.models.drives import drive_model

        given = raw.get("nominal") if isinstance(raw, dict) else None
        implied["nominal"] = drive_model(stated or implied.get("drive", "dc")).nominal(("physical",)) | (
            given if isinstance(given, dict) else {})
        if isinstance(given, dict):
            raw = {k: v for k, v in raw.items() if k != "nominal"}
    try:
        config = MonitorConfig.model_validate(implied | raw if isinstance(raw, dict) else raw)
    except ValidationError as exc:
        raise from_validation(exc, raw, source, lines, prefix=prefix, model=MonitorConfig) from None
    return ComponentSpec(name="monitor", class_=DEFAULT_MONITOR, config={}).model_copy(update={"config": config})


def _check_lowpass(s: Scenario) -> None:
    """An anti-aliasing filter runs at the plant's step: its cut-off must be well below that step's Nyquist."""
    hf = s.step / s.plant.oversample
    sensors = s.sensors
    channels = {("current", 0): sensors.current[0], ("current", 1): sensors.current[1], ("voltage",): sensors.voltage,
                ("voltage_ref",): sensors.voltage_ref, ("tachometer",): sensors.tachometer}
    for key, chan in channels.items():
        fc = chan.cutoff_hz or 0.25 / s.step
        if chan.sampling == "lowpass" and not fc < 0.45 / hf:
            raise s.error(("sensors", *key, "cutoff_hz"), f"{fc:g} Hz: expected a cut-off below {0.45 / hf:g} Hz "
                                                         f"(0.9 x the Nyquist frequency of the plant's step {hf:g} s)")


def _implied_sampling(data: dict) -> dict[str, str]:
    """The monitor's default ``sampling``: a quantity is an interval mean when the plant is oversampled and
    every sensor of it samples the mean (the default; a PMSM's servo sensors included); bad values are left to
    the sections' own checks."""
    plant, sensors = data.get("plant"), data.get("sensors")
    m = plant.get("oversample", 1) if isinstance(plant, dict) else 1
    if not isinstance(m, int) or m <= 1:
        return {}
    sensors = sensors if isinstance(sensors, dict) else {}
    current = sensors.get("current")
    channels = {"voltage": [sensors.get("voltage"), sensors.get("voltage_ref")],
                "current": list(current) if isinstance(current, list) else [None, None],
                "speed": [sensors.get("tachometer")]}
    servo = next((c.get("config") for c in data.get("components") or () if isinstance(c, dict)
                  and c.get("name") == SERVO and isinstance(c.get("config"), dict)), None) \
        if isinstance(data.get("components"), list) else None
    if servo is not None:  # a PMSM's servo sensors sample the same quantities (cosim/sensors_servo.py)
        phases = servo.get("phases")
        channels["current"] += (list(phases) if isinstance(phases, list) else [None] * 3) + [servo.get("second")]
        channels["voltage"] += [servo.get("voltage"), servo.get("voltage_ref")]
    return {q: "mean" for q, chans in channels.items()
            if all((c or {}).get("sampling", "mean") == "mean" if isinstance(c, dict) or c is None else False
                   for c in chans)}


def _event_step(time: float, t0: float, h: float) -> int:
    """``cosim.master.event_step`` (the master imports this module): index n of the first grid point t0 + n h >= time."""
    return max(0, math.ceil((time - t0) / h - 1e-9))


def _check_stop(s: Scenario, stop: float, what: str) -> None:
    """Refuse an event the run ends before: it was dropped without a word (a fault injected at 9.5 s into a 2.1 s
    run left a healthy verdict)."""
    hf = s.step / s.plant.oversample
    ticks = _event_step(stop, 0.0, s.step) * s.plant.oversample
    for k, ev in enumerate(s.events):
        if _event_step(ev.time, 0.0, hf) >= ticks:
            raise s.error(("events", k, "time"), f"{ev.time:g} s is not before the run's end ({stop:.10g} s, {what}): "
                                                 "the event would never be applied; expected a time before it, or a "
                                                 "later stop_time")


def stop_note(s: Scenario) -> str | None:
    """What a monitored run's ``stop_time`` leaves unjudged, or None: a high-speed motion of the NC program that the
    run stops inside (or before the first one). Such a motion is never judged, and the run said nothing of it; a
    short run is still a valid simulation (a slice of a motion compared between two loops), so it is said, not
    refused (``cosim run`` prints it; the monitor's report holds ``unfinished_motion``)."""
    from feeddrive.cosim.nc import RAPID

    if s.stop_time is None or s.monitor is None or s.nc is None:
        return None
    stop, motions, plan = s.stop_time, [], plan_program(s.nc)  # (start, end, item) of each run of RAPID pieces
    for seg, nxt in zip(plan, plan[1:]):
        if seg[4] == RAPID:
            if motions and motions[-1][2] == seg[6] and motions[-1][1] == seg[0]:
                motions[-1][1] = nxt[0]
            else:
                motions.append([seg[0], nxt[0], seg[6]])
    for k, (start, end, _) in enumerate(motions, 1):
        judged = _event_step(end, 0.0, s.step) * s.step  # the monitor ends a motion at the first sample after it
        if stop < judged - 1e-9 * s.step and (start < stop or k == 1):
            where = (f"inside the NC program's high-speed motion {k} ({start:.6g}-{end:.6g} s): it is not judged"
                     if start < stop else f"before the NC program's first high-speed motion ({start:.6g}-{end:.6g} "
                     "s): the monitor judges nothing")
            return f"stop_time: {stop:g} s ends {where}; a stop_time of at least {judged:.10g} s judges it"
    return None


def _check_events(s: Scenario, md: Any) -> None:
    names = {"plant", "nc", "sensors"} | {c.name for c in s.components} | ({"monitor"} if s.monitor else set())
    users = [c.name for c in s.components]
    clash = sorted(set(users) & set(STANDARD_COMPONENTS)) or sorted({n for n in users if users.count(n) > 1})
    if clash:
        raise s.error(("components",), f"component name {clash[0]!r} is used twice; names must be unique "
                                       f"and differ from {', '.join(STANDARD_COMPONENTS)}")
    variables = {v.name: v for v in md.modelVariables}
    for k, ev in enumerate(s.events):
        comp, _, param = ev.target.partition(".")
        if comp not in names:
            raise s.error(("events", k, "target"), f"unknown component {comp!r}; expected one of "
                                                   f"{', '.join(sorted(names))}")
        if comp == "plant":
            v = variables.get(param)
            if v is None or v.causality != "parameter" or v.variability != "tunable" or v.type not in REAL_TYPES:
                tunable = [n for n, x in variables.items() if x.causality == "parameter"
                           and x.variability == "tunable" and x.type in REAL_TYPES]
                raise s.error(("events", k, "target"), f"{param!r} is not a tunable Real parameter of the plant "
                                                       f"FMU; expected one of: {', '.join(tunable)}")
            if not isinstance(ev.value, float) or not math.isfinite(ev.value):
                raise s.error(("events", k, "value"), f"expected a finite number for plant.{param}, got {ev.value!r}")
            scenario_plant.check_range(s, ("events", k, "value"), v, ev.value, "the plant FMU")
        elif comp == "sensors":
            _check_sensor_event(s, k, param, ev.value)
        elif comp == "nc" or (comp == "monitor" and s.monitor.class_ == DEFAULT_MONITOR):
            raise s.error(("events", k, "target"), f"{comp!r} accepts no events; expected a target on plant, "
                                                   "sensors or a user component")


def _check_sensor_event(s: Scenario, k: int, name: str, value: float | str) -> None:
    """``sensors.<channel>.<field>`` with the channels and fields ``SensorsComponent.set_parameter`` accepts."""
    channels, fields = tuple(s.sensors.channels()), EVENT_FIELDS
    channel, _, field = name.partition(".")
    if channel not in channels or field not in fields:
        raise s.error(("events", k, "target"), f"sensors.{name}: expected sensors.<channel>.<field> with channel "
                                               f"in {', '.join(channels)} and field in {', '.join(fields)}")
    if not isinstance(value, float) or not math.isfinite(value) or (field == "noise" and value < 0):
        raise s.error(("events", k, "value"), f"expected a finite number{' >= 0' * (field == 'noise')} for "
                                              f"sensors.{name}, got {value!r}")
