"""Build a vendor-style plant FMU: the same feed drive, other variable names and units.

A drive vendor's FMU rarely uses the toolkit's names and SI units. This script derives a variant of
``models.feed_drive()`` whose interface is::

    inputs   n_cmd [rpm] (speed command), T_load [N.m], u_in [V]
    outputs  n_mot [rpm] (motor speed), x_mm [mm] (table position), U_arm [V], U_ref [V], I_arm [A]

and builds it with ``fmu_build.build_fmu``; ``examples/vendor_fmu.yaml`` maps it onto the master's
roles. ``--pitch`` sets the start value of its ball-screw ``pitch`` parameter [m] (a vendor axis with
another drive chain; the scenario's ``axis.pitch`` must then say the same, since nothing but the
scenario tells the NC and the encoder). The FMU is built here, never committed::

    python examples/vendor_fmu/build_vendor_fmu.py [--out examples/vendor_fmu/VendorDrive.fmu] [--pitch 0.01]
"""
from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

from feeddrive.fmu_build import build_fmu
from feeddrive.models import Model, Variable, feed_drive

RPM = 30 / math.pi  # rad/s -> rpm


def vendor_model(pitch: float | None = None) -> Model:
    """The feed drive with the vendor's names and units (same physics, same parameters; ``pitch`` [m]:
    another start value of the ball-screw pitch)."""
    m = feed_drive()
    s = {name: v.sym for name, v in m.variables.items()}
    outputs = dict(zip((v.name for v in m.outputs), (m.output_expressions()[k] for k in range(len(m.outputs)))))
    n_cmd = Variable("n_cmd", "rpm", "speed command from the NC", "input", 0.0)
    t_load = Variable("T_load", "N.m", "load torque", "input", 0.0)
    algebraic = {  # the original inputs become functions of the vendor's inputs
        "w_ref": n_cmd.sym / RPM,
        "Tl": t_load.sym,
        "n_mot": s["w"] * RPM,
        "x_mm": outputs["x"] * 1000.0,
        "U_arm": outputs["u"],
        "U_ref": outputs["u_ref"],
        "I_arm": s["i"],
    }
    units = {"n_mot": "rpm", "x_mm": "mm", "U_arm": "V", "U_ref": "V", "I_arm": "A"}
    variables = (
        [dataclasses.replace(v, output=False) for v in m.states]
        + [n_cmd, t_load, m.variables["u_in"]]
        + [dataclasses.replace(v, nominal=pitch) if v.name == "pitch" and pitch else v for v in m.parameters]
        + [dataclasses.replace(m.variables[n], kind="algebraic", nominal=None) for n in ("w_ref", "Tl")]
        + [Variable(n, u, f"vendor output {n}", "algebraic", output=True) for n, u in units.items()]
    )
    rhs = m.state_derivatives()
    explicit = {v.name: rhs[k] for k, v in enumerate(m.states)}
    return Model("VendorDrive", variables, [], explicit, algebraic,
                 description="feed drive with a vendor's interface (rpm, mm)")


def main(argv: list[str] | None = None) -> Path:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path(__file__).with_name("VendorDrive.fmu"))
    parser.add_argument("--pitch", type=float, default=None, help="ball-screw pitch [m] (default: the built-in 0.02)")
    args = parser.parse_args(argv)
    out = build_fmu(vendor_model(args.pitch), args.out)
    print(out)
    return out


if __name__ == "__main__":
    main()
