"""pythonfmu slaves wrapping the project's components (NC, sensors, monitor) as FMI 2.0 Co-Simulation FMUs.

An exported FMU holds, in its ``resources/`` folder, a two-line script naming one of the classes below
and ``component.json``: the component kind, its name, the scenario's communication step and the full
scenario section (``nc:``, ``sensors:`` or ``monitor:``, every default filled in). The FMU runs the
component through its public interface (cosim/component.py)::

    fmi2Instantiate            read component.json; ports and parameters are declared from it
    fmi2SetReal/Integer/...    parameters: the section's numeric and boolean keys (kv, seed, alpha, ...)
                               and the monitor's history file ``db``
    fmi2ExitInitializationMode section | parameters -> the component's frozen config; setup(t0, h, N)
    fmi2DoStep(t, h)           set_inputs(inputs); step(n), n = round((t - t0) / h); outputs
    fmi2Terminate              terminate()

The communication step must be the component's ``step_size`` parameter (the scenario's step): the
sensors' encoder window, the NC's feed-forward and the monitor's derivatives are built on it; another
step is refused with fmi2Error and a log message. Sensor channels' ``gain``, ``offset`` and ``noise``
(``Im1.gain``, ...) are tunable: a change after initialisation is a sensor fault event
(``SensorsComponent.set_parameter``), which is how OSP scenario files inject faults.

The monitor FMU adds, per completed motion, the outputs listed in ``MONITOR_OUTPUTS`` and writes its
history to the SQLite file of the string parameter ``db`` and ``{"axis", "db", "motions": [...]}``
(the per-motion dicts of report.json) to ``<db without suffix>.report.json`` beside it.
"""
from __future__ import annotations

import json
import typing
from pathlib import Path
from typing import Any, ClassVar
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability
from pythonfmu.enums import Fmi2Status
from pythonfmu.variables import Boolean, Integer, Real, String

#: file in the FMU's resources/ holding the component's kind, name, step and scenario section
CONFIG_FILE = "component.json"
#: steps announced to ``Component.setup`` (an FMU does not know its stop time; the components only use
#: it to size buffers, which they cap by their own limits)
OPEN_END_STEPS = 2**31
#: the string keys that become FMU parameters; the others (axis, scenario, method) stay in component.json:
#: libcosim reads every variable of an FMU at every step, and a string costs it ~40 us there (measured:
#: the monitor FMU alone 310 us per step with four string parameters, 137 us without)
STRING_PARAMETERS = ("db",)
#: the six estimated parameters, in the order of the monitor FMU's outputs
PARAMETERS = ("R", "L", "K", "Jt", "ft", "Cd")
PARAMETER_UNITS = {"R": "Ohm", "L": "H", "K": "N.m/A", "Jt": "kg.m2", "ft": "N.m.s/rad", "Cd": "N.m"}
#: the six measured signals a sensor-fault flag can name (estimator.validation.PAIRS)
FAULT_SENSORS = ("Im1", "Im2", "u", "u_ref", "w_tach", "w_enc")


def monitor_outputs() -> list[tuple[str, str, str, str]]:
    """The monitor FMU's outputs after ``request``: (name, FMI type, unit, description)."""
    out = [("validated", "Integer", "1", "1 when the last completed motion was validated")]
    out += [(p, "Real", PARAMETER_UNITS[p], f"estimate of {p} in the last completed motion") for p in PARAMETERS]
    out += [(f"{p}_std", "Real", PARAMETER_UNITS[p], f"standard error of {p}") for p in PARAMETERS]
    out += [(f"fault_{s}", "Integer", "1", f"1 when sensor {s} was found faulty in the last motion")
            for s in FAULT_SENSORS]
    out += [("mismatch", "Integer", "1", "1 when the model check of the last motion failed"),
            ("diagnosis", "Integer", "1", "Table I bit mask of the last motion (see the FMU's documentation)"),
            ("motions", "Integer", "1", "completed high-speed motions processed so far")]
    return out


def diagnosis_code(diagnosis: list[dict]) -> int:
    """Bit mask of a motion's diagnoses: bit k for ``TABLE_I``'s k-th fault, bit len(TABLE_I) for unexplained."""
    from feeddrive.estimator.diagnosis import TABLE_I

    faults = list(TABLE_I)
    code = 0
    for d in diagnosis:
        k = faults.index(d["fault"]) if d["fault"] in faults else len(faults)
        code |= 1 << k
    return code


