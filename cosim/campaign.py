"""Campaigns: many co-simulations of one base scenario, with swept and drawn changes, and their statistics.

A control engineer trusts a monitor only after measuring it over many runs: how often it detects each
fault, how often it raises a false alarm, how early it sees a slow drift, and how far its parameter
estimates are from the truth. A campaign file says which runs to make::

    name: cd-sweep
    base: ../tool_change.yaml          # a scenario file (relative to this file) or an inline mapping
    seed: 42                           # campaign seed: every run's seed and draws derive from it
    repetitions: 3                     # runs per grid point, each with its own seed
    sweep:                             # a full grid over dotted scenario keys
      plant.parameters.Cd: [1.2, 1.5, 1.8]
      sensors.current[0].offset: [0.0, 0.2]
    draw:                              # one independent draw per run
      sensors.current[0].noise: {uniform: [0.02, 0.1]}
      plant.parameters.R: {normal: {mean: 0.6, std: 0.03}}
      nc.program[0].tool_change.accel: {choice: [0.4, 0.6, 0.8]}
    seed_keys: [sensors.seed]          # scenario keys that receive the run's seed
    run: cosim.campaign:run_cosim      # the run function (``package.module:function``)
    run_options: {methods: [ls, iv]}   # passed to the run function as ``spec.options``
    keep_signals: false                # keep each run's signals.csv and plots under OUT/runs/<id>/

Runs are numbered grid point by grid point (``index = grid_index * repetitions + repetition``). The
run seed and the draws come from ``numpy.random.SeedSequence(seed, spawn_key=(index, stream))``, and
the run id is ``<index>-<hash of its changes and seed>``, so a campaign expands to the same runs on
every machine, and a changed campaign never reuses a stale result.

Execution: in this process (``workers=1``), on a local process pool (``workers > 1``) or on an
existing ``dask.distributed`` cluster (``scheduler="tcp://host:port"``). Each run's outcome depends
only on its spec, so the three give the same results. Every finished run is written at once, atomically,
to ``OUT/runs/<id>.json``; a campaign started again on the same out dir runs only what is missing.
A run that raises is recorded as ``failed`` with its reason and the campaign goes on.

Run function protocol: ``fn(spec: RunSpec) -> dict`` (JSON-serialisable), shaped as::

    {"truth": {"R": 0.6, ...},                        # plant parameters of the run
     "injected": {"plant": {"Cd": 0.25},              # relative change of each faulty parameter
                  "sensors": {"Im1": {"gain": 1.03, "offset": 0.0}}},
     "motions": [{"truth": {...},                     # optional: parameters at this motion (drifts)
                  "validated": true,
                  "parameters": {"R": {"value": v, "ci95": [lo, hi]}, ...}, "method": "iv",  # the monitor's
                  "methods": {"ls": {"R": {...}}, "iv": {...}, "oe": {...}},   # optional, on the recorded data
                  "sensor_faults": [{"sensor": "Im1", ...}],
                  "diagnosis": [{"fault": "brush wear", "parameters": ["R"], "evidence": ...}]}]}

``aggregate`` turns the records into the detection and estimation tables (see its docstring for the
exact definitions of the rates).
"""
from __future__ import annotations

import csv
import hashlib
import importlib
import itertools
import json
import math
import os
import re
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from multiprocessing import get_context
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, PositiveInt, ValidationError, field_validator, model_validator

from cosim.errors import InputError
from estimator.diagnosis import TABLE_I
from estimator.estimate import METHODS
from models import feed_drive

#: the physical parameters the monitor estimates (the optional offset T0 left out)
PHYSICAL = tuple(v.name for v in feed_drive().parameters if v.kind == "physical" and not v.optional)

_KEY_RE = re.compile(r"^[A-Za-z_][\w-]*(\[\d+\])*(\.[A-Za-z_][\w-]*(\[\d+\])*)*$")
_PART_RE = re.compile(r"[A-Za-z_][\w-]*|\[(\d+)\]")


class CampaignError(InputError):
    """A campaign file or out dir is unusable. The message names the file, key and line."""


# -- schema -------------------------------------------------------------------------------------------
class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class Normal(_Frozen):
    mean: float
    std: float = Field(gt=0)


class Draw(_Frozen):
    """One distribution: exactly one of ``uniform: [low, high]``, ``normal: {mean, std}``, ``choice: [...]``."""

    uniform: tuple[float, float] | None = None
    normal: Normal | None = None
    choice: list[Any] | None = Field(default=None, min_length=1)

    @model_validator(mode="after")
    def _exactly_one(self) -> "Draw":
        given = [n for n in ("uniform", "normal", "choice") if getattr(self, n) is not None]
        if len(given) != 1:
            raise ValueError(f"give exactly one of uniform, normal, choice (got {given or 'none'})")
        if self.uniform is not None and not self.uniform[0] < self.uniform[1]:
            raise ValueError(f"uniform: expected [low, high] with low < high, got {list(self.uniform)}")
        return self

    def sample(self, rng: np.random.Generator) -> Any:
        if self.uniform is not None:
            return float(rng.uniform(*self.uniform))
        if self.normal is not None:
            return float(rng.normal(self.normal.mean, self.normal.std))
        return self.choice[int(rng.integers(len(self.choice)))]


