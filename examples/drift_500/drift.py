"""500 tool changes over simulated months: slide-way wear, oil ageing and an oil change, brush wear.

The axis makes 3 tool changes a day, so 500 motions span about 5.5 months. Its plant drifts
(``parameters_at``), relative to the healthy values:

* slide-way wear: Cd +20 % and ft +25 % over the 500 motions (linear, permanent);
* lubricating-oil ageing: Cd +40 % and ft +50 % per 500 motions since the last oil change; the oil
  is changed before motion ``oil_change`` (default 300), so the friction falls back to the wear part;
* brush wear: R +30 % over the 500 motions.

How it runs in minutes. Only the high-speed motions are simulated: each tool change is one short
scenario (``tool_change.yaml``: the 0.15 m out-and-back rapid move, ~2 s simulated), run with
``cosim.run.run_scenario`` and the monitor in the loop. Nothing else of the months is simulated; the
state that links the tool changes is carried between the runs:

1. the plant's parameters at motion k, a pure function of k (``parameters_at``), written into the
   scenario's ``plant.parameters`` (and the sensor seed k into ``sensors.seed``);
2. the monitor's history, one SQLite file (``monitor.db`` = OUT/history.db) shared by every run: at
   each run's setup the monitor reads theta_{j-1}, its healthy baseline (the first validated motions)
   and the recent trend back from it, exactly as on a machine between two tool changes.

The history is also the resume point: a second start on the same OUT continues after the motions
already stored. Results in OUT: history.db, drift.json (truth and monitor result per motion, the
motion at which each fault is first diagnosed, detection delays), plots/trends.png.

    python examples/drift_500/drift.py [--motions 500] [--out runs/drift_500] [--overwrite]
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

HERE = Path(__file__).resolve().parent
AXIS = "X"
PER_DAY = 3
#: relative rise over ``n`` motions: wear (permanent) and oil ageing (reset by the oil change)
WEAR = {"Cd": 0.20, "ft": 0.25, "R": 0.30}
OIL = {"Cd": 0.40, "ft": 0.50}


def parameters_at(k: int, n: int = 500, oil_change: int | None = 300) -> dict[str, float]:
    """True physical parameters at motion k (0-based) of an ``n``-motion drift.

    Parameters
    ----------
    k : int
        Motion index.
    n : int
        Motions over which the WEAR and OIL rises are reached.
    oil_change : int or None
        Motion before which the oil is changed (oil ageing restarts from 0), or None.

    Returns
    -------
    dict
        R [Ohm], L [H], K [N.m/A], Jt [kg.m^2], ft [N.m.s/rad], Cd [N.m].
    """
    from feeddrive.models import feed_drive

    nominal = {p: v for p, v in feed_drive().nominal(("physical",)).items() if p != "T0"}
    since_oil = k - oil_change if oil_change is not None and k >= oil_change else k
    return {p: v * (1 + WEAR.get(p, 0.0) * k / n + OIL.get(p, 0.0) * since_oil / n) for p, v in nominal.items()}


def run_drift(out: Path, motions: int = 500, oil_change: int | None = 300, overwrite: bool = False,
              progress: bool = True) -> dict:
    """Run (or resume) the drift and write OUT/drift.json and OUT/plots/trends.png; see the module docstring.

    ``motions`` < 500 runs the first motions of the same 500-motion drift (the same plant at each k).
    """
    from tqdm import tqdm

    from feeddrive.cosim.campaign import aggregate
    from feeddrive.cosim.errors import InputError
    from feeddrive.cosim.run import run_scenario
    from feeddrive.cosim.scenario import scenario_from_dict

    out.mkdir(parents=True, exist_ok=True)
    # absolute: a relative monitor.db is read against the scenario's folder (examples/drift_500/), not
    # against the current directory where OUT was created
    db = (out / "history.db").resolve()
    if overwrite:
        for f in [db, db.with_name("history.db-wal"), db.with_name("history.db-shm"), out / "drift.json"]:
            f.unlink(missing_ok=True)
    base = yaml.safe_load((HERE / "tool_change.yaml").read_text())
    done = len(_tool_changes(db))
    if done > motions:
        raise InputError(f"{db}: holds {done} tool changes, more than --motions {motions}; pass --overwrite to start again")
    wall = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="drift-") as tmp:
        for k in tqdm(range(done, motions), initial=done, total=motions, unit="motion", disable=not progress):
            data = json.loads(json.dumps(base))
            data["plant"]["parameters"] = parameters_at(k, 500, oil_change)
            data["sensors"]["seed"] = k
            data["monitor"] |= {"db": str(db), "scenario": f"tool change {k}"}
            run_scenario(scenario_from_dict(data, source=f"drift motion {k}", base_dir=HERE), tmp,
                         overwrite=True, plots=False)
    stored = _tool_changes(db)
    result = {"truth": parameters_at(0, 500, oil_change), "injected": {},
              "motions": [m | {"truth": parameters_at(k, 500, oil_change), "day": k / PER_DAY}
                          for k, m in enumerate(stored)]}
    first: dict[str, int] = {}
    for k, m in enumerate(stored):
        for d in m.get("diagnosis") or ():
            first.setdefault(d["fault"], k)
    agg = aggregate([{"status": "ok", "index": 0, "result": result}])
    summary = {"motions": len(stored), "oil_change": oil_change, "simulated_now": motions - done,
               "wall_time_s": time.perf_counter() - wall,
               "validated": sum(bool(m.get("validated")) for m in stored),
               "first_diagnosis": {f: {"motion": k, "day": round(k / PER_DAY, 1),
                                       "relative_change": {p: parameters_at(k, 500, oil_change)[p] / result["truth"][p] - 1
                                                           for p in ("R", "ft", "Cd")}}
                                   for f, k in sorted(first.items(), key=lambda kv: kv[1])},
               "detection": agg.detection, "estimation": agg.estimation}
    (out / "drift.json").write_text(json.dumps(summary | {"per_motion": result["motions"]}, indent=1, default=float))
    plot_trends(result, first, oil_change, out / "plots" / "trends.png")
    return summary


def _tool_changes(db: Path) -> list[dict]:
    """The monitor's result of each tool change k, in order (identification motions that the monitor's
    request inserted into a run are stored too, under the same scenario, and skipped here)."""
    from feeddrive.estimator.history import History

    first: dict[int, dict] = {}
    with History(db) as history:
        for m in history.motions(AXIS):
            first.setdefault(int(m["scenario"].rpartition(" ")[2]), m)
    return [first[k] for k in range(len(first))]


#: the units of the plotted parameters
UNITS = {"R": "Ohm", "ft": "N.m.s/rad", "Cd": "N.m"}


def plot_trends(result: dict, first: dict[str, int], oil_change: int | None, path: Path) -> Path:
    """Estimated (validated: dots with 95 % CI, not validated: grey) and true R, ft, Cd against the motion,
    with the oil change and the first diagnosis of each fault marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    motions = result["motions"]
    k = np.arange(len(motions))
    names = ("R", "ft", "Cd")
    fig, axes = plt.subplots(len(names), 1, figsize=(9, 7.5), sharex=True)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, name in zip(axes, names):
        est = np.array([m.get("parameters", {}).get(name, {}).get("value", np.nan) for m in motions])
        ci = np.array([m.get("parameters", {}).get(name, {}).get("ci95") or [np.nan, np.nan] for m in motions], float)
        ok = np.array([bool(m.get("validated")) for m in motions])
        ax.errorbar(k[ok], est[ok], yerr=np.abs(ci[ok].T - est[ok]), fmt=".", ms=3, lw=0.5, label="validated estimate")
        ax.plot(k[~ok], est[~ok], ".", color="0.6", ms=3, label="not validated")
        # the truth holds over each motion: the oil change is a step between two motions, not a slope over one
        ax.step(k, [m["truth"][name] for m in motions], "k-", where="mid", lw=1.2, label="truth")
        if oil_change is not None and oil_change < len(motions):
            ax.axvline(oil_change, color="g", ls=":", label="oil change")
        for c, (fault, at) in enumerate(sorted(first.items(), key=lambda kv: kv[1])):
            ax.axvline(at, color=colours[(c + 3) % len(colours)], ls="--", lw=1, label=f"first: {fault}")
        ax.set_ylabel(f"{name} [{UNITS[name]}]")
        ax.grid(True)
    axes[0].legend(fontsize=7, ncol=2)
    axes[-1].set_xlabel(f"tool change (motion); {PER_DAY} per day")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--motions", type=int, default=500, help="tool changes to simulate (default 500)")
    parser.add_argument("--oil-change", type=int, default=300, help="motion before which the oil is changed")
    parser.add_argument("--out", type=Path, default=Path("runs/drift_500"))
    parser.add_argument("--overwrite", action="store_true", help="start again: discard OUT/history.db")
    args = parser.parse_args(argv)
    s = run_drift(args.out, args.motions, args.oil_change, args.overwrite, progress=sys.stderr.isatty())
    print(f"{s['motions']} motions ({s['validated']} validated; {s['simulated_now']} simulated now in "
          f"{s['wall_time_s']:.0f} s) -> {args.out}")
    for fault, at in s["first_diagnosis"].items():
        rel = ", ".join(f"{p} {100 * v:+.1f} %" for p, v in at["relative_change"].items())
        print(f"  first diagnosed: {fault:40s} motion {at['motion']:4d} (day {at['day']:5.1f}; true {rel})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
