"""The monitor's configuration: the scenario's ``monitor:`` section, parsed once into a frozen object.

Kept apart from the pipeline (cosim/monitor_pipeline.py) so that loading a scenario does not import the
estimator.
"""
from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, ValidationInfo, field_validator, model_validator

from feeddrive.estimator.filtering import FilterSpec
from feeddrive.estimator.motion import SAMPLING_DELAY


class MonitorConfig(BaseModel):
    """The scenario's ``monitor:`` section (all keys optional).

    Attributes
    ----------
    axis : str or None
        Machine/axis id in the history; None: the scenario's ``axis`` (set by the loader), else ``X``.
    scenario : str
        Scenario name stored with each motion.
    db : str or None
        SQLite history file; None keeps the history in memory (nothing persists between runs).
    method : {"ls", "iv", "oe"}
        Estimation method whose parameters are validated and stored.
    filter_cutoff_hz, filter_order : float, int
        The identical low-pass of every signal (eq. 8), used by validation and estimation.
    speed_threshold : float or None
        Samples with ``|w|`` below it [rad/s] are excluded from the sign(w) term; None (default):
        ``speed_fraction`` of each motion's largest speed (relative to the data, not to a nominal plant).
    speed_fraction : float
        The relative threshold used when ``speed_threshold`` is None.
    alpha : float
        Level of every statistical test (residues, model whiteness, drifts).
    window_s, gain_tol, offset_tol : float
        Residue windows [s]; sensor gain error [relative] and offset [fraction of range] that count as faults.
    mismatch_alpha : float
        Family-wise level of the model check (independence and size tests of the output-error residues,
        estimator/mismatch.py): its false-alarm rate on healthy motions.
    baseline : {"motions", "nominal"} or str
        Healthy baseline: the first ``baseline_motions`` validated motions without a diagnosis, or the
        model's nominal values. While it is incomplete, each validated motion is diagnosed against the
        healthy motions accepted so far (from the second validated motion on; the same test), and a
        motion with a diagnosis is not added to it. Or a stated baseline FILE (a relative path is the
        scenario's directory's), read once here: a JSON or YAML mapping of ``R, L, K, Jt, ft, Cd`` to a
        value or ``{value, std}`` (optionally under ``parameters:``; std 0 when not given), or a history
        database (``.sqlite``, ``.sqlite3``, ``.db``) whose axis ``baseline_axis`` gives its first
        ``baseline_motions`` healthy validated motions (``make_baseline``).
    baseline_axis : str or None
        The axis of a history database baseline; None: this monitor's axis.
    baseline_motions : int
    nominal : dict of str to float
        The axis's design values of ``R, L, K, Jt, ft, Cd`` (motor side, SI): the first motion's sensor
        isolation (R, L, K) and ``baseline: nominal`` (all of them) use them. A scenario with a built-in
        plant states its model's; a vendor FMU's or a recording's are the user's (without them a disagreeing
        pair on the first motion is not isolated, and ``baseline: nominal`` is refused).
    known : dict of str to float
        Parameters known in advance (motor side, SI), fixed in the estimation and the model checks, e.g.
        ``{R: 8.4, K: 0.042}`` (``cosim monitor --known R=8.4 K=0.042``); K is needed to estimate Jt, ft,
        Cd from a current without a voltage.
    min_relative_drift : float
        Smallest relative parameter change diagnosed.
    min_motion_s, max_motion_s : float
        Shorter motions are recorded as not identified; longer ones are cut to this length [s].
    max_motions, max_age_s : int, float
        Identification too old: more motions than this, or more seconds, since the last validated one.
    budget_s : float
        Processing time allowed per motion [s] (paper: 1-2 s).
    keep_traces : int
        Motions whose signals are kept for the monitor plots (the last ones).
    encoder_window_s : float
        The component's encoder speed is the centred difference of ``theta_enc`` over this window [s].
        The sensors' ``w_enc`` is a backward difference, i.e. the speed half a window earlier: averaged
        with the tachometer it delayed the speed by a quarter window (0.25 ms), which biased R by
        +0.45 % and ft by -1 % on the built-in plant.
    drive : {"dc", "pmsm", "pmsm-spm"}
        The axis's drive model (``models.drives``); in a scenario, ``axis.drive.kind``. A PMSM's motions
        are validated with the servo drive's redundancies and estimated with the dq model
        (cosim/monitor_servo.py); the estimation, model check and diagnosis steps are the same.
    pole_pairs : int or None
        A PMSM's pole pairs (known, not estimated); None: the model's 4. In a scenario, ``axis.drive.pole_pairs``.
    second_sensor_on : {"U", "V", "W"} or None
        The phase of a PMSM's second current sensor ``I_2`` (checked against that phase's sensor); None: no
        second sensor. In a scenario, the ``servo`` component's (``axis.drive.second_sensor_on``).
    dead_time_loss_v : float
        A PMSM drive's nominal per-leg dead-time loss ``t_dead f_pwm u_dc`` [V], modelled in the voltage
        reference check (0: an ideal inverter).
    lost_motion_allowed_mm : float
        A PMSM axis's acceptance value of the lost motion between the motor encoder and the linear scale [mm]:
        the one-sided test's null (an elastic drive chain has some um without play: 1.2 um on the vendor FMU).
    decimation : "auto" or int
        Every how many filtered samples the estimation uses (``EstimationOptions.decimation``): "auto"
        (default) from the filter's cut-off and the rate (3 at 10 kHz with the 100 Hz filter), 1 every
        sample; each motion's ``estimation_rate_hz`` says the rate. The model checks have no split halves
        and take their own D from the same rule (``estimator.filtering.check_rate_factor``: 5 at 10 kHz
        with the 100 Hz filter); a factor given here is taken by them too, lowered to a divisor of their
        50 Hz block.
    sampling : mapping of {"voltage", "current", "speed"} to {"instant", "mean"}
        What a sample of each quantity is: ``mean``, the mean over the sampling interval before its
        time stamp, which the estimator aligns to the interval's middle (h/2 earlier); default
        instant. In a scenario it defaults to the sensors' sampling when ``plant.oversample`` > 1.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    axis: str | None = Field(None, min_length=1)
    scenario: str = ""
    db: str | None = None
    method: Literal["ls", "iv", "oe"] = "iv"
    filter_cutoff_hz: float = Field(100.0, gt=0)
    filter_order: int = Field(4, ge=1)
    speed_threshold: float | None = Field(None, ge=0)
    speed_fraction: float = Field(0.03, ge=0, lt=1)
    alpha: float = Field(1e-3, gt=0, lt=0.5)
    window_s: float = Field(0.05, gt=0)
    gain_tol: float = Field(0.005, gt=0)
    offset_tol: float = Field(0.005, gt=0)
    mismatch_alpha: float = Field(0.01, gt=0, lt=0.5)
    baseline_axis: str | None = Field(None, min_length=1)
    baseline_motions: int = Field(3, ge=1)
    baseline: str = Field("motions", min_length=1)  # after axis, baseline_axis and baseline_motions: it reads them
    drive: Literal["dc", "pmsm", "pmsm-spm"] = "dc"  # before the parameter maps: they take its model's names
    nominal: dict[str, float] = {}
    known: dict[str, float] = {}
    bounds: dict[str, tuple[float | None, float | None]] = {}
    min_relative_drift: float = Field(0.05, gt=0)
    min_motion_s: float = Field(1.0, gt=0)
    max_motion_s: float = Field(30.0, gt=0)
    max_motions: int = Field(10, ge=0)
    max_age_s: float = Field(7 * 86400.0, gt=0)
    budget_s: float = Field(2.0, gt=0)
    keep_traces: int = Field(5, ge=0)
    encoder_window_s: float = Field(1.0e-3, gt=0)
    sampling: dict[Literal["voltage", "current", "speed"], Literal["instant", "mean"]] = {}
    pole_pairs: int | None = Field(None, ge=1)
    second_sensor_on: Literal["U", "V", "W"] | None = "U"
    dead_time_loss_v: float = Field(0.0, ge=0)
    lost_motion_allowed_mm: float = Field(0.005, ge=0)
    decimation: Literal["auto"] | int = "auto"
    #: the stated baseline FILE's values, name -> (value, std), read once by the validator
    _stated: dict[str, tuple[float, float]] | None = PrivateAttr(None)

    @field_validator("decimation", mode="before")
    @classmethod
    def _decimation(cls, value: object) -> object:
        if value == "auto" or (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
            return value
        raise ValueError(f"expected 'auto' or an integer >= 1 (every how many filtered samples are estimated on), "
                         f"got {value!r}")

    @field_validator("baseline")
    @classmethod
    def _baseline_file(cls, value: str, info: ValidationInfo) -> str:
        if value not in ("motions", "nominal"):  # read here, so that a bad file is an error at loading
            _read(value, info.data.get("baseline_axis") or info.data.get("axis") or "X",
                  info.data.get("baseline_motions", 3))
        return value

    @field_validator("nominal", "known", "bounds")
    @classmethod
    def _parameter_names(cls, value: dict, info: ValidationInfo) -> dict:
        """The names of the axis's drive model (R, L, K, ... or R, L_d, L_q, psi_f, ...; ``p`` known too)."""
        from feeddrive.models.drives import drive_model

        drive = info.data.get("drive", "dc")
        names = [v.name for v in drive_model(drive).of_kind("physical")]
        unknown = sorted(set(value) - set(names) - ({"p"} if info.field_name == "known" else set()))
        if unknown:
            raise ValueError(f"unknown parameter {', '.join(map(repr, unknown))} of the {drive} drive "
                             f"(expected {', '.join(names)})")
        if info.field_name != "bounds":  # a stated value is used as the axis's: it must be physically possible
            from feeddrive.estimator.physical import impossible_values

            impossible_values(value, "")
        return value

    @model_validator(mode="after")
    def _read_baseline(self) -> MonitorConfig:
        if self.baseline == "nominal":  # the axis's own values: another motor's would diagnose a healthy axis
            from feeddrive.models.drives import drive_model

            need = [v.name for v in drive_model(self.drive).of_kind("physical") if not v.optional]
            missing = [n for n in need if n not in self.nominal and n not in self.known]
            if missing:
                raise ValueError(f"baseline: nominal needs the axis's nominal values of {', '.join(need)} (monitor."
                                 f"nominal, --nominal NAME=VALUE); missing {', '.join(missing)}")
        if self.baseline not in ("motions", "nominal"):
            self._stated = _read(self.baseline, self.baseline_axis or self.axis or "X", self.baseline_motions)
        return self

    @property
    def stated_baseline(self) -> dict[str, tuple[float, float]] | None:
        """The baseline FILE's ``name -> (value, std)``; None for ``motions`` and ``nominal``."""
        return None if self._stated is None else dict(self._stated)

    @field_validator("bounds", mode="before")
    @classmethod
    def _bounds(cls, raw: object) -> object:
        """``{Jt: "4e-6:", ft: [0, 1]}`` (the scenario's and ``--bounds``' forms) -> (low, high) pairs."""
        from feeddrive.estimator.physical import bounds_mapping

        if isinstance(raw, dict):
            try:
                return bounds_mapping(raw, "")
            except ValueError as exc:
                raise ValueError(str(exc).lstrip(": ")) from None
        return raw

    def delays(self, h: float) -> dict[str, float]:
        """Estimator signal -> delay [s] of its samples (see ``sampling``), for sampling period ``h``."""
        symbol = {"voltage": "u", "current": "i", "speed": "w"}
        return {symbol[q]: SAMPLING_DELAY[mode] * h for q, mode in self.sampling.items() if SAMPLING_DELAY[mode]}

    @property
    def filter(self) -> FilterSpec:
        return FilterSpec(self.filter_cutoff_hz, self.filter_order)