def _check_key(key: str) -> str:
    if not _KEY_RE.match(key):
        raise ValueError(f"{key}: not a dotted scenario key such as plant.parameters.Cd or sensors.current[0].offset")
    return key


class Campaign(_Frozen):
    """A validated campaign; see the module docstring for the YAML shape.

    ``root`` is the directory that a relative ``base`` and the inline scenario's relative paths are
    resolved against (``load_campaign`` sets it to the campaign file's directory).
    """

    name: str = Field(min_length=1)
    base: str | dict[str, Any]
    seed: int = Field(default=0, ge=0)
    repetitions: PositiveInt = 1
    sweep: dict[str, list[Any]] = {}
    draw: dict[str, Draw] = {}
    seed_keys: list[str] = ["sensors.seed"]
    run: str = "cosim.campaign:run_cosim"
    run_options: dict[str, Any] = {}
    keep_signals: bool = False
    root: str = "."

    @field_validator("sweep")
    @classmethod
    def _sweep_keys(cls, v: dict[str, list[Any]]) -> dict[str, list[Any]]:
        for key, values in v.items():
            _check_key(key)
            if not values:
                raise ValueError(f"{key}: expected a non-empty list of values")
        return v

    @field_validator("draw")
    @classmethod
    def _draw_keys(cls, v: dict[str, Draw]) -> dict[str, Draw]:
        for key in v:
            _check_key(key)
        return v

    @field_validator("seed_keys")
    @classmethod
    def _seed_keys(cls, v: list[str]) -> list[str]:
        return [_check_key(k) for k in v]

    @field_validator("run")
    @classmethod
    def _run_spec(cls, v: str) -> str:
        if not re.match(r"^[\w.]+:\w+$", v):
            raise ValueError(f"expected 'package.module:function', got {v!r}")
        return v

    @model_validator(mode="after")
    def _disjoint(self) -> "Campaign":
        both = sorted(set(self.sweep) & set(self.draw) | (set(self.sweep) | set(self.draw)) & set(self.seed_keys))
        if both:
            raise ValueError(f"keys given twice (sweep, draw, seed_keys): {both}")
        return self

    @property
    def base_dir(self) -> Path:
        """Directory the base scenario's relative paths are resolved against."""
        return Path(self.root, self.base).resolve().parent if isinstance(self.base, str) else Path(self.root).resolve()

    def base_scenario(self) -> dict[str, Any]:
        """The base scenario as a plain mapping (read from ``base`` when it is a path)."""
        if isinstance(self.base, dict):
            return json.loads(json.dumps(self.base))
        path = Path(self.root, self.base)
        if not path.is_file():
            raise CampaignError(f"campaign {self.name}: base: scenario file {path} not found")
        data = yaml.safe_load(path.read_text())
        if not isinstance(data, dict):
            raise CampaignError(f"{path}: expected a scenario mapping at the top level")
        return data


def _line_map(text: str) -> dict[tuple, int]:
    """YAML key path -> 1-based line, for error messages."""
    lines: dict[tuple, int] = {}

    def walk(node: yaml.Node, path: tuple) -> None:
        lines.setdefault(path, node.start_mark.line + 1)
        if isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                lines[path + (k.value,)] = k.start_mark.line + 1
                walk(v, path + (k.value,))
        elif isinstance(node, yaml.SequenceNode):
            for n, v in enumerate(node.value):
                walk(v, path + (n,))

    root = yaml.compose(text)
    if root is not None:
        walk(root, ())
    return lines


def load_campaign(path: str | os.PathLike) -> Campaign:
    """Read and validate a campaign YAML file.

    Raises
    ------
    CampaignError
        Naming the file, the line and the key path, and what was expected.
    """
    path = Path(path)
    if not path.is_file():
        raise CampaignError(f"{path}: campaign file not found")
    text = path.read_text()
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise CampaignError(f"{path}: not valid YAML: {' '.join(str(exc).split())}") from None
    if not isinstance(data, dict):
        raise CampaignError(f"{path}: expected a mapping at the top level")
    if "root" in data:
        raise CampaignError(f"{path}:{_line_map(text)[('root',)]}: root: unknown key")
    try:
        campaign = Campaign.model_validate({**data, "root": str(path.resolve().parent)})
    except ValidationError as exc:
        err = exc.errors()[0]
        lines = _line_map(text)
        loc = tuple(err["loc"])
        msg = "unknown key" if err["type"] == "extra_forbidden" else err["msg"].removeprefix("Value error, ")
        # a dict-level validator names the offending key first in its message: point at that key's line
        loc += tuple(k[-1] for k in lines if k and k[:-1] == loc and isinstance(k[-1], str) and msg.startswith(f"{k[-1]}:"))[:1]
        line = next((lines[loc[:n]] for n in range(len(loc), 0, -1) if loc[:n] in lines), 1)
        key = ".".join(str(p) for p in loc) or "(top level)"
        msg = msg.removeprefix(f"{loc[-1]}: ") if loc else msg
        more = f" (and {exc.error_count() - 1} more)" if exc.error_count() > 1 else ""
        raise CampaignError(f"{path}:{line}: {key}: {msg}{more}") from None
    if isinstance(campaign.base, str) and not Path(campaign.root, campaign.base).is_file():
        raise CampaignError(f"{path}:{_line_map(text)[('base',)]}: base: scenario file {campaign.base} not found "
                            f"(relative to {campaign.root})")
    campaign.base_scenario()  # a malformed base fails now, not in every run
    return campaign


