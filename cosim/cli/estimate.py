"""``cosim estimate DATA.csv --map ROLE=COLUMN ...``: R, L, K, Jt, ft, Cd from a recorded CSV.

Roles: ``time``, ``voltage`` [V], ``current`` [A], ``speed``, ``position``, ``torque``, ``state``
(NC state, 1 = rapid). ``--drive pmsm`` (or ``pmsm-spm``) estimates a PMSM's R, L_d, L_q, psi_f, Jt, ft, Cd
(and K_t = 1.5 p psi_f, K_e = p psi_f, ``"derived"`` in the JSON) from the roles ``u_q, u_d`` [V] and
``i_q, i_d`` [A] in place of voltage and current, with ``--pole-pairs N`` (or ``--known p=N``). Columns are converted to SI from the unit in their header (``x [mm]``) or an
explicit ``--map ROLE=COLUMN*SCALE``. The mechanical parameters are estimated on the side the data are
on: the motor side (position in rad, speed in rad/s, torque in N.m: Jt in kg.m2, ft in N.m.s/rad, Cd in
N.m), or the table side of a linear axis when the headers say m, m/s or N (Jt is then the moving mass
in kg, ft in N.s/m, Cd in N); ``--pitch``/``--ratio`` convert table-side data to the motor side.
The recording is cut into high-speed motions (``--segment``), each estimated on its own; the output is
a table per motion with 95 % confidence intervals, or with ``--json``::

    {"side": "motor"|"table", "segments": [{"start": s, "end": s, "method": m, "rate_hz": r,
      "parameters": {"R": {"value": v, "ci95": [lo, hi], "unit": u}, ...}, "condition_number": c, "fit_error": e}]}

holding only the parameters the data determine; the others are listed in ``"refused"`` with the rule
that refuses them and its numbers (``estimator.partial``), and ``"fixed"`` says what was fixed in the
re-fit of the others (L = 0: the quasi-static electrical equation). A given parameter outside its physical
range or the ``--bounds`` is listed in ``"flags"`` (never to be validated), with the bounded estimate
(``"bounded"``). ``"method"`` is the method that ran; ``"method_requested"`` and ``"fallback"`` appear when
it is not the one asked for; ``"rate_hz"`` is the rate the fits ran at (the signals low-passed, then every
D-th sample kept: ``EstimationOptions.decimation``). When there are several motions, one of which nothing can be estimated is
reported on stderr and left out; if no motion is left, the exit status is 2. When every parameter of every motion
is refused (each with its reason in the table), the last line says so and the exit status is 3 (``NOTHING_GIVEN``,
as ``cosim monitor``'s nothing judged).

Several recordings (``cosim estimate A.csv B.csv`` or a quoted glob ``'run*.csv'``) of one machine: a row
per file (its motions pooled), a test of whether the files agree within their intervals and the pooled
estimate (``estimator.pooling``); ``--json``: ``{"side", "files": [{"file", "segments", "estimate"}],
"consistency": {"p_value", "verdict", "differ", "joint": {"chi2", "dof", "p_value"}, "per_parameter",
"pooled"}}``.
"""
from __future__ import annotations

import argparse
import glob
import json
import sys
import warnings
from pathlib import Path

from feeddrive.cosim.axis import parameter_units
from feeddrive.cosim.errors import InputError
from feeddrive.cosim.recorded import (
    SAMPLED,
    add_recording_arguments,
    filter_cutoff,
    mapped_roles,
    motions,
    no_motion,
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
)
from feeddrive.estimator.adequacy import check_motion
from feeddrive.estimator.motion import FIELDS, SAMPLING_DELAY
from feeddrive.estimator.partial import NOT_ASSUMED, estimate_parameters
from feeddrive.estimator.physical import impossible_values, parse_bounds
from feeddrive.estimator.pooling import pool
from feeddrive.estimator.pvalue_text import p_text

