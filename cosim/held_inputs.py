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
    unaveraged = sorted(c for c, s in sampling.items() if s != "mean")
    if not rejected or (oversample >= MEAN_OVERSAMPLE and not unaveraged):
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
