"""A vendor-style drive FMU the project builds itself: held inputs, analog-style PI loops, no reference filter.

Many drive vendors ship Co-Simulation FMUs that differ from the built-in plant in ways that matter to
the measurement chain:

- the inputs are held over each communication step (``canInterpolateInputs="false"``);
- the speed PI and the (fast, 1 kHz) current PI act on the held speed command directly: no reference
  filter, so every step of the command jumps the terminal voltage through the proportional gains;
- other names and units: ``n_set`` [rpm] in, ``M_load`` [N.m] in; ``n_act`` [rpm], ``s_mm`` [mm],
  ``U_A`` [V] (armature voltage), ``U_st`` [V] (the current regulator's output), ``I_A`` [A] out.

The physics is the paper's DC drive (eq. 1, 2) with the built-in plant's parameter values (``R``, ``L``,
``K``, ``Jt``, ``ft``, ``Cd``, same names), so an estimate can be judged against ``TRUTH``. The model is
written with ``feeddrive.models`` and compiled to C by ``feeddrive.fmu_build`` with the system compiler;
``build_vendor_drive`` then marks the FMU as one that cannot interpolate its inputs.
"""
from __future__ import annotations

import math
import shutil
import tempfile
import zipfile
from pathlib import Path

import casadi as ca

from feeddrive.fmu_build import build_fmu
from feeddrive.models import Model, Variable

RPM = 30 / math.pi  # rad/s -> rpm
#: the physical parameters of the FMU (the built-in plant's defaults)
TRUTH = {"R": 0.6, "L": 4.0e-3, "K": 1.05, "Jt": 0.1, "ft": 0.02, "Cd": 1.2}
#: role map of a scenario's ``plant.map`` for this FMU
ROLE_MAP = {
    "speed_ref": {"var": "n_set", "scale": RPM},
    "load": {"var": "M_load"},
    "voltage": {"var": "U_A"},
    "voltage_ref": {"var": "U_st"},
    "current": {"var": "I_A"},
    "speed": {"var": "n_act", "scale": 1 / RPM},
    "position": {"var": "s_mm", "scale": 1e-3},
}


def _sat(v: ca.SX, limit: ca.SX) -> ca.SX:
    return ca.fmin(ca.fmax(v, -limit), limit)


def vendor_drive_model(current_bandwidth_hz: float = 1000.0) -> Model:
    """The vendor's drive: speed PI -> current PI (``current_bandwidth_hz``) -> converter -> DC motor."""
    V = Variable
    t = TRUTH
    wc_i, wc_w = 2 * math.pi * current_bandwidth_hz, 2 * math.pi * 20.0
    variables = [
        V("i", "A", "armature current", "state", 0.0),
        V("w", "rad/s", "motor speed", "state", 0.0),
        V("theta", "rad", "motor angle", "state", 0.0),
        V("xi_w", "A", "speed PI integrator", "state", 0.0),
        V("xi_i", "V", "current PI integrator", "state", 0.0),
        V("n_set", "rpm", "speed command (held over each step)", "input", 0.0),
        V("M_load", "N.m", "load torque", "input", 0.0),
        *(V(k, u, f"physical parameter {k}", "physical", t[k], lower=0.0)
          for k, u in (("R", "Ohm"), ("L", "H"), ("K", "N.m/A"), ("Jt", "kg.m2"), ("ft", "N.m.s/rad"), ("Cd", "N.m"))),
        V("Kp_i", "V/A", "current PI gain", "design", t["L"] * wc_i, "L x current bandwidth"),
        V("Ki_i", "V/(A.s)", "current PI integral gain", "design", t["R"] * wc_i, "R x current bandwidth"),
        V("Kp_w", "A.s/rad", "speed PI gain", "design", t["Jt"] * wc_w / t["K"], "Jt x 20 Hz / K"),
        V("Ki_w", "A/rad", "speed PI integral gain", "design", t["Jt"] * wc_w / t["K"] * 2 * math.pi * 4, "4 Hz corner"),
        V("u_max", "V", "converter voltage limit", "design", 150.0),
        V("i_max", "A", "current limit", "design", 30.0),
        V("pitch", "m", "ball-screw pitch", "design", 0.02),
        V("w_eps", "rad/s", "dry-friction smoothing speed", "design", 1.0e-3),
        V("sgn_w", "1", "smoothed sign of the speed", "algebraic"),
        V("i_ref", "A", "current reference", "algebraic"),
        V("U_st", "V", "current regulator output", "algebraic", output=True),
        V("U_A", "V", "armature voltage", "algebraic", output=True),
        V("I_A", "A", "armature current", "algebraic", output=True),
        V("n_act", "rpm", "motor speed", "algebraic", output=True),
        V("s_mm", "mm", "table position", "algebraic", output=True),
    ]
    s = {v.name: v.sym for v in variables}
    e_w = s["n_set"] / RPM - s["w"]  # no reference filter: the held command acts at once
    v_w = s["Kp_w"] * e_w + s["xi_w"]
    e_i = s["i_ref"] - s["i"]
    v_i = s["Kp_i"] * e_i + s["xi_i"]
    algebraic = {
        "sgn_w": ca.tanh(s["w"] / s["w_eps"]),
        "i_ref": _sat(v_w, s["i_max"]),
        "U_st": _sat(v_i, s["u_max"]),
        "U_A": s["U_st"],
        "I_A": s["i"],
        "n_act": s["w"] * RPM,
        "s_mm": s["theta"] / (2 * math.pi) * s["pitch"] * 1000.0,
    }
    explicit = {
        "i": (s["U_A"] - s["R"] * s["i"] - s["K"] * s["w"]) / s["L"],
        "w": (s["K"] * s["i"] - s["ft"] * s["w"] - s["Cd"] * s["sgn_w"] - s["M_load"]) / s["Jt"],
        "theta": s["w"],
        "xi_w": s["Ki_w"] * e_w + s["Ki_w"] / s["Kp_w"] * (s["i_ref"] - v_w),  # back-calculation anti-windup
        "xi_i": s["Ki_i"] * e_i + s["Ki_i"] / s["Kp_i"] * (s["U_st"] - v_i),
    }
    return Model("VendorHeldDrive", variables, [], explicit, algebraic,
                 description="vendor-style drive: held inputs, speed and current PI, no reference filter")


def build_vendor_drive(out: Path | str, current_bandwidth_hz: float = 1000.0) -> Path:
    """Compile the vendor drive into ``out`` (an FMI 2.0 FMU) that declares it cannot interpolate its inputs."""
    out = Path(out)
    built = build_fmu(vendor_drive_model(current_bandwidth_hz), out)
    with tempfile.TemporaryDirectory() as tmp:
        patched = Path(tmp) / out.name
        with zipfile.ZipFile(built) as src, zipfile.ZipFile(patched, "w", zipfile.ZIP_DEFLATED) as dst:
            for item in src.infolist():
                data = src.read(item)
                if item.filename == "modelDescription.xml":  # a vendor FMU holds its inputs over each step
                    data = data.replace(b'canInterpolateInputs="true"', b'canInterpolateInputs="false"')
                dst.writestr(item, data)
        shutil.move(patched, out)
    return out
