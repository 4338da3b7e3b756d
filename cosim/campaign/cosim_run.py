"""The campaign's default run function: one co-simulation, its monitor and its estimates per motion."""
from __future__ import annotations

import copy
import json
import math
import tempfile
from collections.abc import Collection, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from feeddrive.cosim.campaign.schema import PHYSICAL, CampaignError, RunSpec
from feeddrive.estimator.errors import FAILURES
from feeddrive.estimator.estimate import METHODS
from feeddrive.models import feed_drive

# -- the co-simulation run function ----------------------------------------------------------------------
#: sensor outputs ``run_cosim`` needs recorded
RECORDED = ("u", "u_ref", "Im1", "Im2", "w_tach", "w_enc", "theta_enc")
#: monitor keys copied into a campaign record (residues and notes stay in the run's report.json)
MONITOR_KEYS = ("validated", "measurements_valid", "method", "parameters", "sensor_faults", "gain_ratio", "mismatch",
                "diagnosis", "processing_s", "error", "verdict")


def _injected(scenario: Any, truth: Mapping[str, float], nominal: Mapping[str, float],
              known: Collection[str] = ()) -> dict[str, Any]:
    """Faults a scenario injects: plant parameters off nominal (static or by event, their relative change), a
    plant parameter the monitor's model lacks (not in ``known``, its variables) set to a non-zero value
    (backlash [rad], its value: the model has no nominal for it), sensors off gain 1 / offset 0."""
    plant = {p: v / nominal[p] - 1 for p, v in truth.items() if not math.isclose(v, nominal[p], rel_tol=1e-9)}
    lacks = [(p, v) for p, v in scenario.plant.parameters.items()] + [
        (e.target.partition(".")[2], e.value) for e in scenario.events if e.target.startswith("plant.")]
    plant |= {p: float(v) for p, v in lacks if p not in nominal and p not in known and v != 0}
    sensors = {name: {"gain": ch.gain, "offset": ch.offset}
               for name, ch in scenario.sensors.channels().items() if ch.gain != 1 or ch.offset != 0}
    for e in scenario.events:
        component, _, rest = e.target.partition(".")
        name, _, what = rest.rpartition(".")
        if component == "sensors" and what in ("gain", "offset"):
            sensors.setdefault(name, {})[what] = e.value
    return {"plant": plant, "sensors": sensors}


#: recorded sensor signals of each quantity, in the monitor's pairs (speed: the encoder is handled apart)
_QUANTITIES = {"u": ("u", "u_ref"), "i": ("Im1", "Im2"), "w": ("w_tach", "encoder")}


def _estimates(signals: Mapping[str, np.ndarray], rows: slice, h: float, faulty: set[str], methods: list[str],
               config: Any) -> dict[str, dict]:
    """LS / IV / OE estimates of one motion from the recorded measurements, as the monitor forms them.

    Each quantity is the mean of its sensors without an injected fault (the monitor's signal of a pair
    that passes validation; the first sensor when both are faulty): ``u`` and ``u_ref``, ``Im1`` and
    ``Im2``, the tachometer and the encoder speed centred over ``config.encoder_window_s``
    (``cosim.monitor.centred_speed``). The filter and the speed threshold are the monitor's ``config``
    (``cosim.monitor.MonitorConfig``), so that the table scores the estimator the monitor validates.
    """
    from feeddrive.cosim.monitor import centred_speed, interval_mean_speed
    from feeddrive.estimator.all_or_none import estimate_motion
    from feeddrive.estimator.estimate import EstimationOptions, MotionData

    sampling = getattr(config, "sampling", {})  # interval means (plant.oversample > 1): as the monitor aligns them

    def measured(name: str) -> np.ndarray:
        if name == "encoder":
            w = centred_speed(signals["sensors.theta_enc"][rows], signals["sensors.w_enc"][rows], h,
                              config.encoder_window_s)
            return interval_mean_speed(w) if sampling.get("speed") == "mean" else w
        return signals[f"sensors.{name}"][rows]

    data = {q: np.mean([measured(c) for c in [c for c in pair if c not in faulty] or pair[:1]], axis=0)
            for q, pair in _QUANTITIES.items()}
    method = next(m for m in ("oe", "iv", "ls") if m in methods)
    delays = config.delays(h) if hasattr(config, "delays") else {}
    est = estimate_motion(MotionData(h=h, delays=delays, **data), EstimationOptions(method=method, filter=config.filter,
                                                                     speed_threshold=config.speed_threshold))
    return {m: {k: {"value": p.value, "ci95": list(p.ci95)} for k, p in getattr(est, m).parameters.items()}
            for m in methods if getattr(est, m) is not None}