# -- expansion ------------------------------------------------------------------------------------------
def parse_key(key: str) -> tuple[str | int, ...]:
    """``"sensors.current[0].offset"`` -> ``("sensors", "current", 0, "offset")``."""
    _check_key(key)
    return tuple(int(m.group(1)) if m.group(1) is not None else m.group(0) for m in _PART_RE.finditer(key))


def set_key(data: dict[str, Any], key: str, value: Any) -> None:
    """Set a dotted key in a nested scenario mapping, creating missing mappings (never lists or list items).

    Raises
    ------
    CampaignError
        When the path crosses a value that is not a mapping, or a list index is out of range.
    """
    parts = parse_key(key)
    node: Any = data
    for n, part in enumerate(parts):
        last = n == len(parts) - 1
        where = key if last else "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in parts[: n + 1]).lstrip(".")
        if isinstance(part, int):
            if not isinstance(node, list) or part >= len(node):
                has = f"a list of {len(node)}" if isinstance(node, list) else f"a {type(node).__name__}"
                raise CampaignError(f"{key}: the base scenario has {has} at {where.rpartition('[')[0]}, no item [{part}]")
        elif not isinstance(node, dict):
            raise CampaignError(f"{key}: the base scenario has a {type(node).__name__} before {where}, not a mapping")
        if last:
            node[part] = value
        else:
            if isinstance(part, str) and part not in node:
                if isinstance(parts[n + 1], int):
                    raise CampaignError(f"{key}: the base scenario has no {where}")
                node[part] = {}
            node = node[part]


@dataclass(frozen=True)
class RunSpec:
    """Everything one run needs; picklable, sent to local or Dask workers.

    Attributes
    ----------
    id : str
        ``<index>-<hash>``, deterministic.
    index : int
        Position in the campaign.
    seed : int
        Run seed in [0, 2**31), written to the campaign's ``seed_keys``.
    overrides : dict
        Dotted key -> value, the sweep and draw values of this run.
    scenario : dict
        The full scenario mapping with the overrides and seed applied.
    base_dir : str
        Directory the scenario's relative paths are resolved against.
    out_dir : str or None
        Where to keep the run's files, or None (the run function uses a temporary directory).
    options : dict
        The campaign's ``run_options``.
    """

    id: str
    index: int
    seed: int
    overrides: dict[str, Any]
    scenario: dict[str, Any] = field(repr=False)
    base_dir: str
    out_dir: str | None = None
    options: dict[str, Any] = field(default_factory=dict)


def expand(campaign: Campaign, out_dir: str | os.PathLike | None = None) -> list[RunSpec]:
    """All runs of a campaign, in index order; the same for the same campaign on any machine.

    Parameters
    ----------
    campaign : Campaign
    out_dir : path or None
        The campaign's out dir; runs keep their files in ``out_dir/runs/<id>/`` when ``keep_signals``.
    """
    base = campaign.base_scenario()
    keys = list(campaign.sweep)
    grid = list(itertools.product(*(campaign.sweep[k] for k in keys))) or [()]
    specs = []
    for g, point in enumerate(grid):
        for rep in range(campaign.repetitions):
            index = g * campaign.repetitions + rep
            seed = int(np.random.SeedSequence(campaign.seed, spawn_key=(index, 0)).generate_state(1)[0] >> 1)
            rng = np.random.default_rng(np.random.SeedSequence(campaign.seed, spawn_key=(index, 1)))
            overrides = dict(zip(keys, point)) | {k: campaign.draw[k].sample(rng) for k in sorted(campaign.draw)}
            scenario = json.loads(json.dumps(base))
            try:
                for key, value in overrides.items():
                    set_key(scenario, key, value)
                for key in campaign.seed_keys:
                    set_key(scenario, key, seed)
            except CampaignError as exc:
                raise CampaignError(f"campaign {campaign.name}: {exc}") from None
            digest = hashlib.sha256(json.dumps([overrides, seed], sort_keys=True).encode()).hexdigest()[:10]
            run_id = f"{index:05d}-{digest}"
            keep = str(Path(out_dir, "runs", run_id)) if campaign.keep_signals and out_dir is not None else None
            specs.append(RunSpec(run_id, index, seed, overrides, scenario, str(campaign.base_dir), keep,
                                 dict(campaign.run_options)))
    return specs


