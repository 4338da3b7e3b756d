"""VendorPMSM: a vendor-style PMSM servo drive FMU written by hand in C (``vendor_pmsm.c``), built here with gcc.

A truly foreign plant for the tests: FMI 2.0 Co-Simulation with its own fixed-step RK4 integrator (not
``feeddrive.fmu_build``), held inputs (``canInterpolateInputs="false"``), a space-vector PWM average
inverter with a per-phase dead time, and a vendor's names and units:

=============  ======  ==========================================================================
variable       unit    meaning
=============  ======  ==========================================================================
n_soll         rpm     speed command (input, held over each communication step)
M_last         N.m     load torque (input)
n_ist          rpm     motor speed
I_U, I_V, I_W  A       phase currents (instantaneous)
I_d_rms        A       d current as an rms value, i_d / sqrt(2) (the vendor's unit string is "A")
I_q_rms        A       q current as an rms value, i_q / sqrt(2)
U_d_soll       V       d voltage reference of the current regulator (phase peak, dq frame)
U_q_soll       V       q voltage reference
U_d, U_q       V       terminal voltages after the SVPWM limit u_dc / sqrt(3) and the dead time
M_mot          N.m     air-gap torque
s_mot_mm       mm      table position from the motor angle (motor encoder side)
s_lin_mm       mm      table position behind the screw's stiffness ``k_axial`` and the play ``lost_motion_mm``
phi_el         rad     electrical angle p * theta (not wrapped)
=============  ======  ==========================================================================

**rms quantities.** An rms value is not a unit: ``A rms -> A peak`` is no pint conversion, and the vendor
declares ``I_q_rms`` in plain ``A`` (as data sheets do). A scenario maps it onto the ``current`` role (the
amplitude-invariant i_q, a phase peak) with the factor stated and the unit overridden as dimensionless, so
that ``cosim.unit_map`` takes the scale as given and prints it as a stated assumption:
``current: {var: I_q_rms, unit: "1", scale: 1.4142135623730951}``. A bare ``scale: 1.4142`` on the declared
``A`` is refused (it contradicts A -> A = x 1); a forgotten factor (``{var: I_q_rms}``) is accepted by the
units but caught by the drive's analytic redundancy: the q current of the three phase currents is
sqrt(2) times the mapped one (``estimator.redundancy_servo.dq_current_consistency``).
"""
from __future__ import annotations

import math
import shutil
import subprocess
import tempfile
import zipfile
from pathlib import Path

import fmpy

from feeddrive.fmu_build.build import compiler

HERE = Path(__file__).parent
GUID = "{8c4e810f-3df3-4a00-8276-176fa3c9f9e0}"
MODEL = "VendorPMSM"
RPM = 30 / math.pi  # rad/s -> rpm
SQRT2 = math.sqrt(2.0)
#: a table's share of the lumped load, for a drive chain that deflects: 150 kg of table and work-piece, 120 N of
#: guide friction (preloaded linear guides), 200 N/um axial stiffness: 2 Fc / k = 1.2 um of elastic lost motion
ELASTIC = {"m_table": 150.0, "Fc_table": 120.0, "k_axial": 200.0}

