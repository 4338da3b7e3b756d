"""Test data: a recorded linear axis in SI, generated from the exact inverse dynamics.

The table moves ``v(t) = 0.09 sin(2 pi 0.2 t) + 0.04 sin(2 pi 0.73 t)`` m/s (peak ~0.13 m/s, speed
reversals separate Cd from the offset); the force command is what the axis needs to follow it,
``F = M dv/dt + Fv v + Fc sign(v) + F0``, plus white noise; the position is the exact integral of v
quantised by a 1 um linear encoder. Sampled at 1 kHz for 25 s.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

#: the truth: moving mass [kg], viscous friction [N.s/m], Coulomb friction [N], force offset [N]
TRUTH = {"Jt": 100.0, "ft": 200.0, "Cd": 20.0, "T0": -3.0}
H = 1e-3
DURATION = 25.0
RESOLUTION = 1e-6  # encoder [m]
FORCE_NOISE = 1.0  # [N] std
_A = ((0.09, 0.2), (0.04, 0.73))  # (amplitude m/s, frequency Hz)


def linear_axis(seed: int = 0) -> dict[str, np.ndarray]:
    """``{"t" [s], "x" [m], "F" [N], "v" [m/s]}`` of the linear axis (module docstring)."""
    t = np.arange(int(round(DURATION / H))) * H
    v = sum(a * np.sin(2 * math.pi * f * t) for a, f in _A)
    dv = sum(a * 2 * math.pi * f * np.cos(2 * math.pi * f * t) for a, f in _A)
    x = sum(a / (2 * math.pi * f) * (1 - np.cos(2 * math.pi * f * t)) for a, f in _A)
    force = TRUTH["Jt"] * dv + TRUTH["ft"] * v + TRUTH["Cd"] * np.sign(v) + TRUTH["T0"]
    rng = np.random.default_rng(seed)
    return {"t": t, "x": np.round(x / RESOLUTION) * RESOLUTION, "F": force + FORCE_NOISE * rng.normal(size=t.size),
            "v": v}


def write_csv(path: Path, data: dict[str, np.ndarray], *, mm: bool = False, sep: str = ",", decimal: str = ".",
              units: bool = True, bom: bool = False) -> Path:
    """Write ``t, x, F`` as a CSV (position in mm with ``mm``), in the given dialect."""
    scale, xu = (1e3, "mm") if mm else (1.0, "m")
    names = ["t [s]", f"x [{xu}]", "F [N]"] if units else ["t", "x", "F"]
    cols = [data["t"], data["x"] * scale, data["F"]]
    lines = [sep.join(names)]
    for row in zip(*cols):
        cells = [f"{c:.10g}" for c in row]
        lines.append(sep.join(c.replace(".", decimal) for c in cells))
    path.write_text(("\ufeff" if bom else "") + "\n".join(lines) + "\n", encoding="utf-8")
    return path


def main(argv: list[str] | None = None) -> int:
    """``python tests/cosim/linear_axis.py rec.csv [--mm] [--overwrite]``: the recording for the README."""
    import argparse

    parser = argparse.ArgumentParser(description="Write the linear-axis test recording (25 s at 1 kHz) as CSV.")
    parser.add_argument("csv", type=Path, help="CSV file to write")
    parser.add_argument("--mm", action="store_true", help="position in mm (unit in the header)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing file")
    args = parser.parse_args(argv)
    if args.csv.exists() and not args.overwrite:
        parser.error(f"{args.csv} exists; use --overwrite to replace it")
    print(write_csv(args.csv, linear_axis(), mm=args.mm))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