def _scenario(spec: RunSpec) -> Any:
    """The run's resolved scenario: a copy of the one ``validate`` resolved in this process (or in the process
    it was forked from) when its FMU files are unchanged, else resolved now (see ``_RESOLVED``)."""
    key = _key(spec)
    hit = _RESOLVED.get(key)
    if hit is not None and _fmu_stats(hit[0]) == hit[1]:
        return copy.deepcopy(hit[0])  # ~1 ms; the run may change its scenario, never the cached one
    return copy.deepcopy(_resolve(spec, key))


def _resolve(spec: RunSpec, key: str) -> Any:
    """The run's scenario resolved and kept in ``_RESOLVED``. Runs that differ by their sensors' seed alone share
    one resolution (``_template``) with the seed set, when the resolution puts the seed nowhere else."""
    templated = _template(spec)
    if templated is None:
        return _keep(key, _from_dict(spec, spec.scenario))
    seed, base = templated
    return _keep(key, base.model_copy(update={"sensors": base.sensors.model_copy(update={"seed": seed})}))


def _template(spec: RunSpec) -> tuple[int, Any] | None:
    """``(the run's sensors' seed, its scenario resolved with ``SENTINEL_SEED`` for it)``, or None when the run is to
    be resolved as it is: a seed the sensors would refuse (their ``seed`` is a strict int >= 0, which
    ``model_copy`` does not check: resolved as given, with its error), or a resolution that puts the sentinel
    anywhere but the sensors' ``seed`` (a PMSM axis's servo sensors component takes the seed, cosim/drive.py).

    A Monte Carlo campaign's runs differ by this seed alone (``seed_keys``' default): their scenarios are one
    resolution (~1.5 ms: the plant's FMU found, its units checked, the sections validated), not one per run;
    ``run_campaign`` resolves every run's scenario before the first starts (1.5 s for 1000 runs), and each Dask
    worker's zygote again for its own runs (issue 26).
    """
    sensors = spec.scenario.get("sensors")
    seed = sensors.get("seed") if isinstance(sensors, Mapping) else None
    if type(seed) is not int or seed < 0:
        return None
    template = {**spec.scenario, "sensors": {**sensors, "seed": SENTINEL_SEED}}
    key = _key_of(template, spec.base_dir)
    hit = _TEMPLATES.get(key)
    if hit is None or _fmu_stats(hit[0]) != hit[1]:
        base = _from_dict(spec, template)
        text = repr(base) + repr(getattr(base, "__pydantic_private__", None))
        hit = _TEMPLATES[key] = (base, _fmu_stats(base), base.sensors.seed == SENTINEL_SEED
                                 and text.count(str(SENTINEL_SEED)) == 1)
        while len(_TEMPLATES) > RESOLVED_MAX:
            _TEMPLATES.pop(next(iter(_TEMPLATES)))
    return (seed, hit[0]) if hit[2] else None


#: the sensors' seed of a run's shared resolution (``_template``): a number found in the resolved scenario only
#: where it was put, unless the resolution copied it elsewhere
SENTINEL_SEED = 1_732_050_807
#: shared resolutions, by ``_key_of`` their mapping: (scenario, ``_fmu_stats``, whether only the sensors hold the seed)
_TEMPLATES: dict[str, tuple[Any, tuple, bool]] = {}


def _from_dict(spec: RunSpec, data: dict) -> Any:
    from feeddrive.cosim.errors import ScenarioError
    from feeddrive.cosim.scenario import scenario_from_dict

    try:
        return scenario_from_dict(data, source="scenario", base_dir=spec.base_dir)
    except ScenarioError as exc:
        raise ScenarioError(f"campaign run {spec.id} {json.dumps(spec.overrides)}: {exc}") from None


def _keep(key: str, scenario: Any) -> Any:
    _RESOLVED.pop(key, None)
    _RESOLVED[key] = (scenario, _fmu_stats(scenario))
    while len(_RESOLVED) > RESOLVED_MAX:  # the oldest first (dicts keep their insertion order)
        _RESOLVED.pop(next(iter(_RESOLVED)))
    return scenario


#: scenarios resolved in this process, by ``_key``: (scenario, ``_fmu_stats``). A run's scenario was resolved
#: three times (``run_campaign``'s check of every run, ``execute``'s in the worker, the run's own in its forked
#: child), reading and hashing its FMU each time (~20 ms each, most of it the model description): now once by
#: ``run_campaign``, whose pool workers are forked after it, and once per Dask worker (issue 26)
_RESOLVED: dict[str, tuple[Any, tuple]] = {}
#: at most this many kept (a resolved scenario is ~5 kB)
RESOLVED_MAX = 4096