# -- execution -------------------------------------------------------------------------------------------
def resolve_function(spec: str) -> Callable[[RunSpec], dict]:
    """Import ``package.module:function``."""
    module_name, _, name = spec.partition(":")
    try:
        fn = getattr(importlib.import_module(module_name), name)
    except (ImportError, AttributeError) as exc:
        raise CampaignError(f"run: cannot load {spec!r} ({exc})") from None
    if not callable(fn):
        raise CampaignError(f"run: {spec!r} is not callable")
    return fn


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"run result holds a {type(obj).__name__}, which is not JSON-serialisable")


def execute(run: str | Callable[[RunSpec], dict], spec: RunSpec) -> dict[str, Any]:
    """Run one spec and return its record; any exception becomes a ``failed`` record with its reason.

    The result goes through a JSON round trip here, in the worker, so records are identical whichever
    executor ran them.
    """
    start = time.perf_counter()
    try:
        fn = resolve_function(run) if isinstance(run, str) else run
        result, status, reason = json.loads(json.dumps(fn(spec), default=_jsonable)), "ok", ""
    except Exception as exc:  # a failing run must not stop the campaign: it is recorded with its reason
        result, status, reason = None, "failed", f"{type(exc).__name__}: {' '.join(str(exc).split())}"
    return {"id": spec.id, "index": spec.index, "seed": spec.seed, "overrides": spec.overrides,
            "status": status, "reason": reason, "elapsed_s": time.perf_counter() - start, "result": result}


