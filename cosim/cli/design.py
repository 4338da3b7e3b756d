"""``cosim design SCENARIO.yaml``: the rapid-move acceleration that minimises the parameters' variance.

Only the slope of the NC's trapezoid may be adapted (paper II.C). For the scenario's first high-speed
move (``--item`` to choose another), every candidate acceleration is scored by
``estimator.design.design_acceleration`` (noise-free closed-loop plant, the estimator's regressions,
predicted covariance sigma^2 (Phi^T Phi)^-1, criterion: sum of squared relative standard errors),
with the move's distance and top speed kept. The speed reference is the NC's planned speed
(feed-forward; the position loop only corrects small errors); the noise levels are the scenario's
voltage, first current sensor and tachometer noise. ``--verify N`` then runs a small campaign
(N noise seeds at the default and at the chosen slope) and prints the measured spread of the LS and
IV estimates beside the prediction.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from feeddrive.cosim.errors import InputError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", type=Path, help="scenario YAML file")
    parser.add_argument("--item", type=int, help="index of the rapid or tool_change item in nc.program "
                                                 "(default: the first one)")
    parser.add_argument("--accel", help="candidate accelerations [m/s^2], comma-separated "
                                        "(default 0.2, 0.3, ..., 2.0)")
    parser.add_argument("--verify", type=int, default=0, metavar="N",
                        help="check with a campaign of N >= 2 runs at the default and at the chosen slope "
                             "(the measured spread needs two)")
    parser.add_argument("--workers", type=int, default=1, help="worker processes of the --verify campaign")
    parser.add_argument("--out", type=Path, help="out dir of the --verify campaign (default campaigns/design-<name>)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def reference(nc, item: int, accel: float, h: float, tail: float = 0.1) -> np.ndarray:
    """Planned motor speed [rad/s] of program item ``item`` at ``accel``, sampled every ``h``, then ``tail`` s at rest.

    Parameters
    ----------
    nc : cosim.nc.NCConfig
    item : int
        Index of a ``rapid`` or ``tool_change`` item.
    accel : float
        Acceleration [m/s^2] replacing the item's.
    h : float
        Sampling period [s].
    """
    from feeddrive.cosim.nc import plan_program

    start = next(s[1] for s in plan_program(nc) if s[6] == item)
    line = nc.program[item]
    kind, move = line.move
    one = nc.model_copy(update={"start": start, "program": (line.model_copy(update={kind: move.model_copy(
        update={"accel": accel})}),)})
    segments = plan_program(one)
    t_end = segments[-1][0]
    t = np.arange(int(math.ceil((t_end + tail) / h))) * h
    k = np.searchsorted([s[0] for s in segments], t, side="right") - 1
    v = np.array([s[2] for s in segments])[k] + np.array([s[3] for s in segments])[k] * (t - np.array([s[0] for s in segments])[k])
    return v * 2 * math.pi * nc.belt_ratio / nc.pitch


def main(args: argparse.Namespace) -> int:
    from feeddrive.cosim.scenario import load_scenario
    from feeddrive.estimator.design import design_acceleration, physical
    from feeddrive.estimator.motion import EstimationOptions

    # checked now, not after the whole design sweep
    if args.verify < 0 or args.verify == 1:
        raise InputError(f"--verify: expected 0 (no check) or a number of runs >= 2 per slope, got {args.verify}")
    if args.workers < 1:
        raise InputError(f"--workers: expected >= 1, got {args.workers}")
    scenario = load_scenario(args.scenario)
    items = [k for k, line in enumerate(scenario.nc.program) if line.move[0] in ("rapid", "tool_change")]
    item = items[0] if args.item is None and items else args.item
    if item not in items:
        raise InputError(f"{args.scenario}: nc.program{'' if item is None else f'[{item}]'}: expected a rapid or "
                         f"tool_change item (the program has them at {items})")
    kind, move = scenario.nc.program[item].move
    try:
        accels = ([float(a) for a in args.accel.split(",")] if args.accel else
                  [round(0.1 * k, 10) for k in range(2, 21)])
    except ValueError:
        raise InputError(f"--accel: expected comma-separated numbers [m/s^2], got {args.accel!r}") from None
    if any(not a > 0 for a in accels):
        raise InputError(f"--accel: accelerations must be > 0 m/s^2, got {accels}")
    model, noise, note = drive_noise(scenario)
    options = EstimationOptions(model=model)

    # the design simulates the built-in model: a vendor plant's own parameter names are not used
    params = {k: v for k, v in scenario.plant.parameters.items() if k in model.nominal()}
    from tqdm import tqdm

    from feeddrive.cosim.progress import enabled

    # each candidate is a closed-loop simulation and its regressions (~5 s each): one bar step per slope
    with tqdm(total=len(accels), desc="design", unit="slope", disable=not enabled(not args.no_progress)) as bar:
        def ref(a: float) -> np.ndarray:  # called at the start of each candidate: the previous one is done
            if started:
                bar.update()
            started.append(a)
            bar.set_postfix_str(f"accel {a:g} m/s^2")
            return reference(scenario.nc, item, a, scenario.step)

        started: list[float] = []
        best, candidates = design_acceleration(ref, accels, scenario.step, noise, options, params=params)
        bar.update()
    names = physical(model)
    print(f"{scenario.name}: nc.program[{item}].{kind}, default accel {move.accel} m/s^2; noise "
          + ", ".join(f"{k} {v:g} {model.variables[k].unit}" for k, v in noise.items()) + note)
    print(f"{'accel':>6} {'time s':>7} " + " ".join(f"{p + ' %':>8}" for p in names) + f" {'J':>9} {'peak A':>7}")
    for c in candidates:
        mark = " <- best" if c is best else "" if c.feasible else " (saturates)"
        print(f"{c.accel:6.2f} {c.duration:7.2f} " + " ".join(f"{100 * c.rel_std[p]:8.3f}" for p in names)
              + f" {c.criterion:9.3g} {c.peak_current:7.1f}{mark}")
    print(f"chosen slope: {best.accel} m/s^2 (criterion: sum of squared relative standard errors)")
    if args.verify:
        if model.name != "FeedDrive":
            raise InputError(f"--verify: the campaign check compares the DC drive's estimates; the {model.name} "
                             f"design is printed above without it")
        verify(args, scenario, item, kind, move.accel, best.accel, noise, params)
    return 0


def drive_noise(scenario) -> tuple:
    """The axis's drive model, the white noise std of each of its measured signals, and a note on what is left out.

    DC: the voltage, the first current sensor and the tachometer. PMSM (``axis.drive.kind: pmsm``, the servo
    sensors' component): the dq voltages' channel, and the dq currents from three phase sensors of noise s by
    the amplitude-invariant Park transform, ``s sqrt(2 / 3)``; the speed from the encoder is differentiated
    quantisation, not white noise, and is left out of the prediction (said in the note).
    """
    from feeddrive.cosim.drive import SERVO
    from feeddrive.cosim.sensors_servo import ServoSensorsConfig
    from feeddrive.models.drives import drive_model, with_design

    drive = scenario.axis.drive
    if drive is None or drive.kind == "dc":
        return drive_model("dc"), {"u": scenario.sensors.voltage.noise, "i": scenario.sensors.current[0].noise,
                                   "w": scenario.sensors.tachometer.noise}, ""
    spec = next((c for c in scenario.components if c.name == SERVO), None)
    cfg = ServoSensorsConfig(**(spec.config if spec is not None else {}))
    model = with_design(drive_model(drive.kind), {"p": float(drive.pole_pairs or cfg.pole_pairs)})
    i = float(np.sqrt(np.mean([ph.noise ** 2 for ph in cfg.phases]) * 2 / 3))
    noise = {"u_q": cfg.voltage.noise, "u_d": cfg.voltage.noise, "i_q": i, "i_d": i}
    return model, noise, " (the encoder's speed: not in the prediction)"


def verify(args, scenario, item: int, kind: str, default: float, best: float, noise, params) -> None:
    """Small campaign: N runs at each slope; measured relative std of LS and IV against the prediction."""
    from feeddrive.cosim.campaign import Campaign, run_campaign
    from feeddrive.cosim.progress import enabled
    from feeddrive.estimator.design import PHYSICAL, predicted_std, simulate_closed_loop

    key = f"nc.program[{item}].{kind}.accel"
    campaign = Campaign(name=f"design-{scenario.name}", base=str(Path(args.scenario).resolve()), seed=1,
                        repetitions=args.verify, sweep={key: sorted({default, best}), "monitor": [None]},
                        run_options={"methods": ["ls", "iv"]})
    result = run_campaign(campaign, args.out or Path("campaigns", campaign.name), workers=args.workers,
                          progress=enabled(not args.no_progress), plots=False)
    print(f"\nverification: {args.verify} runs per slope ({len(result.failed)} failed)")
    print(f"{'accel':>6} {'param':>5} {'predicted %':>12} {'LS std %':>9} {'IV std %':>9}")
    for accel in sorted({default, best}):
        sig = simulate_closed_loop(reference(scenario.nc, item, accel, scenario.step), scenario.step, params)
        predicted = predicted_std(sig, scenario.step, noise, params=params)
        runs = [r["result"] for r in result.records if r["status"] == "ok" and r["overrides"][key] == accel]
        for p in PHYSICAL:
            spread = {}
            for method in ("ls", "iv"):
                e = [m["methods"][method][p]["value"] / m["truth"][p] - 1 for r in runs for m in r["motions"]
                     if method in m.get("methods", {}) and p in m["methods"][method]]
                spread[method] = 100 * np.std(e, ddof=1) if len(e) > 1 else math.nan
            print(f"{accel:6.2f} {p:>5} {100 * predicted[p]:12.3f} {spread['ls']:9.3f} {spread['iv']:9.3f}")