def _key(spec: RunSpec) -> str:
    return _key_of(spec.scenario, spec.base_dir)


def _key_of(scenario: Mapping[str, Any], base_dir: str | None) -> str:
    return json.dumps([scenario, base_dir], sort_keys=True, default=str)


def _fmu_stats(scenario: Any) -> tuple:
    """(path, size, mtime) of the scenario's FMU files: a file rebuilt since the resolution is resolved again
    (a long-lived Dask worker keeps its cache from one campaign to the next)."""
    base = Path(getattr(scenario, "base_dir", None) or ".")
    paths = [scenario.plant.fmu] + [c.fmu for c in scenario.components if getattr(c, "fmu", None)]
    stats = []
    for path in paths:
        try:
            st = (base / Path(path).expanduser()).stat()
        except (OSError, TypeError):
            stats.append((str(path), None))
        else:
            stats.append((str(path), st.st_size, st.st_mtime_ns))
    return tuple(stats)


def run_cosim(spec: RunSpec) -> dict[str, Any]:
    """The default run function: one co-simulation (``cosim.run.run_scenario``) and its per-motion results.

    For each high-speed motion (NC ``state == 1``, one ``motion`` index): the true parameters at its
    start (the scenario's plant parameters with the plant events applied by its first step: an event
    applied at step n changes the plant over [t_n, ...), although the plant outputs show it from
    t_(n+1) on), the monitor's result when the scenario has a monitor, and the estimates of every method
    in ``spec.options["methods"]`` (default ``["ls", "iv"]``; add ``"oe"`` for the output-error
    refinement) computed from the recorded measurements with the monitor's signals and filter (see
    ``_estimates``), so that each method can be compared with the truth whatever the monitor's own method.

    Needs the signals ``nc.state``, ``nc.motion`` and ``sensors.<name>`` for every name in ``RECORDED``
    recorded (the default ``record: all``).
    """
    from feeddrive.cosim.master import event_step
    from feeddrive.cosim.monitor import MonitorConfig
    from feeddrive.cosim.run import run_scenario

    methods = _methods(spec)
    scenario = _scenario(spec)
    with tempfile.TemporaryDirectory(prefix="campaign-run-") as tmp:
        keep = spec.out_dir is not None  # else the files go with the temporary directory: no figures, no page
        res = run_scenario(scenario, spec.out_dir or tmp, overwrite=True, plots=keep, page=keep, signals=keep)
    config = scenario.monitor.config if isinstance(getattr(scenario.monitor, "config", None), MonitorConfig) \
        else MonitorConfig()
    if config.drive == "dc":
        model = feed_drive()
        nominal = model.nominal(("physical",))
        nominal = {p: nominal[p] for p in PHYSICAL}
    else:  # a PMSM axis: its model's parameters (R, L_d, L_q, psi_f, Jt, ft, Cd)
        from feeddrive.models.drives import drive_model

        model = drive_model(config.drive)
        nominal = {k: v for k, v in model.nominal(("physical",)).items() if k != "T0"}
    truth0 = nominal | {k: float(v) for k, v in scenario.plant.parameters.items() if k in nominal}
    t0 = float(res.time[0])
    # (step at which the event applies, parameter, value), the master's rule
    events = sorted((event_step(e.time, t0, scenario.step), e.target.partition(".")[2], float(e.value))
                    for e in scenario.events
                    if e.target.startswith("plant.") and e.target.partition(".")[2] in nominal)
    final = truth0 | {p: v for _, p, v in events}
    injected = _injected(scenario, final, nominal, model.variables)
    missing = [k for k in ("nc.state", "nc.motion") + tuple(f"sensors.{c}" for c in RECORDED) if k not in res.signals]
    if missing:
        raise CampaignError(f"run {spec.id}: the scenario does not record {missing} (use record: all)")
    state, motion = res.signals["nc.state"], res.signals["nc.motion"]
    monitor = {int(m["motion"]): m for m in res.report.get("motions", [])}
    motions = []
    for k in np.unique(motion[state == 1]).astype(int):
        idx = np.flatnonzero((state == 1) & (motion == k))
        rows = slice(int(idx[0]), int(idx[-1]) + 1)
        start = float(res.time[rows.start])
        truth = truth0 | {p: v for n, p, v in events if n <= rows.start}
        entry: dict[str, Any] = {"motion": int(k), "start": start, "end": float(res.time[rows.stop - 1]),
                                 "truth": truth, "validated": None, "parameters": {}, "sensor_faults": [],
                                 "diagnosis": []}
        try:  # a PMSM: the DC estimates on its q axis would be biased, the monitor's dq estimate only
            entry["methods"] = {} if config.drive != "dc" else _estimates(
                res.signals, rows, scenario.step, set(injected["sensors"]), methods, config)
        except FAILURES as exc:  # not enough excitation in this motion: no numbers, the reason kept (not a bug's)
            entry["methods"], entry["estimation_error"] = {}, " ".join(str(exc).split())
        entry |= {key: monitor[k][key] for key in MONITOR_KEYS if key in monitor.get(k, {})}
        motions.append(entry)
    out = {"truth": truth0, "injected": injected, "motions": motions, "wall_time_s": res.report.get("wall_time_s")}
    for key in ("following", "held_inputs"):  # verdicts that judge the set-up: the aggregate sets the run apart
        if res.report.get(key):
            out[key] = res.report[key]
    return out


