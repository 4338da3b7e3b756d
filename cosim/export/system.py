"""A scenario as a system description that OSP's tools (libcosim, cosim-cli) and SSP tools read.

``export_system`` writes into one folder::

    FeedDrive.fmu (the plant, copied)   FeedDriveNC.fmu   FeedDriveSensors.fmu   FeedDriveMonitor.fmu
    OspSystemStructure.xml   simulators nc, plant, sensors, monitor and the FMU components (``fmu:``,
                             copied as they are, each with its ``step_multiple`` as its stepSize);
                             the scenario's step as BaseStepSize;
                             the plant's parameters and start values and the monitor's history file as
                             initial values; every connection of ``cosim run`` (its default wiring plus
                             the scenario's ``connections``; a constant source becomes an initial value)
    OspScenario.json         the timed events as libcosim ``override`` events (plant parameters, sensor
                             faults ``sensors.Im1.gain`` -> variable ``Im1.gain`` of ``sensors``), and
                             the stop time as ``end``
    <name>.ssp               optional: the same system as an SSP 1.0 archive (SystemStructure.ssd and
                             the FMUs in resources/)

What another master does differently from ``cosim run`` (and the README repeats): libcosim's
fixedStep algorithm exchanges values between steps (Jacobi), not in the NC -> plant -> sensors ->
monitor order, so each connection adds one step of delay; and no master here sets the plant's input
derivatives, so the plant holds its speed reference over each step (``input_hold: zoh``).
"""
from __future__ import annotations

import json
import shutil
import zipfile
from pathlib import Path
from typing import Any
from xml.dom import minidom
from xml.etree.ElementTree import Element, SubElement, tostring

from feeddrive.cosim.export.build import KINDS, ExportError, build_component_fmu, section
from feeddrive.cosim.master import default_connections, event_step
from feeddrive.cosim.monitor import Monitor
from feeddrive.cosim.nc import SETTLING, NCComponent, plan_program
from feeddrive.cosim.scenario import INPUT_ROLES, OUTPUT_ROLES, Scenario
from feeddrive.cosim.sensors import SensorsComponent

OSP_NS = "http://opensimulationplatform.com/MSMI/OSPSystemStructure"
SSD_NS = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC_NS = "http://ssp-standard.org/SSP1/SystemStructureCommon"
SSV_NS = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
SYSTEM_FILE = "OspSystemStructure.xml"
SCENARIO_FILE = "OspScenario.json"
#: simulator name -> component class of the project (the plant is the scenario's FMU)
COMPONENTS = {"nc": NCComponent, "sensors": SensorsComponent, "monitor": Monitor}


def stop_time(scenario: Scenario) -> float:
    """The run's stop time as ``cosim run`` computes it: whole steps up to ``stop_time`` or the NC program + SETTLING."""
    stop = scenario.stop_time if scenario.stop_time is not None else plan_program(scenario.nc)[-1][0] + SETTLING
    return float(f"{event_step(stop, 0.0, scenario.step) * scenario.step:.12g}")  # drop n*h rounding


