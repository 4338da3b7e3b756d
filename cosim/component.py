"""The one interface between the co-simulation master and every component.

The FMU adapter, the NC trajectory generator, the sensors, the monitor and any user component
implement ``Component``. A user plugs in their own by naming it in the scenario as
``class: package.module:ClassName`` (see ``load_component_class``).

Call order (the master's contract)
----------------------------------
::

    c = Cls(name, config)                 # config: the component's own section of the scenario
    c.setup(t0, h, n_steps)               # once; ports (input_names, output_names) are fixed after it
    y0 = c.get_outputs()                  # outputs at t0
    for n in range(n_steps):              # t_n = t0 + n * h, an integer step count, never t += h
        c.set_parameter(name, value)      # zero or more timed events due at t_n (see below)
        c.set_inputs(values)              # inputs for [t_n, t_{n+1}], in input_names order
        c.step(n)                         # advance from t_n to t_{n+1}
        y = c.get_outputs()               # outputs at t_{n+1}, in output_names order
    c.terminate()                         # once, also after a failure (must not raise again)

Components are stepped in Gauss-Seidel order (NC -> plant -> sensors -> monitor): at step n a
component's inputs are the newest outputs of the components it is connected to, i.e. those at
t_{n+1} for components earlier in the order and at t_n for later ones (feedback, such as the
plant position read by the NC or the monitor's identification request).

Timed events: an event at time ``te`` takes effect at the first grid point ``t_n >= te`` (with a
tolerance of 1e-9 h, so an event exactly on the grid is not postponed), before ``set_inputs`` of
step n; the new value holds for [t_n, ...) until the next event on the same target. For a component
whose outputs at t_n come from step n-1 (the plant; the sensors, whose sample at t_n was measured in
step n-1), an event at t_n first shows in the outputs at t_(n+1): a sensor fault at t_n changes the
samples from t_(n+1) on, a plant parameter changed at t_n acts over [t_n, t_(n+1)] and shows from t_(n+1).

Rates: ``h`` is the component's own communication step. The master counts ticks of the finest step
and steps each component every ``rate`` ticks (the plant and the sensors every tick, at
``step / plant.oversample``; the NC every ``nc.cycle``; the monitor and user components every recording
``step``); see cosim/master.py.

Ports are plain sequences of floats in a fixed order, not dicts, so that the per-step cost stays
small (the master's loop runs 10^4 to 10^5 times per simulated second).
"""
from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import Any

from feeddrive.cosim.errors import ScenarioError


class Component(ABC):
    """Base class of all co-simulation components; see the module docstring for the call order.

    Subclasses set ``input_names``, ``output_names`` and ``output_units`` (tuples of str) at the
    latest in ``setup``, and may set ``input_units``: the master then checks the unit of every output
    connected to such an input (cosim/port_units.py; ``""`` declares nothing).
    """

    input_names: tuple[str, ...] = ()
    input_units: tuple[str, ...] = ()
    output_names: tuple[str, ...] = ()
    output_units: tuple[str, ...] = ()

    def __init__(self, name: str, config: Any = None) -> None:
        self.name = name
        self.config = config

    @abstractmethod
    def setup(self, t0: float, h: float, n_steps: int) -> None:
        """Prepare for a run of ``n_steps`` steps of ``h`` seconds from ``t0``."""

    def set_inputs(self, values: Sequence[float]) -> None:
        """Receive input values for the coming step, in ``input_names`` order."""

    @abstractmethod
    def step(self, n: int) -> None:
        """Advance from ``t0 + n h`` to ``t0 + (n + 1) h``."""

    @abstractmethod
    def get_outputs(self) -> Sequence[float]:
        """Output values at the component's current time, in ``output_names`` order."""

    def set_parameter(self, name: str, value: Any) -> None:
        """Apply a timed event. The default refuses: components that accept events override it."""
        raise ScenarioError(f"component {self.name!r} has no parameter {name!r} that events can change")

    def report(self) -> dict:
        """Anything the component wants in report.json (JSON-serialisable). Called after the run."""
        return {}

    def terminate(self) -> None:
        """Release resources. Called once, also after a failure; must not raise."""


#: the project's packages before they moved under ``feeddrive`` (0.2): old scenarios are told the new name
LEGACY_PACKAGES = ("cosim", "estimator", "models", "fmu_build")


def legacy_hint(module_name: str) -> str:
    """``"; write 'feeddrive.cosim.x' instead"`` when ``module_name`` is a module's pre-0.2 name, else ``""``."""
    if module_name.split(".")[0] not in LEGACY_PACKAGES:
        return ""
    try:
        importlib.import_module(f"feeddrive.{module_name}")
    except ImportError:
        return ""
    return f"; the project's modules moved under feeddrive: write 'feeddrive.{module_name}' instead"


def load_component_class(spec: str, where: str = "class") -> type[Component]:
    """Import ``package.module:ClassName`` and check that it is a ``Component``.

    Parameters
    ----------
    spec : str
        ``"package.module:ClassName"``.
    where : str
        The scenario key being read, for the error message.

    Raises
    ------
    ScenarioError
        When the spec is malformed, the module or class does not exist, or the class is not a
        ``Component`` subclass.
    """
    module_name, sep, class_name = spec.partition(":")
    if not sep or not module_name or not class_name:
        raise ScenarioError(f"{where}: expected 'package.module:ClassName', got {spec!r}")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise ScenarioError(f"{where}: cannot import module {module_name!r} ({exc}){legacy_hint(module_name)}") from None
    cls = getattr(module, class_name, None)
    if cls is None:
        raise ScenarioError(f"{where}: module {module_name!r} has no class {class_name!r}")
    if not (isinstance(cls, type) and issubclass(cls, Component)):
        raise ScenarioError(f"{where}: {spec!r} is not a subclass of feeddrive.cosim.component.Component")
    return cls
