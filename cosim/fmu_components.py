"""FMU components of a scenario: ``components:`` entries with ``fmu:`` instead of ``class:``.

::

    components:
      - name: mechanics
        fmu: Mechanics.fmu                 # FMI 2.0 or 3.0, relative to the scenario file
        config: {interface: me, step_multiple: 2, parameters: {J: 0.01}, call_timeout: 10}
        inputs: {tau: drive.tau}           # port: component.output (or a number)

``config`` takes the keys of ``plant:`` (interface, tolerance, call_timeout, parameters, start, map,
input_hold) plus ``step_multiple``: the FMU's communication step in ticks of the master's finest step
(``step / plant.oversample``); default one recording ``step``. Its ports are the FMU's Real / Float64
inputs and its numeric outputs under their own names (cosim/fmu_ports.py), after the roles of ``map``
when it has one. A plant split into several FMUs maps each role where it lives: ``plant.map`` the drive's
roles, a component's ``map`` the others (e.g. ``position``); such a part steps right after the plant, at
the plant's rate (default), and the NC and the sensors read the roles the plant lacks from it.

Units on every connection into an FMU component (``inputs:`` or ``connections:``): the source's unit
(an FMU component's output variable or role, the plant's roles, the NC's and the sensors' outputs) and
the input's (the FMU's declared unit, or the role's SI unit) are compared with pint when the scenario is
loaded; a different scale (``rpm`` into ``rad/s``, ``mm`` into ``m``) is converted at the input like a
role map entry (``x_fmu = scale * source + offset``), another dimension is refused with one line naming
the connection. A source whose unit is known only at run time (a ``class:`` component) is checked by the
master (cosim/port_units.py). ``cosim info FMU --map SCENARIO`` lists each link and its conversion.

A scenario without ``nc:`` is a system of components only (e.g. foreign FMUs run alone, as the
conformance tests run the Modelica Reference-FMUs): no NC, plant, sensors or monitor; ``stop_time``
is then required.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from feeddrive.cosim.fmu_inspect import (
    REAL_TYPES,
    check_archive,
    fixed_step_problem,
    fmi_version,
    model_description,
    runnable,
    sha256,
)
from feeddrive.cosim.fmu_ports import unit_of
from feeddrive.cosim.scenario_plant import check_setting
from feeddrive.cosim.unit_map import ROLE_UNITS, role_unit
from feeddrive.cosim.yaml_source import from_validation

#: top-level keys a components-only scenario (no ``nc:``) cannot have
DRIVE_KEYS = ("plant", "sensors", "monitor", "axis")


def check_components_only(s: Any, data: dict) -> None:
    """A scenario without ``nc:``: only components, at least one, and a ``stop_time``."""
    given = [k for k in DRIVE_KEYS if k in data and data[k] is not None]
    if given:
        raise s.error((given[0],), f"a scenario without nc: is a system of components only; expected no "
                                   f"{given[0]}: (or add an nc: program to run the drive)")
    if not s.components:
        raise s.error(("components",), "a scenario without nc: needs components; expected entries with fmu: or class:")
    if s.stop_time is None:
        raise s.error(("stop_time",), "a scenario without nc: has no NC program to end it; expected stop_time [s]")
    if s.step > s.stop_time:
        raise s.error(("step",), f"{s.step:g} s is longer than the run ({s.stop_time:g} s); expected a "
                                 "communication step <= the stop time")


def resolve_components(s: Any, config_class: type, check_map: Any) -> list:
    """The scenario's components with each ``fmu:`` entry's config checked and resolved (path, sha256).

    ``config_class`` is ``cosim.scenario.FMUConfig`` and ``check_map`` ``cosim.scenario.check_map``
    (passed in: the scenario module imports this one)."""
    out, descriptions = [], {}
    for k, spec in enumerate(s.components):
        if (spec.fmu is None) == (spec.class_ is None):
            raise s.error(("components", k), f"component {spec.name!r}: expected exactly one of class: or fmu:")
        if spec.fmu is not None:
            spec, descriptions[spec.name] = _resolve_fmu(s, k, spec, config_class, check_map)
        out.append(spec)
    _link_units(s, out, descriptions)
    return out


def _resolve_fmu(s: Any, k: int, spec: Any, cls: type, check_map: Any) -> Any:
    where = ("components", k)
    try:
        cfg = cls.model_validate(spec.config)
    except ValidationError as exc:
        raise from_validation(exc, spec.config, s.source, s._lines, prefix=(*where, "config"), model=cls) from None
    path = (s.base_dir / Path(spec.fmu).expanduser()).resolve()
    if not path.is_file():
        raise s.error((*where, "fmu"), f"FMU file not found: {path} (expected the path of an .fmu, relative to "
                                       "the scenario file)")
    try:
        version = fmi_version(path)
        if version not in ("2.0", "3.0"):
            raise ValueError(f"{path.name} is an FMI {version or '(unknown)'} FMU; expected FMI 2.0 or 3.0")
        check_archive(path)
        md = model_description(path)
    except ValueError as exc:
        raise s.error((*where, "fmu"), str(exc) if str(exc).startswith(path.name) else f"{path}: {exc}") from None
    problem = runnable(md, cfg.interface, path.name)
    if problem:
        raise s.error((*where, "fmu" if problem[0] == "fmu" else "config"), problem[1])
    # its rate as the master gives it (cosim/master.py): step_multiple ticks of the finest step, else the
    # plant's rate for a part of the plant, else the recording step
    oversample = s.plant.oversample if s.plant is not None else 1
    ticks = cfg.step_multiple or (1 if cfg.map and s.nc is not None else oversample)
    problem = fixed_step_problem(md, cfg.interface, s.step / oversample * ticks, path.name)
    if problem:
        raise s.error((*where, "config", "step_multiple") if cfg.step_multiple else ("step",), problem)
    try:
        check_archive(path, (md.coSimulation if cfg.interface == "cs" else md.modelExchange).modelIdentifier)
        hold = cfg.hold(md)
    except ValueError as exc:
        raise s.error((*where, "fmu"), f"{path}: {exc}") from None
    # a role map here may be partial (a plant split into FMUs): only its entries are checked, and each one
    # converted by its units as the plant's are (n_mot [rpm] -> speed x 0.10472)
    conversions: dict = {}
    problems = [p for p in check_map(md, cfg.map, path.name, s.axis.kind, conversions, interface=cfg.interface) if p[0] != ("plant", "map")]
    if problems:
        key, message = problems[0]
        raise s.error((*where, "config", *key[1:]), message)
    role_map = {r: e.model_copy(update={"scale": conversions[r].scale, "offset": conversions[r].offset})
                for r, e in cfg.map.items()}
    variables = {v.name: v for v in md.modelVariables}
    for key in ("parameters", "start"):
        for name in getattr(cfg, key):
            v = variables.get(name)
            if v is None or v.type not in REAL_TYPES or (key == "parameters" and v.causality != "parameter"):
                raise s.error((*where, "config", key, name), f"{path.name} has no Real "
                                                             f"{'parameter' if key == 'parameters' else 'variable'} {name!r}")
            check_setting(s, (*where, "config", key, name), v, getattr(cfg, key)[name], path.name)
    for j, ev in enumerate(s.events):
        comp, _, param = ev.target.partition(".")
        v = variables.get(param) if comp == spec.name else None
        if comp == spec.name and (v is None or v.causality != "parameter" or v.variability != "tunable"
                                  or v.type not in REAL_TYPES or not isinstance(ev.value, float)
                                  or not math.isfinite(ev.value)):
            raise s.error(("events", j), f"{param!r} is not a tunable Real parameter of {path.name} (or the value "
                                         f"{ev.value!r} is not a number)")
    cfg = cfg.model_copy(update={"fmu": str(path), "sha256": sha256(path), "input_hold": hold, "map": role_map})
    return spec.model_copy(update={"config": cfg}), md


@dataclass(frozen=True)
class Link:
    """One input port of an FMU component and its source: the FMU gets ``scale * source + offset``.

    ``unit`` is the port's unit ('' when the FMU declares none), ``source_unit`` the source's (None when
    not known before the run: a number, or a ``class:`` component's output)."""

    port: str
    unit: str
    source: str | float
    source_unit: str | None
    scale: float = 1.0
    offset: float = 0.0

    def describe(self) -> str:
        """``n_set [rpm] <- a.w [rad/s] x 9.5493`` (what ``cosim info --map`` prints)."""
        text = f"{self.port} [{self.unit or '?'}] <- {self.source}"
        if not isinstance(self.source, str):
            return text + " (a constant)"
        if self.source_unit is None:
            return text + "  (unit known at run time: checked by the master, not converted)"
        text += f" [{self.source_unit or '?'}]"
        if (self.scale, self.offset) != (1.0, 0.0):
            text += f" x {self.scale:.5g}" + (f" {'+' if self.offset >= 0 else '-'} {abs(self.offset):.5g}"
                                               if self.offset else "")
        return text


def _output_unit(s: Any, fmus: dict, descriptions: dict, source: str) -> str | None:
    """The unit of ``component.output`` when the scenario alone says it (None: known at run time only)."""
    from feeddrive.cosim.nc import NCComponent
    from feeddrive.cosim.sensors import SensorsComponent

    comp, _, port = source.partition(".")
    if comp in fmus:
        if port in fmus[comp].config.map:
            return role_unit(port, s.axis.kind)
        v = {v.name: v for v in descriptions[comp].modelVariables}.get(port.split("[")[0])
        return unit_of(v) if v is not None else None
    if s.nc is None:
        return None
    if comp == "plant" and port.removesuffix("_mean") in ROLE_UNITS:
        return role_unit(port.removesuffix("_mean"), s.axis.kind)
    known = {"nc": NCComponent, "sensors": SensorsComponent}.get(comp)
    return dict(zip(known.output_names, known.output_units)).get(port) if known is not None else None


def _link_units(s: Any, specs: list, descriptions: dict) -> None:
    """Each FMU component's input links (``config._links``), their units compared and converted with pint."""
    from feeddrive.cosim.unit_map import _affine, angle_mismatch

    fmus = {spec.name: spec for spec in specs if spec.fmu is not None}
    for k, spec in enumerate(specs):
        if spec.fmu is None:
            continue
        cfg, links = spec.config, {}
        variables = {v.name: v for v in descriptions[spec.name].modelVariables}
        given = {dst.partition(".")[2]: (("connections", dst), src) for dst, src in s.connections.items()
                 if dst.partition(".")[0] == spec.name}
        given |= {port: (("components", k, "inputs", port), src) for port, src in spec.inputs.items()}
        for port, (key, src) in given.items():
            v = variables.get(port.split("[")[0])
            unit = role_unit(port, s.axis.kind) if port in cfg.map else (unit_of(v) if v is not None else "")
            su = _output_unit(s, fmus, descriptions, src) if isinstance(src, str) else None
            scale, offset = 1.0, 0.0
            if su and unit and su != unit:
                import pint  # only here: its import is not free

                try:
                    scale, offset = _affine(su, None, unit)  # x_fmu = scale * source + offset
                    angle = angle_mismatch(su, unit)
                except pint.errors.DimensionalityError:
                    raise s.error(key, f"{src} -> {spec.name}.{port}: unit {su!r} does not convert to {unit!r} "
                                       f"(another dimension); expected a source in a unit convertible to {unit}") from None
                except (pint.errors.PintError, ValueError, TypeError, AttributeError, SyntaxError, AssertionError):
                    raise s.error(key, f"{src} -> {spec.name}.{port}: cannot compare units {su!r} and {unit!r} "
                                       "(unknown to pint); expected units pint knows (state them in the FMU)") from None
                if angle is not None:  # pint converts Hz into rad/s by 1
                    raise s.error(key, f"{src} -> {spec.name}.{port}: unit {su!r} into {unit!r}: {angle}; expected "
                                       "units that say it (rpm: revolutions per minute, rad/s: radians per second)")
            links[port] = Link(port, unit, src, su, scale, offset)
        cfg._links = links


def convert_links(names: tuple, units: tuple, lin: list, links: dict) -> tuple[tuple, list]:
    """An FMU component's input units and ``(index, scale, offset)`` conversions with its links applied: a port
    fed in another unit declares the source's unit (the master's check passes) and converts it (role map after
    link: ``x = s (a source + b) + o``)."""
    units, lin = list(units), list(lin)
    for k, port in enumerate(names):
        link = links.get(port)
        if link is not None and link.source_unit and (link.scale, link.offset) != (1.0, 0.0):
            i, scale, offset = lin[k]
            lin[k] = (i, scale * link.scale, scale * link.offset + offset)
            units[k] = link.source_unit
    return tuple(units), lin