def wiring(scenario: Scenario) -> tuple[list[tuple[str, str, str, str]], dict[str, dict[str, float]]]:
    """The system's connections ``(source simulator, variable, target simulator, variable)`` and the constant
    inputs ``{simulator: {variable: value}}``, with plant roles translated to the FMU's variables.

    Raises
    ------
    ExportError
        User components (``components:``), or a map with a scale or offset, or an FMU component's input
        converted from its source's unit (OSP connections are plain assignments).
    """
    classes = [c.name for c in scenario.components if c.fmu is None]
    if classes:
        raise ExportError(f"{scenario.source}: components: user components ({classes[0]}, ...) cannot be exported; "
                          "expected nc, plant, sensors, monitor and FMU components (fmu:)")
    if scenario.nc is None:
        raise ExportError(f"{scenario.source}: no nc: a system of components only is not exported; expected a drive")
    # the exported system runs every FMU at the one BaseStepSize: one rate only
    if scenario.plant.oversample != 1:
        raise ExportError(f"{scenario.source}: plant.oversample: {scenario.plant.oversample}; the exported system "
                          "steps every FMU at `step`, expected 1 (or export a scenario with step = step / oversample)")
    if scenario.nc.cycle is not None and abs(scenario.nc.cycle - scenario.step) > 1e-9 * scenario.step:
        raise ExportError(f"{scenario.source}: nc.cycle: {scenario.nc.cycle:g} s; the exported system steps the NC "
                          f"at `step` = {scenario.step:g} s, expected no nc.cycle")
    maps = {"plant": scenario.plant.map} | {c.name: c.config.map for c in scenario.components}
    for comp, role_map in maps.items():
        for role, entry in role_map.items():
            if entry.scale != 1.0 or entry.offset != 0.0:
                key = "plant" if comp == "plant" else f"components[{comp}].config"
                raise ExportError(f"{scenario.source}: {key}.map.{role}: scale {entry.scale:g} and offset "
                                  f"{entry.offset:g}; an OSP connection cannot convert units, expected scale 1 and "
                                  "offset 0 (or an FMU in SI units)")
    converted = [(c.name, x) for c in scenario.components if c.fmu is not None for x in c.config._links.values()
                 if (x.scale, x.offset) != (1.0, 0.0)]
    if converted:
        name, x = converted[0]
        raise ExportError(f"{scenario.source}: components[{name}].inputs.{x.port}: {x.source} [{x.source_unit}] into "
                          f"[{x.unit}] is converted (x {x.scale:.5g}); an OSP connection cannot convert units, "
                          "expected the same unit on both sides")
    ports = {n: (tuple(c.input_names), tuple(c.output_names)) for n, c in COMPONENTS.items()}
    ports["plant"] = (tuple(r for r in INPUT_ROLES if r in maps["plant"]),
                      tuple(r for r in OUTPUT_ROLES if r in maps["plant"]))
    ports |= {c.name: fmu_ports(c) for c in scenario.components}
    if scenario.monitor is None:
        del ports["monitor"]
    parts = [c.name for c in scenario.components if c.config.map]
    connections = default_connections(ports, parts) | dict(scenario.connections)
    connections |= {f"{c.name}.{port}": src for c in scenario.components for port, src in c.inputs.items()}

    def variable(comp: str, port: str) -> str:
        role_map = maps.get(comp, {})
        return role_map[port].var if port in role_map else port

    links, constants = [], {}
    for dst, src in connections.items():
        d_comp, _, d_port = dst.partition(".")
        if d_comp not in ports or d_port not in ports[d_comp][0]:
            raise ExportError(f"{scenario.source}: connections.{dst}: no such input; expected one of "
                              f"{', '.join(f'{n}.{p}' for n, (i, _) in ports.items() for p in i)}")
        if isinstance(src, str):
            s_comp, _, s_port = src.partition(".")
            if s_comp not in ports or s_port not in ports[s_comp][1]:
                raise ExportError(f"{scenario.source}: connections.{dst}: unknown source {src!r}")
            links.append((s_comp, variable(s_comp, s_port), d_comp, variable(d_comp, d_port)))
        else:
            constants.setdefault(d_comp, {})[variable(d_comp, d_port)] = float(src)
    return links, constants


def fmu_ports(spec: Any) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """An FMU component's (inputs, outputs) as ``cosim run`` names them, from its model description."""
    from feeddrive.cosim import fmu_ports as ports
    from feeddrive.cosim.fmu_inspect import model_description

    md = model_description(Path(spec.config.fmu))
    role_map = spec.config.map
    mapped = {e.var for e in role_map.values()}
    own = ports.own_inputs(md, mapped, spec.config.interface)
    extras, others = ports.extra_outputs(md, mapped | set(OUTPUT_ROLES + INPUT_ROLES))
    if any(v.is_array for v in own + extras + others):
        raise ExportError(f"{spec.config.fmu}: array variables are not exported (OSP connects scalars)")
    return (tuple(r for r in INPUT_ROLES if r in role_map) + tuple(v.name for v in own),
            tuple(r for r in OUTPUT_ROLES if r in role_map) + tuple(v.name for v in extras + others))


