"""Why a model check rejects a plant that holds its inputs: the set-up's sampling, not the drive.

A Co-Simulation FMU that cannot interpolate its inputs (``canInterpolateInputs="false"``, ``plant.input_hold:
zoh``) sees the NC's command as a staircase. A drive that acts on it through proportional gains (analog-style PI
loops, no reference filter) jumps its terminal voltage at every step, and a sample per step sees that sawtooth
at one phase: no continuous model fits such samples, the model check rejects, and R and L come out about 20 %
low (``tests/plants/vendor_drive.py``; README, "Each analogue channel is sampled"). Stepping the plant several
times per recorded sample and averaging each channel over the interval (``sampling: mean``, the default)
removes it. The monitor cannot know this from its samples; the run knows the plant and the sampling, and says
so beside the verdict rather than leaving "model mismatch" to be read as a drive that is not the model.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

#: sub-steps per recorded sample from which the interval mean removes the sawtooth (README's table: R, L within
#: 0.1 % at 10 kHz from 4; at 1 kHz a 1 kHz current loop needs 10)
MEAN_OVERSAMPLE = 4


def _unaveraged(oversample: int, sampling: Mapping[str, str]) -> list[str] | None:
    """The channels not averaged over the recorded sample (``instant``, ``lowpass``), or None when the set-up
    averages enough (``MEAN_OVERSAMPLE`` sub-steps, every channel ``mean``): the notes do not apply then."""
    unaveraged = sorted(c for c, s in sampling.items() if s != "mean")
    return None if oversample >= MEAN_OVERSAMPLE and not unaveraged else unaveraged


def held_input_note(input_hold: str | None, oversample: int, sampling: Mapping[str, str],
                    motions: Sequence[object]) -> str | None:
    """The note for report.json ``held_inputs`` and the console, or None when it does not apply.

    Parameters
    ----------
    input_hold : str or None
        The plant's effective input hold (report.json ``components.plant.input_hold``): ``zoh`` or ``foh``.
    oversample : int
        ``plant.oversample``: plant steps per recorded sample.
    sampling : mapping
        How the voltage and current channels are sampled, channel -> ``instant`` / ``mean`` / ``lowpass``
        (the sensors' configuration).
    motions : sequence
        report.json ``motions``: the note applies only when a model check rejected one of them.
    """
    if input_hold != "zoh":
        return None
    rejected = [k for k, m in enumerate(motions, 1) if isinstance(m, Mapping) and isinstance(m.get("mismatch"), Mapping)
                and m["mismatch"].get("passed") is False]
    unaveraged = _unaveraged(oversample, sampling)
    if not rejected or unaveraged is None:
        return None
    which = f"motion {rejected[0]}" if len(rejected) == 1 else f"motions {', '.join(map(str, rejected))}"
    how = (f"sampled {'once' if oversample == 1 else f'{oversample} times'} per recorded sample (plant.oversample "
           f"{oversample})")
    if unaveraged:
        how += f", {', '.join(unaveraged)} not averaged over it (sampling {sampling[unaveraged[0]]})"
    return (f"{which}: the model check rejects a plant that holds its inputs over each step (plant.input_hold zoh: "
            f"the FMU cannot interpolate them), {how}: a drive whose voltage jumps with each held command gives "
            "samples no continuous model fits, with R and L biased low; state plant.oversample: "
            f"{MEAN_OVERSAMPLE} or more (10 for a fast current loop) with the sensors' sampling: mean (the default)")


#: the discretisation error of L is said when it exceeds this share of L's 95 % half-interval: below it, the
#: interval still covers the motor's L (the error then moves the interval by a third of its half-width at most)
MATERIAL_SHARE = 1 / 3


def sampling_bias_note(input_hold: str | None, step: float, oversample: int, sampling: Mapping[str, str],
                       motions: Sequence[object]) -> str | None:
    """The note for report.json ``sampling_bias`` and the console, or None when it does not apply.

    A plant whose inputs are ramped over each communication step (``foh``: the NC's command changes slope at
    each step), recorded once per step with instantaneous samples, leaves L with a discretisation error of
    about ``-(h R / L)^2``, h the recording step: the samples sit on the inputs' corners, which no derivative of
    the samples resolves. A plant holding its inputs (``zoh``) has a larger error of another form (README,
    "Known limitations"; ``held_input_note`` explains its rejections): not this note. Measured on ``examples/tool_change.yaml``'s built-in
    axis (L / R = 6.7 ms), noise as in the example: L -0.53 % at h = 0.5 ms (predicted -0.56 %), -2.2 % at 1 ms
    (-2.2 %), both with 95 % intervals that exclude the motor's L and an accepting model check; the same motions
    recorded at 10 kHz and decimated to 1 kHz give L within 0.2 % (the estimator is right on smooth inputs);
    stepped 4 times per sample with ``sampling: mean``, L +0.06 % at 1 ms. The samples alone cannot tell this
    (a recording's inputs may be smooth); the run knows its plant and sampling, and says so where the error is
    material: above ``MATERIAL_SHARE`` of L's 95 % half-interval.

    Parameters
    ----------
    input_hold : str or None
        The plant's effective input hold (``foh`` or ``zoh``; None: a user's plant component).
    step : float
        The recording step h [s] (the scenario's ``step``).
    oversample : int
        ``plant.oversample``: plant steps per recorded sample.
    sampling : mapping
        The voltage and current channels' sampling, channel -> ``instant`` / ``mean`` / ``lowpass``.
    motions : sequence
        report.json ``motions`` (each with ``parameters`` R and L: ``value`` and ``ci95``).
    """
    if input_hold != "foh":  # a held input's error is larger and not this one (README, "Known limitations")
        return None
    unaveraged = _unaveraged(oversample, sampling)
    if unaveraged is None:
        return None
    found = []
    for k, m in enumerate(motions, 1):
        p = m.get("parameters") if isinstance(m, Mapping) else None
        r, ell = ((p or {}).get(n) or {} for n in ("R", "L"))
        try:
            R, L = float(r["value"]), float(ell["value"])
            lo, hi = (float(x) for x in ell["ci95"])
        except (KeyError, TypeError, ValueError):  # L not estimated: nothing to say of it
            continue
        if not (R > 0 and L > 0 and hi > lo):
            continue
        error = (step * R / L) ** 2
        if error > MATERIAL_SHARE * (hi - lo) / 2 / L:
            found.append((k, error, L, (hi - lo) / 2 / L, step * R / L))
    if not found:
        return None
    k, error, L, half, ratio = max(found, key=lambda f: f[1])
    which = f"motion {k}" if len(found) == 1 else (f"motions {', '.join(str(f[0]) for f in found)} (largest: "
                                                   f"motion {k})")
    how = f"plant.oversample {oversample}" + (f", {', '.join(unaveraged)} sampling {sampling[unaveraged[0]]}"
                                              if unaveraged else "")
    return (f"{which}: L may read about {100 * error:.2g} % low (L = {1e3 * L:.4g} mH, its 95 % interval "
            f"±{100 * half:.2g} %): the plant's inputs are ramped, changing slope at each step (plant.input_hold foh), and the "
            f"voltage and current samples of each {1e3 * step:g} ms step are not averaged over it ({how}), which leaves "
            f"about (h R / L)^2 = {100 * error:.2g} % of discretisation error on L (h R / L = {ratio:.2g}: the step "
            f"against the electrical time constant L / R = {1e3 * step / ratio:.2g} ms); "
            f"state plant.oversample: {MEAN_OVERSAMPLE} or more with the sensors' sampling: mean (the default)")
