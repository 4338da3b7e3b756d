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

A scenario without ``nc:`` is a system of components only (e.g. foreign FMUs run alone, as the
conformance tests run the Modelica Reference-FMUs): no NC, plant, sensors or monitor; ``stop_time``
is then required.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from pydantic import ValidationError

from feeddrive.cosim.fmu_inspect import REAL_TYPES, check_archive, fmi_version, model_description, runnable, sha256
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
    out = []
    for k, spec in enumerate(s.components):
        if (spec.fmu is None) == (spec.class_ is None):
            raise s.error(("components", k), f"component {spec.name!r}: expected exactly one of class: or fmu:")
        out.append(spec if spec.fmu is None else _resolve_fmu(s, k, spec, config_class, check_map))
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
    try:
        check_archive(path, (md.coSimulation if cfg.interface == "cs" else md.modelExchange).modelIdentifier)
        hold = cfg.hold(md)
    except ValueError as exc:
        raise s.error((*where, "fmu"), f"{path}: {exc}") from None
    # a role map here may be partial (a plant split into FMUs): only its entries are checked
    problems = [p for p in check_map(md, cfg.map, path.name) if p[0] != ("plant", "map")]
    if problems:
        key, message = problems[0]
        raise s.error((*where, "config", *key[1:]), message)
    variables = {v.name: v for v in md.modelVariables}
    for key in ("parameters", "start"):
        for name in getattr(cfg, key):
            v = variables.get(name)
            if v is None or v.type not in REAL_TYPES or (key == "parameters" and v.causality != "parameter"):
                raise s.error((*where, "config", key, name), f"{path.name} has no Real "
                                                             f"{'parameter' if key == 'parameters' else 'variable'} {name!r}")
    for j, ev in enumerate(s.events):
        comp, _, param = ev.target.partition(".")
        v = variables.get(param) if comp == spec.name else None
        if comp == spec.name and (v is None or v.causality != "parameter" or v.variability != "tunable"
                                  or v.type not in REAL_TYPES or not isinstance(ev.value, float)):
            raise s.error(("events", j), f"{param!r} is not a tunable Real parameter of {path.name} (or the value "
                                         f"{ev.value!r} is not a number)")
    cfg = cfg.model_copy(update={"fmu": str(path), "sha256": sha256(path), "input_hold": hold})
    return spec.model_copy(update={"config": cfg})