def _write_atomic(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _fingerprint(campaign: Campaign) -> str:
    payload = json.dumps([campaign.model_dump(mode="json", exclude={"root"}), campaign.base_scenario()], sort_keys=True)
    return hashlib.sha256(payload.encode()).hexdigest()


def _open_store(campaign: Campaign, out: Path, overwrite: bool) -> dict[str, dict]:
    """Create or reopen the out dir; return the finished records by id."""
    meta = out / "campaign.json"
    runs = out / "runs"
    fingerprint = _fingerprint(campaign)
    if meta.exists():
        old = json.loads(meta.read_text())
        if old.get("fingerprint") != fingerprint:
            if not overwrite:
                raise CampaignError(f"{out}: holds the results of another campaign ({old.get('name')!r} or an "
                                    "earlier version of this one); choose another --out or pass --overwrite")
            for f in runs.glob("*.json"):
                f.unlink()
    elif out.exists() and any(out.iterdir()) and not overwrite:
        raise CampaignError(f"{out}: exists, is not empty and holds no campaign; choose another --out or pass --overwrite")
    runs.mkdir(parents=True, exist_ok=True)
    _write_atomic(meta, json.dumps({"name": campaign.name, "fingerprint": fingerprint,
                                    "campaign": campaign.model_dump(mode="json")}, indent=1))
    done = {}
    for f in runs.glob("*.json"):
        record = json.loads(f.read_text())
        done[record["id"]] = record
    return done


def _local(run, specs, workers, on_done) -> None:
    if workers == 1:
        for spec in specs:
            on_done(execute(run, spec))
        return
    # spawn, not fork: CasADi, FMU libraries and the progress bar's thread do not survive a fork safely
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn"))
    try:
        futures = [pool.submit(execute, run, spec) for spec in specs]
        for future in as_completed(futures):
            on_done(future.result())
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _check_scheduler(scheduler: str) -> None:
    """Refuse a malformed or unresolvable scheduler address before anything is written."""
    from distributed.comm.addressing import resolve_address

    try:
        resolve_address(scheduler)
    except (ValueError, OSError) as exc:
        raise CampaignError(f"--scheduler {scheduler}: {' '.join(str(exc).split())}; expected the address of a "
                            "Dask scheduler, such as tcp://host:8786") from None


def _dask(run, specs, scheduler, on_done) -> None:
    from distributed import Client
    from distributed import as_completed as dask_completed

    try:
        client = Client(scheduler, timeout="20s")
    except (OSError, TimeoutError) as exc:
        raise CampaignError(f"--scheduler {scheduler}: cannot connect to the Dask scheduler ({exc})") from None
    futures = []
    try:
        futures = [client.submit(execute, run, spec, key=f"campaign-{spec.id}", pure=False) for spec in specs]
        for future in dask_completed(futures):
            on_done(future.result())
    finally:
        client.cancel(futures)
        client.close()


@dataclass
class CampaignResult:
    """Records of every run in index order, the aggregates, and how many runs this call executed."""

    out_dir: Path
    records: list[dict]
    executed: int
    aggregates: "Aggregates"

    @property
    def failed(self) -> list[dict]:
        return [r for r in self.records if r["status"] == "failed"]


def run_campaign(campaign: Campaign, out_dir: str | os.PathLike, *, workers: int = 1, scheduler: str | None = None,
                 progress: bool = False, overwrite: bool = False, retry_failed: bool = False,
                 run: Callable[[RunSpec], dict] | None = None, plots: bool = True) -> CampaignResult:
    """Run (or resume) a campaign and write its records, aggregates and plots to ``out_dir``.

    Parameters
    ----------
    campaign : Campaign
    out_dir : path
        Holds ``campaign.json``, ``runs/<id>.json`` (one per finished run), ``detection.csv``,
        ``estimation.csv``, ``plots/``. Reopened runs with the same campaign resume.
    workers : int
        1: run in this process; > 1: a local process pool of that size. Ignored with ``scheduler``.
    scheduler : str or None
        Address of a running ``dask.distributed`` scheduler (``tcp://host:port``).
    progress : bool
        tqdm progress bar.
    overwrite : bool
        Discard the results of a different campaign in ``out_dir`` instead of refusing.
    retry_failed : bool
        Run the failed runs again (they are otherwise finished).
    run : callable or None
        Run function; default the campaign's ``run`` entry.
    plots : bool
        Draw the plots.
    """
    from tqdm import tqdm

    if workers < 1:
        raise CampaignError(f"--workers: expected >= 1, got {workers}")
    if scheduler:
        _check_scheduler(scheduler)
    out = Path(out_dir)
    done = _open_store(campaign, out, overwrite)
    specs = expand(campaign, out)
    ids = {s.id for s in specs}
    finished = {i: r for i, r in done.items() if i in ids and not (retry_failed and r["status"] == "failed")}
    pending = [s for s in specs if s.id not in finished]
    fn = run if run is not None else campaign.run
    # a bad entry or scenario is one input error now, not N failed runs later
    check = getattr(resolve_function(fn) if isinstance(fn, str) else fn, "validate", None)
    for spec in pending if check else ():
        check(spec)
    bar = tqdm(total=len(specs), initial=len(finished), desc=campaign.name, unit="run", disable=not progress)

    def on_done(record: dict) -> None:
        _write_atomic(out / "runs" / f"{record['id']}.json", json.dumps(record, indent=1))
        finished[record["id"]] = record
        bar.update(1)

    try:
        if not pending:
            pass
        elif scheduler:
            _dask(fn, pending, scheduler, on_done)
        else:
            _local(fn, pending, min(workers, len(pending)), on_done)
    finally:
        bar.close()
    records = sorted(finished.values(), key=lambda r: r["index"])
    aggregates = aggregate(records)
    aggregates.write(out)
    if plots:
        plot_campaign(records, aggregates, out / "plots")
    return CampaignResult(out, records, len(pending), aggregates)


# -- the co-simulation run function ----------------------------------------------------------------------
#: sensor outputs ``run_cosim`` needs recorded
RECORDED = ("u", "u_ref", "Im1", "Im2", "w_tach", "w_enc", "theta_enc")
#: monitor keys copied into a campaign record (residues and notes stay in the run's report.json)
MONITOR_KEYS = ("validated", "measurements_valid", "method", "parameters", "sensor_faults", "gain_ratio", "mismatch",
                "diagnosis", "processing_s", "error")


def _injected(scenario: Any, truth: Mapping[str, float], nominal: Mapping[str, float]) -> dict[str, Any]:
    """Faults a scenario injects: plant parameters off nominal (static or by event), sensors off gain 1 / offset 0."""
    plant = {p: v / nominal[p] - 1 for p, v in truth.items() if not math.isclose(v, nominal[p], rel_tol=1e-9)}
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
    from cosim.monitor import centred_speed
    from estimator.estimate import EstimationOptions, MotionData, estimate_motion

    def measured(name: str) -> np.ndarray:
        if name == "encoder":
            return centred_speed(signals["sensors.theta_enc"][rows], signals["sensors.w_enc"][rows], h,
                                 config.encoder_window_s)
        return signals[f"sensors.{name}"][rows]

    data = {q: np.mean([measured(c) for c in [c for c in pair if c not in faulty] or pair[:1]], axis=0)
            for q, pair in _QUANTITIES.items()}
    method = next(m for m in ("oe", "iv", "ls") if m in methods)
    est = estimate_motion(MotionData(h=h, **data), EstimationOptions(method=method, filter=config.filter,
                                                                     speed_threshold=config.speed_threshold))
    return {m: {k: {"value": p.value, "ci95": list(p.ci95)} for k, p in getattr(est, m).parameters.items()}
            for m in methods if getattr(est, m) is not None}


def _scenario(spec: RunSpec) -> Any:
    from cosim.errors import ScenarioError
    from cosim.scenario import scenario_from_dict

    try:
        return scenario_from_dict(spec.scenario, source="scenario", base_dir=spec.base_dir)
    except ScenarioError as exc:
        raise ScenarioError(f"campaign run {spec.id} {json.dumps(spec.overrides)}: {exc}") from None


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
    from cosim.master import event_step
    from cosim.monitor import MonitorConfig
    from cosim.run import run_scenario

    methods = _methods(spec)
    scenario = _scenario(spec)
    with tempfile.TemporaryDirectory(prefix="campaign-run-") as tmp:
        res = run_scenario(scenario, spec.out_dir or tmp, overwrite=True, plots=spec.out_dir is not None)
    nominal = feed_drive().nominal(("physical",))
    nominal = {p: nominal[p] for p in PHYSICAL}
    truth0 = nominal | {k: float(v) for k, v in scenario.plant.parameters.items() if k in nominal}
    t0 = float(res.time[0])
    # (step at which the event applies, parameter, value), the master's rule
    events = sorted((event_step(e.time, t0, scenario.step), e.target.partition(".")[2], float(e.value))
                    for e in scenario.events
                    if e.target.startswith("plant.") and e.target.partition(".")[2] in nominal)
    final = truth0 | {p: v for _, p, v in events}
    injected = _injected(scenario, final, nominal)
    config = scenario.monitor.config if isinstance(getattr(scenario.monitor, "config", None), MonitorConfig) \
        else MonitorConfig()
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
        try:
            entry["methods"] = _estimates(res.signals, rows, scenario.step, set(injected["sensors"]), methods, config)
        except ValueError as exc:  # not enough excitation in this motion: no numbers, the reason kept
            entry["methods"], entry["estimation_error"] = {}, " ".join(str(exc).split())
        entry |= {key: monitor[k][key] for key in MONITOR_KEYS if key in monitor.get(k, {})}
        motions.append(entry)
    return {"truth": truth0, "injected": injected, "motions": motions, "wall_time_s": res.report.get("wall_time_s")}


def _methods(spec: RunSpec) -> list[str]:
    methods = list(spec.options.get("methods", ["ls", "iv"]))
    unknown = sorted(set(methods) - set(METHODS))
    if unknown or not methods:
        raise CampaignError(f"run_options.methods: expected some of {list(METHODS)}, got {methods}")
    return methods


def _validate(spec: RunSpec) -> None:
    _methods(spec)
    _scenario(spec)


#: ``run_campaign`` checks every pending run's options and scenario with it before running any
run_cosim.validate = _validate


# -- aggregates ------------------------------------------------------------------------------------------
def fault_class(injected: Mapping[str, Any]) -> str:
    """``healthy``, ``plant:Cd+ft``, ``sensor:Im1`` or a combination joined by ``&``."""
    parts = []
    if injected.get("plant"):
        parts.append("plant:" + "+".join(sorted(injected["plant"])))
    if injected.get("sensors"):
        parts.append("sensor:" + "+".join(sorted(injected["sensors"])))
    return " & ".join(parts) or "healthy"


def _isolates(diagnoses: list[Mapping[str, Any]], changed: set[str]) -> bool:
    """The plant diagnoses of one motion isolate the fault when the Table I faults they name cover every
    changed parameter and none of them is foreign (sensitive to no changed parameter)."""
    named = [set(TABLE_I[d["fault"]]) for d in diagnoses if d.get("fault") in TABLE_I]
    return bool(changed and named) and changed <= set().union(*named) and all(s & changed for s in named)


def _truths(result: Mapping[str, Any]) -> list[dict[str, float]]:
    return [m.get("truth") or result.get("truth") or {} for m in result.get("motions", [])]


def _onset(truths: list[dict[str, float]]) -> tuple[int, set[str]]:
    """First motion whose truth differs from motion 0 and the parameters that change (drifts); 0 and the
    empty set when the truth is constant."""
    if not truths:
        return 0, set()
    changed = {p for t in truths for p, v in t.items() if not math.isclose(v, truths[0].get(p, v), rel_tol=1e-9)}
    onset = next((k for k, t in enumerate(truths)
                  if any(not math.isclose(t[p], truths[0][p], rel_tol=1e-9) for p in changed)), 0)
    return onset, changed


def _run_outcome(result: Mapping[str, Any]) -> dict[str, Any]:
    """Per-run detection facts; see ``aggregate`` for the definitions."""
    injected = result.get("injected") or {}
    motions = result.get("motions", [])
    onset, drifting = _onset(_truths(result))
    plant = set(injected.get("plant") or ()) | drifting
    sensors = set(injected.get("sensors") or ())
    alarms = [bool(m.get("diagnosis")) or bool(m.get("sensor_faults")) for m in motions]
    hits = [_isolates(m.get("diagnosis") or [], plant) for m in motions]
    sensor_hits = [{f.get("sensor") for f in m.get("sensor_faults") or ()} == sensors if sensors else False
                   for m in motions]
    cls = fault_class({"plant": plant, "sensors": sensors})
    if cls == "healthy":
        return {"class": cls, "false_alarm": any(alarms)}
    detected_at = next((k for k in range(onset, len(motions))
                        if (plant and motions[k].get("diagnosis")) or (sensors and motions[k].get("sensor_faults"))),
                       None)
    return {"class": cls, "detected": detected_at is not None,
            "isolated": any(h or s for h, s in zip(hits[onset:], sensor_hits[onset:])),
            "delay": None if detected_at is None else detected_at - onset,
            "false_alarm": any(alarms[:onset])}


@dataclass
class Aggregates:
    """``detection``: one row per fault class; ``estimation``: one row per (parameter, method)."""

    detection: list[dict[str, Any]]
    estimation: list[dict[str, Any]]

    def write(self, out: Path) -> None:
        for name, rows in (("detection", self.detection), ("estimation", self.estimation)):
            if rows:
                with open(out / f"{name}.csv", "w", newline="") as f:
                    w = csv.DictWriter(f, fieldnames=list(rows[0]))
                    w.writeheader()
                    w.writerows(rows)

    def table(self) -> str:
        """Both tables as aligned text."""
        def fmt(v: Any) -> str:
            return "-" if v is None else f"{v:.3g}" if isinstance(v, float) else str(v)

        blocks = []
        for rows in (self.detection, self.estimation):
            if not rows:
                continue
            cells = [list(rows[0])] + [[fmt(v) for v in r.values()] for r in rows]
            widths = [max(len(c[j]) for c in cells) for j in range(len(cells[0]))]
            blocks.append("\n".join("  ".join(c.ljust(w) for c, w in zip(row, widths)) for row in cells))
        return "\n\n".join(blocks)


def _rate(num: int, den: int) -> float | None:
    return num / den if den else None


def aggregate(records: list[dict]) -> Aggregates:
    """Detection and estimation statistics of a campaign.

    Detection (per fault class, ``fault_class`` of the injected faults and of the parameters that
    drift over the motions):

    * a run detects its fault when a motion at or after the fault's onset has a diagnosis (plant
      fault) or a sensor fault (sensor fault);
    * it isolates it when such a motion names the right faults: Table I faults whose sensitive
      parameters together hold every faulty parameter, none of them foreign to the faulty parameters
      (several faults of one drift, e.g. wear and brush wear, need several diagnoses), or exactly the
      faulty sensors;
    * ``false_alarm_rate``: on healthy runs, the fraction with any diagnosis or sensor fault; on
      drifting runs, the fraction with an alarm before the onset;
    * ``mean_delay_motions``: motions from the onset to the first detection (0 for a fault present
      from the first motion), over the detecting runs.

    Estimation (per physical parameter and method, over every motion not marked ``validated: false``
    of the finished runs without an injected sensor fault; method ``monitor``: the parameters of the
    motions the monitor validated):
    relative error ``e = (value - truth) / truth``; ``bias_pct`` = 100 mean(e), ``rms_pct`` =
    100 sqrt(mean(e^2)), ``coverage`` = fraction of motions whose ``ci95`` holds the truth.

    Failed runs are counted in ``failed`` and left out of every rate; runs without a monitor (no motion
    has a ``validated`` verdict) are left out of the detection table.
    """
    classes: dict[str, list[dict]] = {}
    failed: dict[str, int] = {}
    errors: dict[tuple[str, str], list[tuple[float, bool]]] = {}
    for record in records:
        if record["status"] != "ok":
            failed["(failed)"] = failed.get("(failed)", 0) + 1
            continue
        result = record["result"]
        if any(m.get("validated") is not None for m in result.get("motions", [])):  # runs without a monitor
            outcome = _run_outcome(result)                                           # detect nothing
            classes.setdefault(outcome["class"], []).append(outcome)
        if (result.get("injected") or {}).get("sensors"):
            continue  # estimates from a faulty sensor say nothing about the estimator
        for motion, truth in zip(result.get("motions", []), _truths(result)):
            if motion.get("validated") is False:
                continue
            # the methods scored on the recorded signals, and the parameters the monitor validated
            methods = dict(motion.get("methods") or {})
            if motion.get("validated") and motion.get("parameters"):
                methods["monitor"] = motion["parameters"]
            for method, params in methods.items():
                for name, est in (params or {}).items():
                    if name in truth and truth[name] != 0 and est.get("value") is not None:
                        lo, hi = est.get("ci95") or (math.nan, math.nan)
                        errors.setdefault((name, method), []).append(
                            ((est["value"] - truth[name]) / truth[name], lo <= truth[name] <= hi))
    detection = []
    for cls in sorted(classes, key=lambda c: (c != "healthy", c)):
        runs = classes[cls]
        n = len(runs)
        row = {"fault_class": cls, "runs": n}
        if cls == "healthy":
            row |= {"detected": None, "isolated": None, "detection_rate": None, "isolation_rate": None,
                    "false_alarm_rate": _rate(sum(r["false_alarm"] for r in runs), n), "mean_delay_motions": None}
        else:
            det = [r for r in runs if r["detected"]]
            row |= {"detected": len(det), "isolated": sum(r["isolated"] for r in runs),
                    "detection_rate": _rate(len(det), n), "isolation_rate": _rate(sum(r["isolated"] for r in runs), n),
                    "false_alarm_rate": _rate(sum(r["false_alarm"] for r in runs), n),
                    "mean_delay_motions": float(np.mean([r["delay"] for r in det])) if det else None}
        detection.append(row)
    if failed:
        detection.append({"fault_class": "(failed)", "runs": failed["(failed)"]} | dict.fromkeys(
            ("detected", "isolated", "detection_rate", "isolation_rate", "false_alarm_rate", "mean_delay_motions")))
    order = {p: n for n, p in enumerate(PHYSICAL)}
    estimation = []
    for (name, method), values in sorted(errors.items(), key=lambda kv: (order.get(kv[0][0], 99), kv[0][0],
                                                                         METHODS.index(kv[0][1]) if kv[0][1] in METHODS else 9)):
        e = np.array([v for v, _ in values])
        estimation.append({"parameter": name, "method": method, "n": len(e), "bias_pct": float(100 * e.mean()),
                           "rms_pct": float(100 * np.sqrt(np.mean(e ** 2))),
                           "coverage": float(np.mean([c for _, c in values]))})
    return Aggregates(detection, estimation)


# -- plots -----------------------------------------------------------------------------------------------
def plot_campaign(records: list[dict], aggregates: Aggregates, out: Path) -> list[Path]:
    """Detection rate against each swept key, parameter error against the noise key, one drift with its alarm.

    Returns the written PNG paths (plots that have no data in this campaign are skipped).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in records if r["status"] == "ok"]
    out.mkdir(parents=True, exist_ok=True)
    written = []
    keys = sorted({k for r in ok for k, v in r["overrides"].items() if isinstance(v, (int, float))})
    sweep_keys = [k for k in keys if len({r["overrides"].get(k) for r in ok}) <= max(10, len(ok) // 3)]
    if sweep_keys and any(row["fault_class"] not in ("healthy", "(failed)") for row in aggregates.detection):
        fig, axes = plt.subplots(1, len(sweep_keys), figsize=(4.5 * len(sweep_keys), 3.6), squeeze=False)
        for ax, key in zip(axes[0], sweep_keys):
            xs = sorted({r["overrides"][key] for r in ok if key in r["overrides"]})
            outs = {x: [_run_outcome(r["result"]) for r in ok if r["overrides"].get(key) == x] for x in xs}
            for name, pick, faulty in (("detection", "detected", True), ("isolation", "isolated", True),
                                       ("false alarm (healthy runs)", "false_alarm", False)):
                rates = [np.mean([o[pick] for o in outs[x] if (o["class"] != "healthy") == faulty] or [np.nan])
                         for x in xs]
                ax.plot(xs, rates, "o-" if faulty else "x--", label=name)
            ax.set(xlabel=key, ylabel="rate", ylim=(-0.05, 1.05), title="detection against fault size")
            ax.grid(True)
            ax.legend()
        fig.tight_layout()
        written.append(out / "detection_rate.png")
        fig.savefig(written[-1], dpi=110)
        plt.close(fig)
    noise = next((k for k in sweep_keys if "noise" in k), next((k for k in keys if "noise" in k), None))
    if noise:
        fig, ax = plt.subplots(figsize=(6, 4))
        xs = np.array([r["overrides"].get(noise, np.nan) for r in ok], dtype=float)
        values = np.unique(xs[np.isfinite(xs)])
        # a swept key: one point per value; a drawn one: up to 6 quantile bins
        edges = np.c_[values, values] if noise in sweep_keys else np.c_[
            np.quantile(xs, np.linspace(0, 1, 7))[:-1], np.quantile(xs, np.linspace(0, 1, 7))[1:]]
        colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
        for c, name in enumerate(PHYSICAL):
            for method, style in zip(METHODS + ("monitor",), ("o-", "s--", "^:", "d-.")):
                centres, rms = [], []
                for lo, hi in edges:
                    rows = aggregate([r for r, x in zip(ok, xs) if lo <= x <= hi]).estimation
                    row = next((row for row in rows if row["parameter"] == name and row["method"] == method), None)
                    if row:
                        centres.append((lo + hi) / 2)
                        rms.append(row["rms_pct"])
                if centres:
                    ax.plot(centres, rms, style, color=colours[c % len(colours)], label=f"{name} {method}")
        ax.set(xlabel=noise, ylabel="RMS relative error [%]", yscale="log", title="parameter error against noise")
        ax.grid(True, which="both")
        ax.legend(fontsize=7, ncol=3)
        fig.tight_layout()
        written.append(out / "error_vs_noise.png")
        fig.savefig(written[-1], dpi=110)
        plt.close(fig)
    drift = next((r for r in ok if _onset(_truths(r["result"]))[1]), None)
    if drift:
        written.append(plot_drift(drift["result"], out / "drift.png"))
    return written


def plot_drift(result: Mapping[str, Any], path: Path) -> Path:
    """Estimated and true drifting parameters against the motion index, with the first alarm marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    motions = result["motions"]
    truths = _truths(result)
    onset, drifting = _onset(truths)
    outcome = _run_outcome(result)
    names = [p for p in PHYSICAL if p in drifting]
    fig, axes = plt.subplots(len(names), 1, figsize=(7, 2.4 * len(names)), sharex=True, squeeze=False)
    for ax, name in zip(axes[:, 0], names):
        k = np.arange(len(motions))
        est = [m.get("parameters", {}).get(name, {}) for m in motions]
        ax.plot(k, [t[name] for t in truths], "k-", label="truth")
        ax.plot(k, [e.get("value", np.nan) for e in est], ".", ms=3, label="estimate")
        ax.set_ylabel(name)
        if outcome.get("delay") is not None:
            ax.axvline(onset + outcome["delay"], color="r", ls="--", label="first diagnosis")
        ax.grid(True)
    axes[0, 0].legend(fontsize=8)
    axes[-1, 0].set_xlabel("motion")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
