"""The plant of a scenario: its section (``PlantConfig``, the role map's ``MapEntry``, the built-in plants' maps),
then the FMU resolved (path, hash, role map with its units, input hold) and checked against the
rest of the scenario (drive chain, parameter ranges, the axis's drive). Called by ``cosim.scenario`` once the
scenario's sections are validated; every problem is a ScenarioError naming the file, line and key."""
from __future__ import annotations

import math
import shlex
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, field_validator

from feeddrive.cosim import fmu_inspect
from feeddrive.cosim.fmu_inspect import (
    REAL_TYPES,
    check_archive,
    fixed_step_problem,
    fmi_version,
    model_description,
    runnable,
    sha256,
)
from feeddrive.cosim.unit_map import Conversion, check_map
from feeddrive.cosim.yaml_source import KeyPath

Scenario = Any  # cosim.scenario.Scenario (which imports this module)


class Strict(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", populate_by_name=True)


Role = Literal["speed_ref", "load", "voltage", "voltage_ref", "current", "speed", "position"]
BUILTIN_MAP = {"speed_ref": "w_ref", "load": "Tl", "voltage": "u", "voltage_ref": "u_ref", "current": "i",
               "speed": "w", "position": "x"}
#: The PMSM plant's roles: the DC pipeline's voltage and current are the q axis. A DC monitor's model would be biased
#: on it (its one K cannot be both k_T = 1.5 p psi_f and k_E = p psi_f): ``axis.drive.kind: pmsm`` gives the monitor
#: the dq model (cosim/monitor_servo.py).
PMSM_MAP = BUILTIN_MAP | {"voltage": "u_q", "voltage_ref": "u_q_ref", "current": "i_q"}

class MapEntry(Strict):
    """One role <-> FMU variable conversion: ``role = scale * var + offset`` (or its inverse for inputs).

    ``scale`` and ``offset`` follow from the variable's unit (``unit`` when stated here, else the FMU's
    declaration) and the role's SI unit; given explicitly, they must agree with it (``cosim.unit_map``).
    After loading, both are set."""

    var: str
    unit: str | None = None
    scale: float | None = None
    offset: float | None = None

    @field_validator("unit")
    @classmethod
    def _unit_named(cls, v: str | None) -> str | None:
        if v is not None and not v.strip():  # read as dimensionless, it was "stated in , role 'speed' needs rad/s"
            raise ValueError("unit is empty; expected a unit such as 'rpm', or '1' for a dimensionless value")
        return v

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
#: the monitor drives each built-in plant is a model of (its design values are the monitor's nominal ones)
BUILTIN_DRIVES = {"builtin": ("dc",), "builtin-backlash": ("dc",), "builtin-pmsm": ("pmsm", "pmsm-spm")}


class PlantConfig(Strict):
    """The plant FMU. After loading, ``fmu`` is an absolute path, ``sha256`` its hash, ``map`` complete."""

    fmu: str = "builtin"
    build: str | None = Field(None, description="the command that builds plant.fmu, run in the scenario file's "
                              "folder: quoted, runnable, when the file is not found (an FMU that is not committed); never run by "
                              "cosim")
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
    _links: dict = PrivateAttr(default_factory=dict)  # an FMU component's input -> Link (cosim/fmu_components.py)
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



def resolve_plant(s: Scenario) -> tuple[PlantConfig, Any]:
    p = s.plant
    if p.fmu in BUILTIN_PLANTS:
        from feeddrive.fmu_build import builtin_fmu

        path = Path(builtin_fmu(backlash=p.fmu == "builtin-backlash",
                                motor=BUILTIN_DRIVES[p.fmu][0])).resolve()
        # the built-in x is the table travel in the unit of its pitch: rad on a rotary axis, whatever it declares
        role_map = {r: MapEntry(var=v, unit="rad" if r == "position" and s.axis.kind == "rotary" else None)
                    for r, v in BUILTIN_MAPS[p.fmu].items()} | dict(p.map)
    else:
        path = (s.base_dir / Path(p.fmu).expanduser()).resolve()
        role_map = dict(p.map)
        if not path.is_file():
            how = (f"; build it first: (cd {shlex.quote(str(s.base_dir.resolve()))} && {p.build}) (plant.build)" if p.build else
                   f" (expected {', '.join(map(repr, BUILTIN_PLANTS))} or the path of an .fmu, relative to the scenario "
                   "file; plant.build states the command that builds it)")
            raise s.error(("plant", "fmu"), f"FMU file not found: {path}{how}")
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
    problem = fixed_step_problem(md, p.interface, s.step / p.oversample, path.name)
    if problem:
        raise s.error(("step",), f"{problem} (step / plant.oversample)")
    try:
        check_archive(path, (md.coSimulation if p.interface == "cs" else md.modelExchange).modelIdentifier)
    except ValueError as exc:
        raise s.error(("plant", "fmu"), f"{path}: {exc}") from None
    parts = {r for c in s.components if c.fmu is not None and isinstance(c.config, dict)
             for r in c.config.get("map") or {}}
    conversions: dict[str, Conversion] = {}
    problems = check_map(md, role_map, path.name, s.axis.kind, conversions, parts, p.interface)
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
            check_setting(s, ("plant", key, name), v, getattr(p, key)[name], path.name)
    plant = p.model_copy(update={"fmu": str(path), "sha256": digest, "map": role_map, "input_hold": hold})
    return plant, md


def check_drive_chain(s: Scenario, md: Any) -> None:
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


def check_setting(s: Scenario, key: KeyPath, v: Any, value: float, fmu: str) -> None:
    """Refuse a ``parameters`` or ``start`` value (``key[-2]``) the FMU would refuse when the run sets it at t = 0:
    these were run failures (exit 1, "fmi2SetReal returned fmi2Error") for bad input."""
    name = v.name
    if getattr(v, "dimensions", None):  # "could not convert string to float: '1 2 3'", "Expected nValues >= 3"
        raise s.error(key, f"{fmu}: {name!r} is an array variable (FMI 3.0 Dimension); expected a scalar variable")
    if not math.isfinite(value):
        raise s.error(key, f"{name} = {value} is not a finite number; expected a finite value")
    if key[-2] == "start" and (v.start in (None, "") or v.causality == "independent" or v.variability == "constant"):
        # "n_mot is calculated by the FMU and cannot be set"
        raise s.error(key, f"{fmu} calculates {name!r} (causality {v.causality}, no start value): it cannot be set; "
                           "expected a variable with a start value (a state, a parameter, an input)")
    check_range(s, key, v, value, fmu)


def check_input_ranges(s: Scenario, md: Any) -> None:
    """Refuse an NC program whose motor speed (or load torque) leaves the [min, max] the plant FMU declares for the
    input it is mapped to: FMI forbids setting an input outside its range (a vendor FMU clips it, or fails), and the
    run gave no sign of it (660 rpm into an input declared up to 500 rpm: a healthy verdict). The program's planned
    peak is checked (the position loop's correction comes on top), and the identification motion the monitor may
    insert."""
    from feeddrive.cosim.nc import plan_program

    plan, nc = plan_program(s.nc), s.nc
    peaks: dict[str, tuple[float, KeyPath]] = {"speed_ref": (0.0, ()), "load": (0.0, ())}
    for seg, nxt in zip(plan, plan[1:]):
        key = ("nc", "program", seg[6]) if seg[6] >= 0 else ("nc",)
        v = max(abs(seg[2]), abs(seg[2] + seg[3] * (nxt[0] - seg[0])))
        w = v * 2 * math.pi * nc.belt_ratio / nc.pitch  # the NC's table speed -> motor speed [rad/s]
        for role, value in (("speed_ref", w), ("load", abs(seg[5]))):
            if value > peaks[role][0]:
                peaks[role] = (value, key)
    if s.monitor is not None and nc.identification is not None:
        w = nc.identification.v_max * 2 * math.pi * nc.belt_ratio / nc.pitch
        if w > peaks["speed_ref"][0]:
            peaks["speed_ref"] = (w, ("nc", "identification", "v_max"))
    variables = {v.name: v for v in md.modelVariables}
    for role, (peak, key) in peaks.items():
        entry, v = s.plant.map.get(role), None
        v = variables.get(entry.var) if entry is not None else None
        if v is None or not key or (v.min in (None, "") and v.max in (None, "")):
            continue
        scale, offset = entry.linear()
        lo, hi = sorted((offset - scale * peak, offset + scale * peak))  # the FMU's values for -peak and +peak
        for bound, outside, value in ((v.min, lambda b: lo < float(b), lo), (v.max, lambda b: hi > float(b), hi)):
            if bound not in (None, "") and outside(bound):
                what = f"a motor speed of {peak:.5g} rad/s" if role == "speed_ref" else f"a load of {peak:.5g} N.m"
                raise s.error(key, f"the NC program asks {what}: {entry.var} = {value:.5g} (x {scale:.5g}), outside the "
                                   f"range [{v.min or '-inf'}, {v.max or 'inf'}] that {Path(s.plant.fmu).name} declares "
                                   f"for its input (FMI: never set outside it); expected slower motions (a lower v_max) "
                                   "or an FMU whose input allows them")


def check_range(s: Scenario, key: KeyPath, variable: Any, value: float, fmu: str) -> None:
    """Refuse a value outside the [min, max] the FMU declares for the variable (bad input, not a run failure)."""
    for bound, outside in ((variable.min, lambda b: value < b), (variable.max, lambda b: value > b)):
        if bound not in (None, "") and outside(float(bound)):
            low, strict = f"[{variable.min or '-inf'}", ""
            if variable.min not in (None, "") and float(variable.min) == math.nextafter(0.0, 1.0):  # a strict bound
                low, strict = "(0", f" (min {variable.min}, the smallest double above 0: {variable.name} > 0)"
            raise s.error(key, f"{variable.name} = {value:g} is outside the range {low}, "
                               f"{variable.max or 'inf'}] that {fmu} declares{strict}")