def osp_events(scenario: Scenario) -> list[dict]:
    """The scenario's timed events as libcosim scenario events (``override`` of a parameter)."""
    events = []
    for ev in scenario.events:
        comp, _, name = ev.target.partition(".")
        events.append({"time": ev.time, "model": comp, "variable": name, "action": "override", "value": ev.value})
    return events


def export_system(scenario: Scenario, out_dir: str | Path, *, ssp: bool = True, overwrite: bool = False
                  ) -> dict[str, Path]:
    """Write the FMUs, OspSystemStructure.xml, OspScenario.json and (``ssp``) an SSP archive of a scenario.

    Parameters
    ----------
    scenario : Scenario
    out_dir : path
        Folder for everything (created); must not hold an earlier export unless ``overwrite``.
    ssp : bool
        Also write ``<scenario name>.ssp``.
    overwrite : bool
        Replace the files of an earlier export.

    Returns
    -------
    dict
        ``system``, ``scenario``, ``ssp`` (when written) and each simulator name -> Path.

    Raises
    ------
    ExportError
        A scenario that cannot be expressed (see ``wiring``) or files in the way without ``overwrite``.
    """
    out_dir = Path(out_dir)
    links, constants = wiring(scenario)
    kinds = [k for k in KINDS if k != "monitor" or scenario.monitor is not None]
    for kind in kinds:
        section(scenario, kind)  # refuse an unexportable monitor before building anything
    plant_src = Path(scenario.plant.fmu)
    plant_dst = out_dir / plant_src.name
    if plant_src.stem in {KINDS[k][0] for k in KINDS}:
        raise ExportError(f"{scenario.source}: plant.fmu: {plant_src.name} clashes with an exported FMU's name")
    fmus = {c.name: Path(c.config.fmu) for c in scenario.components}  # FMU components, copied as they are
    names = [plant_src.name] + [p.name for p in fmus.values()]
    clash = next((n for n in names if names.count(n) > 1 or Path(n).stem in {KINDS[k][0] for k in KINDS}), None)
    if clash:
        raise ExportError(f"{scenario.source}: {clash} is used twice or clashes with an exported FMU's name")
    in_the_way = [p for p in (out_dir / SYSTEM_FILE, out_dir / SCENARIO_FILE, plant_dst,
                              *(out_dir / p.name for p in fmus.values())) if p.exists()]
    if in_the_way and not overwrite:
        raise ExportError(f"{in_the_way[0]} exists; choose another --out folder or allow overwriting (--overwrite)")
    out_dir.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {"plant": plant_dst}
    shutil.copyfile(plant_src, plant_dst)
    for name, src in fmus.items():
        paths[name] = out_dir / src.name
        shutil.copyfile(src, paths[name])
    for kind in kinds:
        paths[kind] = build_component_fmu(kind, scenario, out_dir, overwrite=overwrite)
    initial = {"plant": dict(scenario.plant.parameters) | dict(scenario.plant.start)}
    initial |= {c.name: dict(c.config.parameters) | dict(c.config.start) for c in scenario.components}
    for comp, values in constants.items():
        initial.setdefault(comp, {}).update(values)
    strings = {"monitor": {"db": section(scenario, "monitor")["db"]}} if "monitor" in kinds else {}
    sources = {name: p.name for name, p in paths.items()}
    order = ["nc", "plant", "sensors", "monitor", *fmus]
    sims = [n for n in order if n in sources]
    multiple = {c.name: c.config.step_multiple or 1 for c in scenario.components}  # OSP: stepSize per simulator
    root = Element("OspSystemStructure", xmlns=OSP_NS, version="0.1")
    SubElement(root, "StartTime").text = "0.0"
    SubElement(root, "BaseStepSize").text = repr(scenario.step)
    SubElement(root, "Algorithm").text = "fixedStep"
    simulators = SubElement(root, "Simulators")
    for name in sims:
        sim = SubElement(simulators, "Simulator", name=name, source=sources[name],
                         stepSize=repr(scenario.step * multiple.get(name, 1)))
        values = [(v, "Real", x) for v, x in initial.get(name, {}).items()]
        values += [(v, "String", x) for v, x in strings.get(name, {}).items()]
        if values:
            iv = SubElement(sim, "InitialValues")
            for var, typ, value in values:
                SubElement(SubElement(iv, "InitialValue", variable=var), typ,
                           value=repr(float(value)) if typ == "Real" else str(value))
    conns = SubElement(root, "Connections")
    for s_comp, s_var, d_comp, d_var in links:
        c = SubElement(conns, "VariableConnection")
        SubElement(c, "Variable", simulator=s_comp, name=s_var)
        SubElement(c, "Variable", simulator=d_comp, name=d_var)
    paths["system"] = out_dir / SYSTEM_FILE
    paths["system"].write_bytes(minidom.parseString(tostring(root)).toprettyxml(indent="  ", encoding="utf-8"))
    stop = stop_time(scenario)
    paths["scenario"] = out_dir / SCENARIO_FILE
    paths["scenario"].write_text(json.dumps({
        "description": f"timed events of scenario {scenario.name} ({scenario.source}), exported by cosim export-system",
        "events": osp_events(scenario), "end": stop}, indent=2), encoding="utf-8")
    if ssp:
        paths["ssp"] = write_ssp(scenario, out_dir, sims, sources, links, initial, strings, stop)
    return paths