#: the plant's true physical parameters (the built-in PMSM's defaults), for judging estimates
TRUTH = {"R": 0.7, "L_d": 8.0e-3, "L_q": 8.0e-3, "psi_f": 0.23, "p": 4.0, "J": 3.0e-3, "ft": 1.5e-3, "Cd": 0.4}
#: the inverter's defaults: 1 us dead time at 8 kHz on a 600 V DC link (a 4.8 V loss per leg)
INVERTER = {"t_dead": 1.0e-6, "f_pwm": 8.0e3, "u_dc": 600.0}
_IN, _OUT, _PAR = "input", "output", "parameter"
#: (name, causality, unit, description, start); value references in this order, as vendor_pmsm.c's enum
VARIABLES = [
    ("n_soll", _IN, "rpm", "speed command", 0.0),
    ("M_last", _IN, "N.m", "load torque", 0.0),
    ("n_ist", _OUT, "rpm", "motor speed", None),
    ("I_U", _OUT, "A", "phase U current", None),
    ("I_V", _OUT, "A", "phase V current", None),
    ("I_W", _OUT, "A", "phase W current", None),
    ("I_d_rms", _OUT, "A", "d current, rms value (i_d / sqrt(2))", None),
    ("I_q_rms", _OUT, "A", "q current, rms value (i_q / sqrt(2))", None),
    ("U_d_soll", _OUT, "V", "d voltage reference (phase peak)", None),
    ("U_q_soll", _OUT, "V", "q voltage reference (phase peak)", None),
    ("U_d", _OUT, "V", "d terminal voltage (SVPWM average with dead time)", None),
    ("U_q", _OUT, "V", "q terminal voltage (SVPWM average with dead time)", None),
    ("M_mot", _OUT, "N.m", "air-gap torque", None),
    ("s_mot_mm", _OUT, "mm", "table position from the motor angle (motor encoder)", None),
    ("s_lin_mm", _OUT, "mm", "table position on the linear scale (behind the lost motion)", None),
    ("phi_el", _OUT, "rad", "electrical angle p * theta", None),
    ("R", _PAR, "Ohm", "stator phase resistance", TRUTH["R"]),
    ("L_d", _PAR, "H", "d-axis inductance", TRUTH["L_d"]),
    ("L_q", _PAR, "H", "q-axis inductance", TRUTH["L_q"]),
    ("psi_f", _PAR, "Wb", "magnet flux linkage (phase peak)", TRUTH["psi_f"]),
    ("p", _PAR, "1", "pole pairs", TRUTH["p"]),
    ("J", _PAR, "kg.m2", "total inertia at the motor", TRUTH["J"]),
    ("ft", _PAR, "N.m.s/rad", "viscous friction", TRUTH["ft"]),
    ("Cd", _PAR, "N.m", "dry friction torque", TRUTH["Cd"]),
    ("t_dead", _PAR, "s", "inverter dead time", INVERTER["t_dead"]),
    ("f_pwm", _PAR, "Hz", "PWM frequency", INVERTER["f_pwm"]),
    ("u_dc", _PAR, "V", "DC-link voltage", INVERTER["u_dc"]),
    ("pitch_mm", _PAR, "mm", "ball-screw pitch", 10.0),
    ("lost_motion_mm", _PAR, "mm", "lost motion (backlash) between the screw and the table", 0.0),
    ("i_max", _PAR, "A", "current-vector limit (peak)", 25.0),
    ("Kp_i", _PAR, "V/A", "current PI gain", 8.0e-3 * 2 * math.pi * 1000),
    ("Ki_i", _PAR, "V/(A.s)", "current PI integral gain", 0.7 * 2 * math.pi * 1000),
    ("Kp_w", _PAR, "A.s/rad", "speed PI gain", 3.0e-3 * 2 * math.pi * 50 / 1.38),
    ("Ki_w", _PAR, "A/rad", "speed PI integral gain", 3.0e-3 * 2 * math.pi * 50 / 1.38 * 2 * math.pi * 10),
    ("tau_ref", _PAR, "s", "speed-reference filter time constant", 1.0e-3),
    ("w_base", _PAR, "rad/s", "base speed (field weakening above)", 300.0),
    ("i_fw", _PAR, "A", "field-weakening current scale", 0.23 / 8.0e-3),
    ("fw", _PAR, "1", "1: field weakening on", 1.0),
    ("w_eps", _PAR, "rad/s", "dry-friction smoothing speed", 1.0e-2),
    ("i_eps", _PAR, "A", "current scale of the dead time's smooth sign", 0.2),
    ("dt_int", _PAR, "s", "integrator step (RK4)", 1.0e-5),
    ("m_table", _PAR, "kg", "table and work-piece mass (its deflection of the screw; part of J)", 0.0),
    ("Fc_table", _PAR, "N", "dry friction of the table's guides (its deflection of the screw; part of Cd)", 0.0),
    ("k_axial", _PAR, "N/um", "axial stiffness of the screw, nut and bearings", 200.0),
]

