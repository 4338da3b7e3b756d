"""A foreign drive FMU in non-SI units: the built-in feed drive behind an interface in rpm, mm, mA and kN.m.

Inputs ``n_soll`` [rpm] (speed command) and ``M_last`` [kN.m] (load torque); outputs ``n_ist`` [rpm]
(motor speed), ``s_ist`` [mm] (table position), ``I_ist`` [mA] (armature current), ``U_ist`` and
``U_soll`` [V]. The physics and parameters are those of ``models.feed_drive()``, so a scenario mapping
these variables *without any scale* must give the built-in plant's signals and estimates: the units
declared in modelDescription.xml are the only thing that converts them (``cosim.unit_map``). Compiled
to C by ``fmu_build.build_fmu`` with the system compiler.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from feeddrive.fmu_build import build_fmu
from feeddrive.models import Model, Variable, feed_drive

RPM = 30 / math.pi  # rad/s -> rpm
#: role map without a single scale: the declared units convert
ROLE_MAP = {"speed_ref": {"var": "n_soll"}, "load": {"var": "M_last"}, "voltage": {"var": "U_ist"},
            "voltage_ref": {"var": "U_soll"}, "current": {"var": "I_ist"}, "speed": {"var": "n_ist"},
            "position": {"var": "s_ist"}}
UNITS = {"n_soll": "rpm", "M_last": "kN.m", "n_ist": "rpm", "s_ist": "mm", "I_ist": "mA", "U_ist": "V", "U_soll": "V"}


def foreign_model() -> Model:
    """The feed drive with the interface above (same states, parameters and equations)."""
    m = feed_drive()
    s = {name: v.sym for name, v in m.variables.items()}
    outputs = dict(zip((v.name for v in m.outputs), (m.output_expressions()[k] for k in range(len(m.outputs)))))
    n_soll = Variable("n_soll", "rpm", "speed command", "input", 0.0)
    m_last = Variable("M_last", "kN.m", "load torque", "input", 0.0)
    algebraic = {"w_ref": n_soll.sym / RPM, "Tl": m_last.sym * 1000.0, "n_ist": s["w"] * RPM,
                 "s_ist": outputs["x"] * 1000.0, "I_ist": s["i"] * 1000.0, "U_ist": outputs["u"],
                 "U_soll": outputs["u_ref"]}
    variables = (
        [dataclasses.replace(v, output=False) for v in m.states]
        + [n_soll, m_last, m.variables["u_in"]] + list(m.parameters)
        + [dataclasses.replace(m.variables[n], kind="algebraic", nominal=None) for n in ("w_ref", "Tl")]
        + [Variable(n, UNITS[n], f"foreign output {n}", "algebraic", output=True)
           for n in ("n_ist", "s_ist", "I_ist", "U_ist", "U_soll")]
    )
    rhs = m.state_derivatives()
    explicit = {v.name: rhs[k] for k, v in enumerate(m.states)}
    return Model("ForeignDrive", variables, [], explicit, algebraic,
                 description="feed drive with a foreign interface (rpm, mm, mA, kN.m)")


def build_foreign_drive(out: Path | str) -> Path:
    """Compile the foreign drive into ``out`` (an FMI 2.0 FMU, Co-Simulation and Model Exchange)."""
    return build_fmu(foreign_model(), Path(out))