def _methods(spec: RunSpec) -> list[str]:
    methods = list(spec.options.get("methods", ["ls", "iv"]))
    unknown = sorted(set(methods) - set(METHODS))
    if unknown or not methods:
        raise CampaignError(f"run_options.methods: expected some of {list(METHODS)}, got {methods}")
    return methods


def _validate(spec: RunSpec) -> None:
    _methods(spec)
    key = _key(spec)
    hit = _RESOLVED.get(key)
    if hit is None or _fmu_stats(hit[0]) != hit[1]:  # checked already here or in the process this one forked from
        _resolve(spec, key)
    if spec.out_dir is not None:  # its report.html: matplotlib and jinja2 imported once per worker
        import feeddrive.cosim.report.page  # noqa: F401


#: ``run_campaign`` checks every pending run's options and scenario with it before running any
run_cosim.validate = _validate


def _cost(spec: RunSpec) -> float | None:
    """The plant steps of a run (its stop time over the plant's finest step), from the scenario ``validate``
    resolved in this process (None when it did not): ``run_campaign`` starts the longest runs first."""
    from feeddrive.cosim.nc import SETTLING, plan_program

    hit = _RESOLVED.get(_key(spec))
    if hit is None:
        return None
    s = hit[0]
    stop = s.stop_time if s.stop_time is not None or s.nc is None else plan_program(s.nc)[-1][0] + SETTLING
    return None if stop is None else stop / s.step * s.plant.oversample


run_cosim.cost = _cost


def _prepare() -> None:
    """What every run needs built, once per worker process before its runs are forked (cosim/supervise.py).

    A forked child loses whatever it builds: pint's unit registry and the scenario's resolution (~1.5 s of
    a 1.4 s run) were paid again by every run of a spawned pool worker or Dask worker, which made 2 workers
    slower than 1 (issue 26). ``execute`` also resolves each run's scenario in the worker
    (``run_cosim.validate``, which imports the report page when the run keeps its files).

    The modules a run imports lazily are imported here too (``RUN_IMPORTS``): statsmodels' GLSAR, which the
    monitor loaded when it started (pandas, pyarrow, formulaic: 537 modules; now in numpy, estimator.glsar and
    estimator.hac), was imported again by every run's child, 0.85 s of its 1.35 s CPU (``PYTHONDONTWRITEBYTECODE`` also recompiles the feeddrive modules
    each time); with them here a run's child takes 0.5 s (issue 26). bench_campaign warns when a run
    imports a module that is not here.
    """
    import importlib

    from feeddrive.cosim.unit_map import _registry

    for name in RUN_IMPORTS:
        importlib.import_module(name)
    _registry()
    from feeddrive.estimator import blocks_c, lti, spline_c

    for compiled in (spline_c, blocks_c, lti):  # their C libraries built (or found) and loaded here, not per run
        compiled.available()


#: modules every co-simulation run with a monitor imports (some lazily, in the run): imported by ``prepare``
RUN_IMPORTS = ("feeddrive.cosim.monitor", "feeddrive.cosim.run", "feeddrive.estimator.estimate",
               "feeddrive.estimator.all_or_none", "feeddrive.estimator.lagged_iv",
               "feeddrive.cosim.fmu_factory", "feeddrive.cosim.fmu_adapter",
               "feeddrive.cosim.fmu_me", "feeddrive.cosim.fmi3_adapter", "feeddrive.estimator.compiled",
               "feeddrive.estimator.spline_c", "feeddrive.estimator.toeplitz", "feeddrive.cosim.held_inputs",
               "multiprocessing.synchronize", "feeddrive.cosim.sensors_servo", "feeddrive.estimator.redundancy_servo",
               # imported by the estimator's functions when first called (estimator.distributions, .kernels)
               "scipy.special", "scipy.fft")

run_cosim.prepare = _prepare
