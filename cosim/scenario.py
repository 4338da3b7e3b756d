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

import math
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, ValidationError, field_validator

from feeddrive.cosim import fmu_inspect
from feeddrive.cosim.axis import Axis, resolve_drive_chain
from feeddrive.cosim.errors import ScenarioError
from feeddrive.cosim.fmu_inspect import REAL_TYPES, check_archive, fmi_version, model_description, runnable, sha256
from feeddrive.cosim.nc import SETTLING, NCConfig, drive_chain_nominal, plan_program
from feeddrive.cosim.sensors import EVENT_FIELDS, SensorsConfig
from feeddrive.cosim.unit_map import INPUT_ROLES as INPUT_ROLES
from feeddrive.cosim.unit_map import OUTPUT_ROLES as OUTPUT_ROLES
from feeddrive.cosim.unit_map import REQUIRED_ROLES as REQUIRED_ROLES
from feeddrive.cosim.unit_map import ROLE_UNITS as ROLE_UNITS
from feeddrive.cosim.unit_map import Conversion, check_map
from feeddrive.cosim.yaml_source import KeyPath, from_validation, located_error, read_yaml

Role = Literal["speed_ref", "load", "voltage", "voltage_ref", "current", "speed", "position"]
BUILTIN_MAP = {"speed_ref": "w_ref", "load": "Tl", "voltage": "u", "voltage_ref": "u_ref", "current": "i",
               "speed": "w", "position": "x"}
#: The PMSM plant's roles: the DC pipeline's voltage and current are the q axis for now. The monitor's DC model is
#: biased on it (its one K cannot be both k_T = 1.5 p psi_f and k_E = p psi_f; issue 25 items 3-4 remove the bias).
PMSM_MAP = BUILTIN_MAP | {"voltage": "u_q", "voltage_ref": "u_q_ref", "current": "i_q"}
STANDARD_COMPONENTS = ("nc", "plant", "sensors", "monitor")
DEFAULT_MONITOR = "feeddrive.cosim.monitor:Monitor"