PARAMETERS = ("R", "L", "K", "Jt", "ft", "Cd")
DATABASES = (".sqlite", ".sqlite3", ".db")


def _read(path: str, axis: str, motions: int) -> dict[str, tuple[float, float]]:
    """``read_baseline``, once per file version (the field's check and the model's value read it once)."""
    try:
        stat = Path(path).stat()
        version = (stat.st_mtime_ns, stat.st_size)
    except OSError:
        version = None
    return dict(_read_version(path, axis, motions, version))


@lru_cache(maxsize=8)
def _read_version(path: str, axis: str, motions: int, version: tuple | None) -> dict[str, tuple[float, float]]:
    return read_baseline(Path(path), axis, motions)


def read_baseline(path: Path, axis: str, motions: int) -> dict[str, tuple[float, float]]:
    """A stated healthy baseline: ``name -> (value, std)`` from a parameter file or a history database.

    Raises ValueError with one line naming the file and what was expected (the scenario's loader adds
    the key ``monitor.baseline``).
    """
    if not path.is_file():
        raise ValueError(f"{path}: no such file (expected 'motions', 'nominal', or a baseline file: JSON/YAML "
                         f"parameter values or a history database {'/'.join(DATABASES)})")
    if path.suffix.lower() in DATABASES:
        from feeddrive.estimator.diagnosis import make_baseline
        from feeddrive.estimator.history import History

        try:
            with History(path) as history:
                sets = [b["parameters"] for b in history.baseline(axis, motions)]
        except ValueError as exc:  # HistoryError: not SQLite, locked, ...
            raise ValueError(str(exc)) from None
        if not sets:
            raise ValueError(f"{path}: no validated healthy motion of axis {axis!r} to learn the baseline from "
                             f"(set baseline_axis)")
        return make_baseline(sets)
    import yaml

    try:
        text = path.read_text(encoding="utf-8")
        data = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
    except (OSError, UnicodeDecodeError, ValueError, yaml.YAMLError) as exc:
        raise ValueError(f"{path}: not a readable JSON/YAML parameter file ({' '.join(str(exc).split())})") from None
    if isinstance(data, dict) and isinstance(data.get("parameters"), dict):
        data = data["parameters"]
    if not isinstance(data, dict) or not data:
        raise ValueError(f"{path}: expected a mapping of {', '.join(PARAMETERS)} to values")
    out = {}
    for name, entry in data.items():
        if name not in PARAMETERS:
            raise ValueError(f"{path}: unknown parameter {name!r} (expected {', '.join(PARAMETERS)})")
        value, std = (entry.get("value"), entry.get("std", 0.0)) if isinstance(entry, dict) else (entry, 0.0)
        if not all(isinstance(x, int | float) and not isinstance(x, bool) and x == x and abs(x) != float("inf")
                   for x in (value, std)) or std < 0:
            raise ValueError(f"{path}: {name}: expected a finite number or {{value, std >= 0}}, got {entry!r}")
        out[name] = (float(value), float(std))
    return out



def resolve_files(raw: dict, base_dir: Path) -> dict:
    """The section's relative files (a history ``db``, a ``baseline`` FILE) against the scenario's directory."""
    special = (":memory:", "motions", "nominal")
    return raw | {k: str(base_dir / Path(v).expanduser()) for k, v in raw.items()
                  if k in ("db", "baseline") and isinstance(v, str) and v not in special}