def write_ssp(scenario: Scenario, out_dir: Path, sims: list[str], sources: dict[str, str],
              links: list[tuple[str, str, str, str]], initial: dict, strings: dict, stop: float) -> Path:
    """``<name>.ssp``: SystemStructure.ssd (components, inline parameter values, connections, the default
    experiment) and the FMUs in resources/. SSP 1.0 has no communication step: the reader passes it (for
    libcosimpy, ``CosimExecution.from_ssp_file(path, step_size)``)."""
    ns = {"xmlns:ssd": SSD_NS, "xmlns:ssc": SSC_NS, "xmlns:ssv": SSV_NS}
    root = Element("ssd:SystemStructureDescription", ns | {"version": "1.0", "name": scenario.name})
    system = SubElement(root, "ssd:System", name=scenario.name)
    elements = SubElement(system, "ssd:Elements")
    for name in sims:
        comp = SubElement(elements, "ssd:Component", name=name, source=f"resources/{sources[name]}",
                          type="application/x-fmu-sharedlibrary")
        values = [(v, "Real", x) for v, x in initial.get(name, {}).items()]
        values += [(v, "String", x) for v, x in strings.get(name, {}).items()]
        # SSP readers (libcosim) resolve connections and parameter values through declared connectors
        connectors = {d_var: "input" for _, _, d, d_var in links if d == name}
        connectors |= {s_var: "output" for s, s_var, _, _ in links if s == name}
        connectors |= {var: ("parameter", typ) for var, typ, _ in values if var not in connectors}
        if connectors:
            node = SubElement(comp, "ssd:Connectors")
            for var, kind in connectors.items():
                kind, typ = kind if isinstance(kind, tuple) else (kind, "Real")
                SubElement(SubElement(node, "ssd:Connector", name=var, kind=kind), f"ssc:{typ}")
        if values:
            binding = SubElement(SubElement(comp, "ssd:ParameterBindings"), "ssd:ParameterBinding")
            pset = SubElement(SubElement(binding, "ssd:ParameterValues"), "ssv:ParameterSet", version="1.0",
                              name=f"{name}-initial-values")
            params = SubElement(pset, "ssv:Parameters")
            for var, typ, value in values:
                SubElement(SubElement(params, "ssv:Parameter", name=var), f"ssv:{typ}",
                           value=repr(float(value)) if typ == "Real" else str(value))
    conns = SubElement(system, "ssd:Connections")
    for s_comp, s_var, d_comp, d_var in links:
        SubElement(conns, "ssd:Connection", startElement=s_comp, startConnector=s_var, endElement=d_comp,
                   endConnector=d_var)
    SubElement(root, "ssd:DefaultExperiment", startTime="0.0", stopTime=repr(stop))
    path = out_dir / f"{scenario.name}.ssp"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("SystemStructure.ssd", minidom.parseString(tostring(root)).toprettyxml(indent="  ",
                                                                                         encoding="utf-8"))
        for name in sims:
            z.write(out_dir / sources[name], f"resources/{sources[name]}")
    return path
