"""The monitor's configuration: the scenario's ``monitor:`` section, parsed once into a frozen object.

Kept apart from the pipeline (cosim/monitor_pipeline.py) so that loading a scenario does not import the
estimator.
"""
from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

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
    baseline : {"motions", "nominal"}
        Healthy baseline: the first ``baseline_motions`` validated motions without a diagnosis, or the
        model's nominal values. While it is incomplete, each validated motion is diagnosed against the
        healthy motions accepted so far (from the second validated motion on; the same test), and a
        motion with a diagnosis is not added to it.
    baseline_motions : int
    nominal : dict of str to float
        The axis's design values of ``R, L, K, Jt, ft, Cd`` (motor side, SI) where they differ from the
        built-in model's: the first motion's sensor isolation and ``baseline: nominal`` use them.
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
    baseline: Literal["motions", "nominal"] = "motions"
    baseline_motions: int = Field(3, ge=1)
    nominal: dict[Literal["R", "L", "K", "Jt", "ft", "Cd"], float] = {}
    known: dict[Literal["R", "L", "K", "Jt", "ft", "Cd"], float] = {}
    bounds: dict[Literal["R", "L", "K", "Jt", "ft", "Cd"], tuple[float | None, float | None]] = {}
    min_relative_drift: float = Field(0.05, gt=0)
    min_motion_s: float = Field(1.0, gt=0)
    max_motion_s: float = Field(30.0, gt=0)
    max_motions: int = Field(10, ge=0)
    max_age_s: float = Field(7 * 86400.0, gt=0)
    budget_s: float = Field(2.0, gt=0)
    keep_traces: int = Field(5, ge=0)
    encoder_window_s: float = Field(1.0e-3, gt=0)
    sampling: dict[Literal["voltage", "current", "speed"], Literal["instant", "mean"]] = {}


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