#: a scenario's ``plant.map`` for this FMU (rpm and mm converted by their units; the rms factor stated)
ROLE_MAP = {
    "speed_ref": {"var": "n_soll"},
    "load": {"var": "M_last"},
    "voltage": {"var": "U_q"},
    "voltage_ref": {"var": "U_q_soll"},
    "current": {"var": "I_q_rms", "unit": "1", "scale": SQRT2},
    "speed": {"var": "n_ist"},
    "position": {"var": "s_mot_mm"},
}


def model_description() -> str:
    """The FMU's modelDescription.xml (FMI 2.0 Co-Simulation, inputs held)."""
    units = sorted({v[2] for v in VARIABLES})
    rows, outputs = [], []
    for vr, (name, causality, unit, description, start) in enumerate(VARIABLES):
        if causality == _OUT:
            outputs.append(vr + 1)
            extra = ' variability="continuous" initial="calculated"'
        elif causality == _IN:
            extra = ' variability="continuous"'
        else:
            extra = ' variability="tunable" initial="exact"'
        s = f' start="{start!r}"' if start is not None else ""
        rows.append(f'    <ScalarVariable name="{name}" valueReference="{vr}" causality="{causality}"{extra} '
                    f'description="{description}">\n      <Real unit="{unit}"{s}/>\n    </ScalarVariable>')
    unknowns = "\n".join(f'      <Unknown index="{i}"/>' for i in outputs)
    unit_defs = "\n".join(f'    <Unit name="{u}"/>' for u in units)
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{MODEL}" guid="{GUID}" generationTool="hand-written C"
  description="vendor-style PMSM servo drive: held inputs, SVPWM average with dead time" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{MODEL}" canHandleVariableCommunicationStepSize="true"
    canInterpolateInputs="false" canGetAndSetFMUstate="false" canSerializeFMUstate="false"
    providesDirectionalDerivative="false"/>
  <UnitDefinitions>
{unit_defs}
  </UnitDefinitions>
  <DefaultExperiment startTime="0" stopTime="1" stepSize="1e-4"/>
  <ModelVariables>
{chr(10).join(rows)}
  </ModelVariables>
  <ModelStructure>
    <Outputs>
{unknowns}
    </Outputs>
    <InitialUnknowns>
{unknowns}
    </InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
"""


def build_vendor_pmsm(out_dir: Path | str) -> Path:
    """Compile ``vendor_pmsm.c`` with the system C compiler and zip ``VendorPMSM.fmu`` into ``out_dir``.

    Returns
    -------
    Path
        The FMU (binaries/linux64/VendorPMSM.so, or the platform's library, and modelDescription.xml).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    fmu = out_dir / f"{MODEL}.fmu"
    headers = Path(fmpy.__file__).parent / "c-code"  # the FMI standard's headers, shipped with fmpy
    with tempfile.TemporaryDirectory() as tmp:
        lib = Path(tmp) / f"{MODEL}{fmpy.sharedLibraryExtension}"
        cmd = [*compiler(), "-O2", "-fPIC", "-shared", "-Wall", "-Wextra", f"-I{headers}", "-o", str(lib),
               str(HERE / "vendor_pmsm.c"), "-lm"]
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            raise RuntimeError(f"compiling {MODEL}: {done.stderr.strip()}")
        staged = Path(tmp) / fmu.name
        with zipfile.ZipFile(staged, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("modelDescription.xml", model_description())
            z.write(lib, f"binaries/{fmpy.platform}/{lib.name}")
            z.write(HERE / "vendor_pmsm.c", f"sources/{MODEL}.c")
        shutil.move(staged, fmu)
    return fmu