class _Unit:
    """Mixin adding FMI's ``unit`` attribute to a pythonfmu variable's type element (pythonfmu has none)."""

    unit: str | None = None

    def to_xml(self) -> Element:
        node = super().to_xml()  # type: ignore[misc]
        if self.unit:
            node[0].set("unit", self.unit)
        return node


class UnitReal(_Unit, Real):
    def __init__(self, name: str, unit: str | None = None, **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        self.unit = unit


def _component_classes(kind: str) -> tuple[type, type]:
    """(Component class, config model) of an exportable kind."""
    if kind == "nc":
        from feeddrive.cosim.nc import NCComponent, NCConfig

        return NCComponent, NCConfig
    if kind == "sensors":
        from feeddrive.cosim.sensors import SensorsComponent, SensorsConfig

        return SensorsComponent, SensorsConfig
    if kind == "monitor":
        from feeddrive.cosim.monitor import Monitor, MonitorConfig

        return Monitor, MonitorConfig
    raise ValueError(f"component kind {kind!r}: expected one of nc, sensors, monitor")


#: units of the components' real parameters (FMI 2.0 gives only Real variables a unit); a key ending in
#: ``_s`` is in seconds and one ending in ``_hz`` in hertz (``parameter_unit``)
CONFIG_UNITS = {
    # nc
    "start": "s", "kv": "1/s", "pitch": "m", "belt_ratio": "1", "accel": "m/s2",
    # monitor: levels, fractions and relative tolerances are dimensionless
    "speed_fraction": "1", "alpha": "1", "gain_tol": "1", "offset_tol": "1", "mismatch_alpha": "1",
    "min_relative_drift": "1",
    # monitor on a PMSM axis: the inverter's per-leg dead-time loss, the lost motion accepted on the table
    "dead_time_loss_v": "V", "lost_motion_allowed_mm": "mm",
}


def parameter_unit(name: str) -> str | None:
    """The unit of a component's real parameter ``name`` (None: not known)."""
    if name in CONFIG_UNITS:
        return CONFIG_UNITS[name]
    if name.endswith("_hz"):
        return "Hz"
    if name.endswith("_s"):
        return "s"
    return None


def scalar_fields(model: type) -> dict[str, type]:
    """The config model's top-level keys that are one scalar (float, int, bool, str, a str Literal or an
    optional str): they become FMU parameters. Nested sections (the NC program, the sensor channels) stay
    in component.json."""
    out: dict[str, type] = {}
    for name, info in model.model_fields.items():
        ann = info.annotation
        args = [a for a in typing.get_args(ann) if a is not type(None)]
        if typing.get_origin(ann) is typing.Literal and all(isinstance(a, str) for a in typing.get_args(ann)):
            out[name] = str
        elif ann in (float, int, bool, str):
            out[name] = ann
        elif len(args) == 1 and args[0] is str:  # str | None: "" stands for None
            out[name] = str
    return out


class ComponentSlave(Fmi2Slave):
    """FMI 2.0 Co-Simulation slave running one project component (see the module docstring)."""

    kind: ClassVar[str] = ""
    author = "feeddrive-monitor"
    license = "MIT"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        spec = json.loads((Path(self.resources) / CONFIG_FILE).read_text(encoding="utf-8"))
        self.component_name = spec["name"]
        self.section: dict = spec["config"]
        self.h = float(spec["step"])
        self.description = spec.get("description", f"feeddrive {self.kind} component")
        self.units: set[str] = set()
        self.component = None
        self.t0 = 0.0
        cls, self.model = _component_classes(self.kind)
        self.cls = cls
        self._in = [0.0] * len(cls.input_names)
        self._out: list = [0.0] * len(cls.output_names)
        self._params: dict[str, Any] = {}
        for k, (port, unit) in enumerate(zip(cls.input_names, self.input_units())):
            self._add(UnitReal(port, unit, causality=Fmi2Causality.input, start=0.0,
                               getter=lambda k=k: self._in[k], setter=lambda v, k=k: self._in.__setitem__(k, v)))
        for k, (port, unit) in enumerate(zip(cls.output_names, cls.output_units)):
            self._add(UnitReal(port, unit, causality=Fmi2Causality.output, getter=lambda k=k: self._out[k]))
        self._add(UnitReal("step_size", "s", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
                           description="communication step the component is built for [s]",
                           getter=lambda: self.h, setter=self._set_step))
        for name, typ in scalar_fields(self.model).items():
            if typ is str and name not in STRING_PARAMETERS:
                continue
            value = self.section.get(name)
            self._params[name] = "" if value is None and typ is str else value
            var = {float: Real, int: Integer, bool: Boolean, str: String}[typ]
            unit = parameter_unit(name) if typ is float else None
            description = (self.model.model_fields[name].description or f"{self.kind}.{name}")[:200]
            extra = {"unit": unit} if unit else {}
            self._add((UnitReal if unit else var)(
                name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed, description=description,
                getter=lambda n=name: self._params[n], setter=lambda v, n=name: self._params.__setitem__(n, v),
                **extra))

    def _add(self, var: Any) -> None:
        if getattr(var, "unit", None):
            self.units.add(var.unit)
        self.register_variable(var, nested=False)

    def _set_step(self, value: float) -> None:
        self.h = float(value)

    def input_units(self) -> tuple[str, ...]:
        """Units of the inputs (components declare only their outputs' units)."""
        return ("",) * len(self.cls.input_names)

    def to_xml(self, model_options: dict[str, str] | None = None) -> Element:
        """pythonfmu's model description plus the UnitDefinitions that the variables' units refer to."""
        root = super().to_xml(model_options or {})
        if self.units:
            defs = Element("UnitDefinitions")
            for unit in sorted(self.units):
                SubElement(defs, "Unit", name=unit)
            root.insert(1, defs)  # FMI 2.0 order: CoSimulation, UnitDefinitions, ..., ModelVariables
        # outputs are calculated at initialisation, so FMI 2.0 wants them among the InitialUnknowns too
        structure, outputs = root.find("ModelStructure"), root.find("ModelStructure/Outputs")
        if outputs is not None:
            initial = SubElement(structure, "InitialUnknowns")
            for unknown in outputs:
                SubElement(initial, "Unknown", index=unknown.get("index"))
        return root

    # -- the FMI calls ---------------------------------------------------------------------------------
    def setup_experiment(self, start_time: float, stop_time: float | None, tolerance: float | None) -> None:
        self.t0 = float(start_time)

    def config(self) -> Any:
        """The section with the parameters' values, as the component's frozen config (raises ValueError)."""
        overrides = {k: (None if v == "" and self.model.model_fields[k].annotation is not str else v)
                     for k, v in self._params.items()}
        return self.model.model_validate(self.section | overrides)

    def exit_initialization_mode(self) -> None:
        try:
            self.component = self.cls(self.component_name, self.config())
            self.component.setup(self.t0, self.h, OPEN_END_STEPS)
            self._out = list(self.component.get_outputs())
        except Exception as exc:  # noqa: BLE001 - reported through the FMI log; pythonfmu returns fmi2Error
            self.log(f"{self.component_name}: {type(exc).__name__}: {exc}", status=Fmi2Status.error)
            raise

    def do_step(self, current_time: float, step_size: float) -> bool:
        if abs(step_size - self.h) > 1e-9 * self.h:
            self.log(f"{self.component_name}: communication step {step_size:g} s; this FMU is built for "
                     f"step_size = {self.h:g} s (set the master's step or the step_size parameter)", status=Fmi2Status.error)
            return False
        c = self.component
        c.set_inputs(tuple(self._in))
        c.step(round((current_time - self.t0) / self.h))
        self._out = list(c.get_outputs())
        return True

    def terminate(self) -> None:
        if self.component is not None:
            self.component.terminate()


class NCSlave(ComponentSlave):
    """The NC trajectory generator and position loop (cosim/nc.py)."""

    kind = "nc"

    def input_units(self) -> tuple[str, ...]:
        return ("m", "1")


class SensorsSlave(ComponentSlave):
    """The redundant sensors (cosim/sensors.py); channel gains, offsets and noise are tunable parameters."""

    kind = "sensors"
    FIELDS = ("gain", "offset", "noise")
    #: unit of each channel's offset and noise (the encoder's are angles)
    CHANNEL_UNITS = {"Im1": "A", "Im2": "A", "u": "V", "u_ref": "V", "w_tach": "rad/s", "encoder": "rad"}

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        channels = self.model.model_validate(self.section).channels()
        self._channels = {f"{c}.{f}": float(getattr(cfg, f)) for c, cfg in channels.items() for f in self.FIELDS}
        for name in self._channels:
            channel, _, field = name.partition(".")
            unit = "1" if field == "gain" else self.CHANNEL_UNITS[channel]
            self._add(UnitReal(name, unit, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable,
                               description=f"sensor channel {name} (a change during the run is a sensor fault)",
                               getter=lambda n=name: self._channels[n],
                               setter=lambda v, n=name: self._set_channel(n, v)))

    def input_units(self) -> tuple[str, ...]:
        return ("V", "V", "A", "rad/s", "m")

    def _set_channel(self, name: str, value: float) -> None:
        # libcosim's override manipulator sets the value before every step: only a change is an event
        if value == self._channels[name]:
            return
        self._channels[name] = float(value)
        if self.component is not None:
            self.component.set_parameter(name, float(value))

    def config(self) -> Any:
        base = self.model.model_validate(self.section).model_dump(mode="json")
        keys = {"Im1": ("current", 0), "Im2": ("current", 1), "u": ("voltage",), "u_ref": ("voltage_ref",),
                "w_tach": ("tachometer",), "encoder": ("encoder",)}
        for name, value in self._channels.items():
            channel, _, field = name.partition(".")
            node = base
            for key in keys[channel]:
                node = node[key]
            node[field] = value
        params = {k: v for k, v in self._params.items()}
        return self.model.model_validate(base | params)


class MonitorSlave(ComponentSlave):
    """The monitor (cosim/monitor.py) with its per-motion results as outputs (see ``monitor_outputs``)."""

    kind = "monitor"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self._results: dict[str, float | int] = {}
        for name, typ, unit, description in monitor_outputs():
            self._results[name] = 0 if typ == "Integer" else float("nan")
            getter = (lambda n=name: self._results[n])
            if typ == "Integer":
                self._add(Integer(name, causality=Fmi2Causality.output, variability=Fmi2Variability.discrete,
                                  description=description, getter=getter))
            else:
                self._add(UnitReal(name, unit, causality=Fmi2Causality.output, description=description,
                                   getter=getter))
        self._seen = 0

    def input_units(self) -> tuple[str, ...]:
        return ("A", "A", "V", "V", "rad/s", "rad/s", "rad", "1", "1")

    def report_path(self) -> Path | None:
        """``<db without suffix>.report.json`` beside the history, None for an in-memory history."""
        db = self.component.config.db if self.component is not None else None
        if not db or db == ":memory:":
            return None
        return Path(db).with_suffix(".report.json")

    def exit_initialization_mode(self) -> None:
        if self._params.get("db") in ("", None):
            self._params["db"] = ":memory:"
        super().exit_initialization_mode()

    def do_step(self, current_time: float, step_size: float) -> bool:
        ok = super().do_step(current_time, step_size)
        results = self.component.results
        if len(results) != self._seen:
            self._seen = len(results)
            self._publish(results[-1])
            self._write_report()
        return ok

    def _publish(self, r: dict) -> None:
        out = self._results
        out["validated"] = int(bool(r["validated"]))
        for p in PARAMETERS:
            est = r["parameters"].get(p)
            out[p] = float(est["value"]) if est else float("nan")
            out[f"{p}_std"] = float(est["std"]) if est else float("nan")
        faulty = {f["sensor"] for f in r["sensor_faults"]}
        for s in FAULT_SENSORS:
            out[f"fault_{s}"] = int(s in faulty)
        out["mismatch"] = int(bool(r["mismatch"]) and not r["mismatch"]["passed"])
        out["diagnosis"] = diagnosis_code(r["diagnosis"])
        out["motions"] = self._seen

    def _write_report(self) -> None:
        path = self.report_path()
        if path is None:
            return
        report = {"axis": self.component.axis, "db": self.component.config.db, "fmu": self.modelName,
                  "motions": self.component.results}
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(report, indent=2, default=_jsonable), encoding="utf-8")
        tmp.replace(path)  # a reader never sees half a file


def _jsonable(x: Any) -> Any:
    if hasattr(x, "item"):
        return x.item()
    if hasattr(x, "tolist"):
        return x.tolist()
    raise TypeError(f"monitor report: {type(x).__name__} is not JSON-serialisable")
