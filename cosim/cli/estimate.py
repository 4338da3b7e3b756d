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

import numpy as np

from feeddrive.cosim.axis import parameter_units
from feeddrive.cosim.errors import InputError
from feeddrive.cosim.recorded import (
    SAMPLED,
    add_recording_arguments,
    filter_cutoff,
    load_recording,
    mapped_roles,
    pairs,
    sampling_modes,
    to_motor_side,
)
from feeddrive.estimator import (
    EstimationOptions,
    EstimatorInputError,
    FilterSpec,
    MotionData,
    NotEnoughExcitation,
    estimate_motion,
)
from feeddrive.estimator.adequacy import check_motion
from feeddrive.estimator.motion import SAMPLING_DELAY
from feeddrive.estimator.segmentation import segment

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
    rec = to_motor_side(load_recording(args.data, roles, args.sample_time, args.delimiter, args.decimal), args)
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
        speed = np.gradient(sig["position"], rec.h)
    segments = segment(args.segment, rec.n, rec.h, speed, rec.signals.get("state"))
    if not segments:
        raise InputError(f"{args.data}: no high-speed motion found (--segment {args.segment})")
    results, datas = [], []
    for seg in segments:
        part = {k: v[seg.start:seg.stop] for k, v in sig.items()}
        data = MotionData(rec.h, t0=rec.t0 + seg.start * rec.h, delays=delays, **part)
        try:
            results.append(estimate_motion(data, options))
            datas.append(data)
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
        # -- model check on the recording's own residue (estimator/adequacy.py, issue 22 item 5) --
        for seg, data in zip(segments, datas):
            seg["model_check"] = check_motion(data, options).to_dict()
        print(json.dumps({"side": side, "segments": segments}))
    else:
        print(table(results, units))
        # -- model check on the recording's own residue (estimator/adequacy.py, issue 22 item 5) --
        print("\n".join(f"motion {k}: {check_motion(data, options).line()}" for k, data in enumerate(datas, 1)))
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
