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
    timeout: 600                       # optional wall-time limit of each run [s] (also --timeout)

Runs are numbered grid point by grid point (``index = grid_index * repetitions + repetition``). The
run seed and the draws come from ``numpy.random.SeedSequence(seed, spawn_key=(index, stream))``, and
the run id is ``<index>-<hash of its changes and seed>``, so a campaign expands to the same runs on
every machine, and a changed campaign never reuses a stale result.

Execution: in this process (``workers=1``), on a local process pool (``workers > 1``) or on an
existing ``dask.distributed`` cluster (``scheduler="tcp://host:port"``). Each run's outcome depends
only on its spec, so the three give the same results. Every finished run is written at once, atomically,
to ``OUT/runs/<id>.json``; a campaign started again on the same out dir runs only what is missing.
Each run is a supervised child process (cosim/supervise.py): a run that raises, crashes (an FMU's
segmentation fault) or hangs (over its ``plant.call_timeout`` or the campaign's ``timeout``) is recorded
as ``failed`` with its reason and the campaign goes on.

Run function protocol: ``fn(spec: RunSpec) -> dict`` (JSON-serialisable), shaped as::

    {"truth": {"R": 0.6, ...},                        # plant parameters of the run
     "injected": {"plant": {"Cd": 0.25},              # relative change of each faulty parameter (a parameter
                                                      # the model lacks, e.g. backlash: its value)
                  "sensors": {"Im1": {"gain": 1.03, "offset": 0.0}}},
     "motions": [{"truth": {...},                     # optional: parameters at this motion (drifts)
                  "validated": true,
                  "parameters": {"R": {"value": v, "ci95": [lo, hi]}, ...}, "method": "iv",  # the monitor's
                  "methods": {"ls": {"R": {...}}, "iv": {...}, "oe": {...}},   # optional, on the recorded data
                  "sensor_faults": [{"sensor": "Im1", ...}],
                  "diagnosis": [{"fault": "brush wear", "parameters": ["R"], "evidence": ...}]}]}

Optional hooks, attributes of the function: ``prepare()`` (once per worker process, before its runs are
forked: imports), ``validate(spec)`` (before any run: one input error, not N failed runs) and
``cost(spec) -> float | None`` (how long the run takes, in any unit: on several workers the costliest runs
start first). ``run_cosim`` has all three.

``aggregate`` turns the records into the detection and estimation tables (see its docstring for the
exact definitions of the rates).
"""
from __future__ import annotations

import hashlib
import itertools
import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, PositiveInt, ValidationError, field_validator, model_validator

from feeddrive.cosim.errors import InputError
from feeddrive.cosim.yaml_source import read_yaml
from feeddrive.models import feed_drive

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
    def _exactly_one(self) -> Draw:
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
    seed: int = Field(default=0, ge=0, strict=True)  # strict: a YAML `true` is not seed 1
    repetitions: PositiveInt = 1
    sweep: dict[str, list[Any]] = {}
    draw: dict[str, Draw] = {}
    seed_keys: list[str] = ["sensors.seed"]
    run: str = "feeddrive.cosim.campaign:run_cosim"
    run_options: dict[str, Any] = {}
    keep_signals: bool = False
    timeout: float | None = Field(default=None, gt=0, description="wall-time limit of each run [s]: a run over "
                                  "it is killed and recorded as failed (hung)")
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
    def _disjoint(self) -> Campaign:
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
        data, _ = read_yaml(path, "scenario", CampaignError)
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
    # size limit, UTF-8, bounded aliases and nesting, YAML errors with their line (cosim/yaml_source.py)
    data, _ = read_yaml(path, "campaign", CampaignError)
    text = path.read_text(encoding="utf-8-sig")
    if not isinstance(data, dict):
        raise CampaignError(f"{path}: expected a mapping at the top level")
    if "root" in data:
        raise CampaignError(f"{path}:{_line_map(text)[('root',)]}: root: unknown key")
    if "base" not in data and {"plant", "nc"} & set(data):  # `cosim campaign` given a scenario file
        raise CampaignError(f"{path}: this is a scenario, not a campaign file: a campaign needs base: (a scenario "
                            "file or mapping) and sweep:, draw: or repetitions: (see examples/campaign_wear.yaml); "
                            f"run a scenario with cosim run {path}")
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
