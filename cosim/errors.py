"""Errors of the co-simulation. Bad input subclasses ValueError, failures RuntimeError.

The CLI maps ``InputError`` (and its subclasses) to exit status 2 with one line, and
``SimulationError`` (and its subclasses) to exit status 1.
"""
from __future__ import annotations

from typing import Any


def format_path(path: tuple[Any, ...]) -> str:
    """``("nc", "program", 2, "rapid")`` -> ``nc.program[2].rapid``: a configuration key as users write it."""
    text = ""
    for part in path:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text


class InputError(ValueError):
    """Bad user input: a scenario, a CSV, a mapping, a command-line option."""


class ScenarioError(InputError):
    """A scenario file is malformed. The message names the file, the key and what was expected."""


class DataError(InputError):
    """A recorded-data file is unusable. The message names the file and the column."""


class SimulationError(RuntimeError):
    """The co-simulation failed after it started."""


class FMIError(SimulationError):
    """An FMI call returned fmi2Discard, fmi2Error or fmi2Fatal.

    Attributes
    ----------
    component : str
        Name of the component in the scenario.
    function : str
        FMI function name, e.g. ``fmi2DoStep``.
    status : str
        ``fmi2Discard``, ``fmi2Error`` or ``fmi2Fatal``.
    time : float
        Simulated time of the failing call [s].
    last_log : str
        The FMU's last log message, or ``""``.
    """

    def __init__(self, component: str, function: str, status: str, time: float, last_log: str = "") -> None:
        self.component = component
        self.function = function
        self.status = status
        self.time = time
        self.last_log = last_log
        log = f": {last_log}" if last_log else ""
        super().__init__(f"{component}: {function} returned {status} at t={time:.6g} s{log}")
