"""``cosim estimate DATA.csv --map ROLE=COLUMN ...``: R, L, K, Jt, ft, Cd from a recorded CSV.

Roles: ``time``, ``voltage`` [V], ``current`` [A], ``speed``, ``position``, ``torque``, ``state``
(NC state, 1 = rapid). Columns are converted to SI from the unit in their header (``x [mm]``) or an
explicit ``--map ROLE=COLUMN*SCALE``. The mechanical parameters are estimated on the side the data are
on: the motor side (position in rad, speed in rad/s, torque in N.m: Jt in kg.m2, ft in N.m.s/rad, Cd in
N.m), or the table side of a linear axis when the headers say m, m/s or N (Jt is then the moving mass
in kg, ft in N.s/m, Cd in N); ``--pitch``/``--ratio`` convert table-side data to the motor side.
The recording is cut into high-speed motions (``--segment``), each estimated on its own; the output is
a table per motion with 95 % confidence intervals, or with ``--json``::

    {"side": "motor"|"table", "segments": [{"start": s, "end": s, "method": m,
      "parameters": {"R": {"value": v, "ci95": [lo, hi], "unit": u}, ...}, "condition_number": c, "fit_error": e}]}

holding only the parameters the data determine. When there are several motions, one that cannot
be estimated (too short, not exciting every parameter) is reported on stderr and left out; if no
motion is left, the exit status is 2.
"""
from __future__ import annotations

import argparse
import json
import sys

from feeddrive.cosim.axis import parameter_units
from feeddrive.cosim.errors import InputError
from feeddrive.cosim.recorded import (
    SAMPLED,
    add_recording_arguments,
    filter_cutoff,
    mapped_roles,
    motions,
    pairs,
    read_recording,
    recording_json,
    sampling_modes,
)
from feeddrive.estimator import (
    EstimationOptions,
    EstimatorInputError,
    FilterSpec,
    MotionData,
    NotEnoughExcitation,
    estimate_motion,
)
from feeddrive.estimator.motion import SAMPLING_DELAY

ROLES = {"time": None, "voltage": "u", "current": "i", "speed": "w", "position": "position", "torque": "torque",
         "state": None}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_recording_arguments(parser, ROLES, EstimationOptions().filter.cutoff_hz)
    parser.add_argument("--known", action="append", default=[], metavar="NAME=VALUE",
                        help="a parameter known in advance, e.g. K=1.05 (mechanical equation only)")
    parser.add_argument("--offset", action="store_true", help="also estimate a constant torque offset T0")


def main(args: argparse.Namespace) -> int:
    roles = mapped_roles(args, ROLES)
    known = {}
    for name, value in pairs(args.known, "--known").items():
        try:
            known[name] = float(value)
        except ValueError:
            raise InputError(f"--known {name}={value!r}: expected a number") from None
    rec = read_recording(args, roles)
    side = rec.side or "motor"
    units = parameter_units(side, "linear" if side == "table" else "rotary")
    options = EstimationOptions(method=args.method, filter=FilterSpec(filter_cutoff(args, rec.h)), known=known,
                                offset=args.offset, speed_threshold=args.speed_threshold,
                                speed_unit="m/s" if side == "table" else "rad/s")
    modes = sampling_modes(args)
    delays = {SAMPLED[q]: SAMPLING_DELAY[m] * rec.h for q, m in modes.items() if SAMPLING_DELAY[m]}
    sig = {ROLES[r]: v for r, v in rec.signals.items() if ROLES[r]}
    speed = sig.get("w")
    if speed is None and "position" in sig:
        speed = rec.gradient(sig["position"])
    segments = motions(args, rec, speed, rec.signals.get("state"))
    if not segments:
        raise InputError(f"{args.data}: no high-speed motion found (--segment {args.segment})")
    results = []
    for seg in segments:
        part = {k: v[seg.start:seg.stop] for k, v in sig.items()}
        data = MotionData(rec.h, t0=rec.time(seg.start), delays=delays, **part)
        try:
            results.append(estimate_motion(data, options))
        except (NotEnoughExcitation, EstimatorInputError) as exc:  # e.g. a rapid block too short to filter
            if len(segments) == 1:
                raise
            print(f"cosim estimate: motion {data.t0:.4g}-{data.t0 + (data.n - 1) * data.h:.4g} s left out: {exc}",
                  file=sys.stderr)
    if not results:
        raise InputError(f"{args.data}: no motion could be estimated (see above)")
    if args.json:
        segments = [r.to_dict() for r in results]
        for seg in segments:
            for name, p in seg["parameters"].items():
                p["unit"] = units[name]
        print(json.dumps({"side": side, **recording_json(rec), "segments": segments}))
    else:
        print(table(results, units))
    return 0


def table(results, units: dict[str, str]) -> str:  # noqa: ANN001 - list of estimator.MotionEstimate
    """One block per motion: parameter, value, unit (``units``: the data's side), 95 % confidence interval."""
    lines = []
    for k, r in enumerate(results, 1):
        lines.append(f"motion {k}: {r.start:.4g}-{r.end:.4g} s, {r.method.upper()}, condition number "
                     f"{r.condition_number:.3g}, fit error {r.fit_error:.3g}")
        if r.result.message:
            lines.append(f"  ({r.result.message})")
        for name, p in r.parameters.items():
            lines.append(f"  {name:3} {p.value:12.6g} {units[name]:10} 95 % CI [{p.ci95[0]:.6g}, {p.ci95[1]:.6g}]")
    return "\n".join(lines)