ROLES = {"time": None, "voltage": "u", "current": "i", "speed": "w", "position": "position", "torque": "torque",
         "state": None, "i_q": "i_q", "i_d": "i_d", "u_q": "u_q", "u_d": "u_d"}
#: roles of each drive kind (``--drive``): the DC motor's voltage and current, or a PMSM's dq ones
DRIVE_ROLES = {"dc": ("voltage", "current", "torque"), "pmsm": ("i_q", "i_d", "u_q", "u_d", "torque"),
               "pmsm-spm": ("i_q", "i_d", "u_q", "u_d", "torque")}


#: exit status when every parameter of every motion was refused (each with its reason): not a result
NOTHING_GIVEN = 3


class NothingEstimated(InputError):
    """No motion of a recording could be estimated (each was reported on stderr)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_recording_arguments(parser, ROLES, EstimationOptions().filter.cutoff_hz, several=True)
    parser.add_argument("--known", action="append", default=[], metavar="NAME=VALUE",
                        help="a parameter known in advance, fixed in the fit of the others, e.g. R=0.6 (repeat "
                             "for several; a known Jt, ft or Cd needs K known too, or a torque signal)")
    parser.add_argument("--offset", action="store_true", help="also estimate a constant torque offset T0")
    parser.add_argument("--drive", choices=sorted(DRIVE_ROLES), default="dc",
                        help="the motor's model: dc (roles voltage, current; default), pmsm (roles u_q, u_d, i_q, "
                             "i_d in the dq frame, peak values; R, L_d, L_q, psi_f and K_t, K_e) or pmsm-spm "
                             "(surface magnets, L_q = L_d)")
    parser.add_argument("--pole-pairs", type=float, default=None, metavar="N",
                        help="a PMSM's pole pairs (default: the model's 4; the same as --known p=N)")
    parser.add_argument("--bounds", action="extend", nargs="+", default=[], metavar="NAME=LOW:HIGH",
                        help="bounds on a parameter beyond its physical range, either side may be empty, e.g. "
                             "Jt=4e-6: (the rotor's own inertia) ft=0:1; an estimate outside is flagged and a "
                             "bounded estimate offered")
    parser.epilog = (f"exit status: 0 a parameter given; {NOTHING_GIVEN} every parameter of every motion refused (the "
                     "last line says so, each reason above); 2 bad input or no motion to estimate (one line)")


def data_files(patterns: list[str]) -> list[str]:
    """The recordings named, a quoted glob pattern expanded (sorted); a pattern matching nothing is an error."""
    files = []
    for item in patterns:
        if not Path(item).exists() and glob.has_magic(item):
            found = sorted(glob.glob(item))
            if not found:
                raise InputError(f"{item}: no file matches this pattern")
            files.extend(found)
        else:
            files.append(item)
    return files


def estimate_file(path: str, args: argparse.Namespace, known: dict, bounds: dict) -> tuple[str, list, dict, list]:
    """Load one recording (``cosim.recorded.load_recording``: any reader that returns a ``Recording`` plugs in
    here), cut it into motions and estimate each; returns (side, estimates, the recording's JSON keys,
    the model checks on each motion's own residue).
    Motions of which nothing can be estimated are reported on stderr and left out; none left is an
    ``InputError``."""
    drive = getattr(args, "drive", "dc")
    roles = mapped_roles(args, [r for r in ROLES if r not in set().union(*DRIVE_ROLES.values()) - set(DRIVE_ROLES[drive])])
    rec = read_recording(args, roles, path)
    side = rec.side or "motor"
    if side == "table" and drive != "dc":
        raise InputError(f"{path}: a {drive} drive's voltage equations need the motor speed: map speed in rad/s or "
                         f"rpm, or give --pitch (and --ratio) to convert the table-side columns")
    options = EstimationOptions(method=args.method, filter=FilterSpec(filter_cutoff(args, rec.h)), known=known,
                                offset=args.offset, speed_threshold=args.speed_threshold,
                                speed_unit="m/s" if side == "table" else "rad/s", model=drive)
    modes = sampling_modes(args, {q: roles[q] for q in SAMPLED if q in roles}, path)
    delays = {SAMPLED[q]: SAMPLING_DELAY[m] * rec.h for q, m in modes.items() if SAMPLING_DELAY[m]}
    sig = {ROLES[r]: v for r, v in rec.signals.items() if ROLES[r]}
    speed = sig.get("w")
    if speed is None and "position" in sig:
        speed = rec.gradient(sig["position"])
    segments = motions(args, rec, speed, rec.signals.get("state"))
    if not segments:
        raise NothingEstimated(f"{path}: {no_motion(args, rec, speed, rec.signals.get('state'))}")
    results, datas = [], []
    for seg in segments:
        part = {k: v[seg.start:seg.stop] for k, v in sig.items()}
        dq = {k: part.pop(k) for k in list(part) if k not in FIELDS}  # a PMSM's dq signals
        data = MotionData(rec.h, t0=rec.time(seg.start), delays=delays, signals=dq, **part)
        try:
            results.append(estimate_parameters(data, options, bounds))
            datas.append(data)
        except (NotEnoughExcitation, EstimatorInputError) as exc:  # e.g. a rapid block too short to filter
            if len(segments) == 1:
                raise
            print(f"cosim estimate: motion {data.t0:.4g}-{data.t0 + (data.n - 1) * data.h:.4g} s left out: {exc}",
                  file=sys.stderr)
    if not results:
        raise NothingEstimated(f"{path}: no motion could be estimated (see above)")
    # -- model check on the recording's own residue (estimator/adequacy.py, issue 22 item 5) --
    return side, results, recording_json(rec), [check_motion(data, options) for data in datas]


def main(args: argparse.Namespace) -> int:
    known = {}
    for name, value in pairs(args.known, "--known").items():
        try:
            known[name] = float(value)
        except ValueError:
            raise InputError(f"--known {name}={value!r}: expected a number") from None
    try:
        impossible_values(known, "--known")
    except EstimatorInputError as exc:
        raise InputError(str(exc)) from None
    if getattr(args, "pole_pairs", None) is not None:
        if args.drive == "dc" or not args.pole_pairs > 0:
            raise InputError(f"--pole-pairs {args.pole_pairs:g}: expected a positive number of pole pairs with "
                             f"--drive pmsm or pmsm-spm")
        known["p"] = args.pole_pairs
    try:
        bounds = parse_bounds(args.bounds)
    except EstimatorInputError as exc:
        raise InputError(str(exc)) from None
    files = data_files(args.data)
    with warnings.catch_warnings():  # numerical trouble becomes a refusal or a fallback with its reason
        warnings.simplefilter("ignore", RuntimeWarning)
        per_file = []
        for path in files:
            try:
                per_file.append((path, *estimate_file(path, args, known, bounds)))
            except (NotEnoughExcitation, NothingEstimated) as exc:  # one of several repeats: the others still count
                if len(files) == 1:
                    raise
                print(f"cosim estimate: {path} left out: {exc}", file=sys.stderr)
    if not per_file:
        raise InputError(f"none of the {len(files)} recordings could be estimated (see above)")
    sides = {side for _, side, _, _, _ in per_file}
    if len(sides) > 1:
        raise InputError(f"the recordings are on different sides ({', '.join(sorted(sides))}): give --pitch or "
                         f"units that agree")
    side = sides.pop()
    units = model_units(getattr(args, "drive", "dc")) | parameter_units(side, "linear" if side == "table" else "rotary")
    for path, _, _, rec_keys, _ in per_file:  # a unit assumed is said (after any error: that stays one line)
        for note in rec_keys.get("unit_assumptions", ()):
            print(f"cosim estimate: {path}: {note}", file=sys.stderr)
    if len(per_file) == 1:
        results, rec_keys, checks = per_file[0][2:]
        if args.json:
            print(json.dumps({"side": side, **rec_keys, "segments": [
                _with_units(r.to_dict(), units) | {"model_check": c.to_dict()} for r, c in zip(results, checks)]}))
        else:
            print(table(results, units))
            print("\n".join(f"motion {k}: {c.line()}" for k, c in enumerate(checks, 1)))
        return nothing_given([r for _, _, rs, _, _ in per_file for r in rs], args.json)
    # pooled and compared with the intervals not conditional on a refused parameter (MotionEstimate.joint)
    all_checks = [checks for *_, checks in per_file]
    rows = [(path, results, pool([r.joint or r.result for r in results])) for path, _, results, _, _ in per_file]
    # between files: a file's one motion with its full covariance, or its motions pooled
    verdict = pool([(results[0].joint or results[0].result) if len(results) == 1 else pooled.as_result()
                    for _, results, pooled in rows])
    if args.json:
        files_out = [{"file": path, "segments": [_with_units(r.to_dict(), units) | {"model_check": c.to_dict()}
                                                 for r, c in zip(results, checks)],
                      "estimate": _units(_params(pooled.parameters), units)}
                     for (path, results, pooled), checks in zip(rows, all_checks)]
        out = verdict.to_dict()
        _units(out["pooled"], units)
        print(json.dumps({"side": side, "files": files_out, "consistency": out}))
    else:
        print(several_table(rows, verdict, units))
        # -- model check on each recording's own residue (estimator/adequacy.py) --
        print("\n".join(f"{path} motion {k}: {c.line()}" for (path, *_), checks in zip(rows, all_checks)
                        for k, c in enumerate(checks, 1)))
    return nothing_given([r for _, _, rs, _, _ in per_file for r in rs], args.json)


def nothing_given(results: list, json_out: bool) -> int:
    """0 when some motion gives a parameter; else ``NOTHING_GIVEN`` with a last line saying so (stderr with
    ``--json``): every parameter of every motion refused, each with its reason in the table or the JSON. (A motion
    that never reached the estimator, or none found, is exit 2 with one line.)"""
    if any(r.parameters for r in results):
        return 0
    what = "the motion" if len(results) == 1 else f"each of the {len(results)} motions"
    print(f"nothing estimated: every parameter of {what} refused, each with its reason "
          f"({'refused in the JSON' if json_out else 'above'})", file=sys.stderr if json_out else sys.stdout)
    return NOTHING_GIVEN


def model_units(drive: str) -> dict[str, str]:
    """Units of a drive model's physical parameters and derived quantities (motor side: L_d, psi_f, K_t, ...)."""
    from feeddrive.models.drives import derived_quantities, drive_model

    model = drive_model(drive)
    return ({v.name: v.unit for v in model.of_kind("physical")}
            | {n: unit for n, (unit, _, _) in derived_quantities(model).items()})


def _params(parameters: dict) -> dict:
    return {n: {"value": p.value, "ci95": list(p.ci95)} for n, p in parameters.items()}


def _units(params: dict, units: dict) -> dict:
    for name, p in params.items():
        p["unit"] = units[name]
    return params


def _with_units(seg: dict, units: dict) -> dict:
    _units(seg["parameters"], units)
    _units(seg.get("derived", {}), units)
    return seg


def several_table(rows, verdict, units: dict[str, str]) -> str:  # noqa: ANN001 - [(path, estimates, Pooled)]
    """A row per file (value +- 95 % half-width of each parameter), the agreement test and the pooled estimate."""
    names = list(verdict.parameters)
    lines = ["file".ljust(24) + "".join(f"{n:>24}" for n in names)]
    for path, results, pooled in rows:
        cells = []
        for n in names:
            p = pooled.parameters.get(n)
            cells.append(f"{p.value:.5g} +- {(p.ci95[1] - p.ci95[0]) / 2:.2g}".rjust(24) if p else "refused".rjust(24))
        lines.append(Path(path).name[:23].ljust(24) + "".join(cells))
        for r in results:
            for n, why in r.refused.items():
                lines.append(f"  {r.start:.4g}-{r.end:.4g} s: {n} refused: {why}")
            for n, why in r.flags.items():
                lines.append(f"  {r.start:.4g}-{r.end:.4g} s: {n} FLAGGED, not to be validated: {why}")
            if r.hint:
                lines.append(f"  {r.start:.4g}-{r.end:.4g} s: {r.hint}")
    if not verdict.per_parameter:  # no parameter given by two files: no agreement to test
        lines.append("agreement: not tested: no parameter is given by two files or more (see the refusals above)")
    else:
        lines.append(f"agreement: {verdict.verdict} ({p_text(verdict.p_value)}, Bonferroni over "
                     f"{len(verdict.per_parameter)} parameters; joint chi2 {verdict.chi2:.3g} on {verdict.dof} dof, "
                     f"{p_text(verdict.joint_p)})")
        lines.append("  per parameter: " + ", ".join(f"{n} chi2 {c:.3g} on {d}, {p_text(p)}"
                                                     for n, (c, d, p) in verdict.per_parameter.items()))
    lines.append("pooled:")
    for n, p in verdict.parameters.items():
        note = ", the files differ" if n in verdict.differ else ""
        lines.append(f"  {n:3} {p.value:12.6g} {units[n]:10} 95 % CI [{p.ci95[0]:.6g}, {p.ci95[1]:.6g}] "
                     f"({verdict.count[n]} file(s){note})")
    return "\n".join(lines)


def table(results, units: dict[str, str]) -> str:  # noqa: ANN001 - list of estimator.MotionEstimate
    """One block per motion: parameter, value, unit (``units``: the data's side), 95 % confidence interval;
    then the refused parameters with their reason, the flagged ones and the bounded estimate."""
    lines = []
    for k, r in enumerate(results, 1):
        lines.append(f"motion {k}: {r.start:.4g}-{r.end:.4g} s, {r.method_used.upper()}, condition number "
                     f"{r.condition_number:.3g}, fit error {r.fit_error:.3g}")
        if r.result.message:
            lines.append(f"  ({r.result.message})")
        w = max([3, *map(len, r.parameters)])  # psi_f: a PMSM's names are longer than the DC drive's
        for name, p in r.parameters.items():
            flag = "  FLAGGED" if name in r.flags else ""
            lines.append(f"  {name:{w}} {p.value:12.6g} {units[name]:10} 95 % CI [{p.ci95[0]:.6g}, {p.ci95[1]:.6g}]{flag}")
        for name, p in r.derived.items():  # K_t = 1.5 p psi_f, K_e = p psi_f
            lines.append(f"  {name:{w}} {p.value:12.6g} {units[name]:10} 95 % CI [{p.ci95[0]:.6g}, {p.ci95[1]:.6g}] "
                         f"(derived)")
        for name, why in r.refused.items():
            # an impossible estimate (R < 0) is the fit's, not a condition of the others' intervals (partial._rule)
            fixed = (f" (fixed at {r.fixed[name]:.4g} in the re-fit of the others: their intervals hold given this "
                     f"value)" if name in r.fixed and NOT_ASSUMED not in why else "")
            lines.append(f"  {name:3} refused: {why}{fixed}")
        for name, why in r.flags.items():
            lines.append(f"  {name:3} FLAGGED, not to be validated: {why}")
        if r.hint:  # one quantity's reversed sign explains the flags (estimator/sign_convention.py)
            lines.append(f"  hint: {r.hint}")
        if r.bounded:
            lines.append("  bounded estimate: " + ", ".join(f"{n} {v:.6g} {units[n]}" for n, v in r.bounded.items()))
    return "\n".join(lines)