class _Strict(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", populate_by_name=True)


class MapEntry(_Strict):
    """One role <-> FMU variable conversion: ``role = scale * var + offset`` (or its inverse for inputs).

    ``scale`` and ``offset`` follow from the variable's unit (``unit`` when stated here, else the FMU's
    declaration) and the role's SI unit; given explicitly, they must agree with it (``cosim.unit_map``).
    After loading, both are set."""

    var: str
    unit: str | None = None
    scale: float | None = None
    offset: float | None = None

    @field_validator("scale")
    @classmethod
    def _scale_nonzero(cls, v: float | None) -> float | None:
        if v is not None and (v == 0 or not math.isfinite(v)):
            raise ValueError("scale must be finite and non-zero")
        return v

    def linear(self) -> tuple[float, float]:
        """``(scale, offset)``, 1 and 0 where unset."""
        return (1.0 if self.scale is None else self.scale), (0.0 if self.offset is None else self.offset)


#: ``plant.fmu`` values naming a built-in plant: the paper's model, and its variant with backlash in the
#: drive chain (``models.feed_drive(backlash=True)``), which provokes a model mismatch in the monitor; and the PMSM
#: servo drive (``models.pmsm_drive()``). Each with its default role map.
BUILTIN_MAPS = {"builtin": BUILTIN_MAP, "builtin-backlash": BUILTIN_MAP, "builtin-pmsm": PMSM_MAP}
BUILTIN_PLANTS = tuple(BUILTIN_MAPS)


class PlantConfig(_Strict):
    """The plant FMU. After loading, ``fmu`` is an absolute path, ``sha256`` its hash, ``map`` complete."""

    fmu: str = "builtin"
    sha256: str | None = None
    interface: Literal["cs", "me"] = "cs"
    oversample: int = Field(1, ge=1, description="plant and sensor steps per recording step: the plant's "
                            "communication step is step / oversample")
    tolerance: float = Field(1e-8, gt=0, description="relative tolerance of CVode (interface: me)")
    call_timeout: float = Field(60.0, gt=0, description="watchdog of `cosim run` [s]: a single FMI call "
                                "running longer stops the run as hung (report.json status: hung)")
    parameters: dict[str, float] = {}
    start: dict[str, float] = {}
    map: dict[Role, MapEntry] = {}
    input_hold: Literal["foh", "zoh"] | None = Field(
        None, description="how the plant sees its inputs between communication points. "
        "foh: first-order hold, the value set at t_n plus the slope (value_n - value_(n-1)) / h given with "
        "fmi2SetRealInputDerivatives (interface cs, for an FMU declaring canInterpolateInputs, as the built-in "
        "plant does) or set by the master inside CVode (interface me, any FMU), so a ramping speed reference "
        "stays a ramp inside each step; zoh: each value held over the step, "
        "a staircase whose ripple biases the electrical estimates (R, L ~ -0.2 % on the built-in plant). "
        "Default: foh when the FMU supports it, else zoh")

    def hold(self, md: Any) -> str:
        """The effective ``input_hold`` for the FMU described by ``md`` (fmpy's model description).

        Raises
        ------
        ValueError
            ``foh`` was asked for in Co-Simulation but the FMU does not declare ``canInterpolateInputs``;
            the message says what was expected.
        """
        # Model Exchange: the master integrates and interpolates the inputs itself
        can = self.interface == "me" or fmu_inspect.interpolates_inputs(md)
        if self.input_hold == "foh" and not can:
            raise ValueError("input_hold foh is not available: the FMU does not declare canInterpolateInputs "
                             "(FMI 2.0) or intermediate update of its inputs (FMI 3.0); expected zoh, no "
                             "input_hold, or interface me")
        return self.input_hold or ("foh" if can else "zoh")


class FMUConfig(PlantConfig):
    """An FMU component's ``config`` (cosim/fmu_components.py): the keys of ``plant:`` and its step multiple."""

    step_multiple: int | None = Field(None, ge=1, description="communication step of the FMU in ticks of the "
                                      "master's finest step (step / plant.oversample); default: the recording step")


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
        """The plant map's stated unit assumptions (``unit not declared: taken as rad/s``), one per entry."""
        return [c.note for c in self._conversions.values() if c.note]

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
    given, data = dict(data), _drive_chain(dict(data), source, lines)
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
    plant, md = _resolve_plant(scenario)
    _check_drive_chain(scenario, md)
    _check_events(scenario, md)
    return scenario.model_copy(update={"plant": plant, "components": fmu_components.resolve_components(scenario, FMUConfig, check_map)})


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
        from feeddrive.cosim.monitor import MonitorConfig, resolve_files
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
    raw = resolve_files(raw, base_dir) if isinstance(raw, dict) else raw  # a relative db or baseline FILE
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
    every sensor of it samples the mean (the default); bad values are left to the sections' own checks."""
    plant, sensors = data.get("plant"), data.get("sensors")
    m = plant.get("oversample", 1) if isinstance(plant, dict) else 1
    if not isinstance(m, int) or m <= 1:
        return {}
    sensors = sensors if isinstance(sensors, dict) else {}
    current = sensors.get("current")
    channels = {"voltage": [sensors.get("voltage"), sensors.get("voltage_ref")],
                "current": list(current) if isinstance(current, list) else [None, None],
                "speed": [sensors.get("tachometer")]}
    return {q: "mean" for q, chans in channels.items()
            if all((c or {}).get("sampling", "mean") == "mean" if isinstance(c, dict) or c is None else False
                   for c in chans)}


# -- the plant FMU -------------------------------------------------------------------------------

def _resolve_plant(s: Scenario) -> tuple[PlantConfig, Any]:
    p = s.plant
    if p.fmu in BUILTIN_PLANTS:
        from feeddrive.fmu_build import builtin_fmu

        path = Path(builtin_fmu(backlash=p.fmu == "builtin-backlash",
                                motor="pmsm" if p.fmu == "builtin-pmsm" else "dc")).resolve()
        # the built-in x is the table travel in the unit of its pitch: rad on a rotary axis, whatever it declares
        role_map = {r: MapEntry(var=v, unit="rad" if r == "position" and s.axis.kind == "rotary" else None)
                    for r, v in BUILTIN_MAPS[p.fmu].items()} | dict(p.map)
    else:
        path = (s.base_dir / Path(p.fmu).expanduser()).resolve()
        role_map = dict(p.map)
        if not path.is_file():
            raise s.error(("plant", "fmu"), f"FMU file not found: {path} (expected {', '.join(map(repr, BUILTIN_PLANTS))} or the path of an "
                                            ".fmu, relative to the scenario file)")
    try:
        version = fmi_version(path)
    except ValueError as exc:
        raise s.error(("plant", "fmu"), f"{path}: {exc}") from None
    if version not in ("2.0", "3.0"):
        raise s.error(("plant", "fmu"), f"{path.name} is an FMI {version or '(unknown)'} FMU; expected FMI 2.0 or 3.0")
    try:
        check_archive(path)
    except ValueError as exc:
        raise s.error(("plant", "fmu"), f"{path}: {exc}") from None
    digest = sha256(path)
    if p.sha256 and p.sha256 != digest:
        raise s.error(("plant", "sha256"), f"{path.name} has sha256 {digest}, expected {p.sha256} "
                                           "(the FMU changed since the scenario was resolved)")
    try:
        md = model_description(path)
    except ValueError as exc:
        raise s.error(("plant", "fmu"), f"{path}: {exc}") from None
    problem = runnable(md, p.interface, path.name)
    if problem:
        raise s.error(("plant", "fmu" if problem[0] == "fmu" else "interface"), problem[1])
    try:
        check_archive(path, (md.coSimulation if p.interface == "cs" else md.modelExchange).modelIdentifier)
    except ValueError as exc:
        raise s.error(("plant", "fmu"), f"{path}: {exc}") from None
    parts = {r for c in s.components if c.fmu is not None and isinstance(c.config, dict)
             for r in c.config.get("map") or {}}
    conversions: dict[str, Conversion] = {}
    problems = check_map(md, role_map, path.name, s.axis.kind, conversions, parts)
    if problems:
        raise s.error(*problems[0])
    role_map = {r: e.model_copy(update={"scale": conversions[r].scale, "offset": conversions[r].offset})
                for r, e in role_map.items()}
    s._conversions = conversions
    try:
        hold = p.hold(md)
    except ValueError as exc:
        raise s.error(("plant", "input_hold"), f"{path.name}: {exc}") from None
    variables = {v.name: v for v in md.modelVariables}
    for key, want in (("parameters", ("parameter",)), ("start", None)):
        for name in getattr(p, key):
            v = variables.get(name)
            if v is None or (want and v.causality not in want) or v.type not in REAL_TYPES:
                kinds = ", ".join(n for n, x in variables.items() if x.type in REAL_TYPES
                                  and (not want or x.causality in want))
                raise s.error(("plant", key, name), f"{path.name} has no Real "
                              f"{'parameter' if want else 'variable'} {name!r}; expected one of: {kinds}")
            _check_range(s, ("plant", key, name), v, getattr(p, key)[name], path.name)
    plant = p.model_copy(update={"fmu": str(path), "sha256": digest, "map": role_map, "input_hold": hold})
    return plant, md


def _check_drive_chain(s: Scenario, md: Any) -> None:
    """A plant FMU with ``pitch`` / ``belt_ratio`` parameters must agree with the scenario's axis (a vendor
    FMU built for a 10 mm screw under a scenario left at 20 mm would give a false encoder fault)."""
    variables = {v.name: v for v in md.modelVariables}
    for fmu_name, key in (("pitch", "pitch"), ("belt_ratio", "ratio")):
        v = variables.get(fmu_name)
        if v is None or v.causality != "parameter" or v.type not in REAL_TYPES or s.axis.kind != "linear":
            continue
        value = s.plant.parameters.get(fmu_name, v.start)
        ours = getattr(s.axis, key)
        if value not in (None, "") and not math.isclose(float(value), ours, rel_tol=1e-9):
            where = f"plant.parameters.{fmu_name}" if fmu_name in s.plant.parameters else f"the FMU's {fmu_name}"
            raise s.error(("axis", key), f"axis.{key} = {ours:g} contradicts {where} = {float(value):g}; expected "
                                         f"axis: {{{key}: {float(value):g}}}")


def _check_range(s: Scenario, key: KeyPath, variable: Any, value: float, fmu: str) -> None:
    """Refuse a value outside the [min, max] the FMU declares for the variable (bad input, not a run failure)."""
    for bound, outside in ((variable.min, lambda b: value < b), (variable.max, lambda b: value > b)):
        if bound not in (None, "") and outside(float(bound)):
            raise s.error(key, f"{variable.name} = {value:g} is outside the range [{variable.min or '-inf'}, "
                               f"{variable.max or 'inf'}] that {fmu} declares")


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
            if not isinstance(ev.value, float):
                raise s.error(("events", k, "value"), f"expected a number for plant.{param}, got {ev.value!r}")
            _check_range(s, ("events", k, "value"), v, ev.value, "the plant FMU")
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
