"""The FMU adapter of an FMU's FMI version: FMI 2.0 (cosim/fmu_adapter.py) or 3.0 (cosim/fmi3_adapter.py)."""
from __future__ import annotations

from typing import Any

from feeddrive.cosim.fmi3_adapter import FMU3Component
from feeddrive.cosim.fmu_adapter import FMUComponent
from feeddrive.cosim.fmu_inspect import fmi_version


def fmu_component(name: str, config: Any, **kwargs: Any) -> FMUComponent:
    """:class:`FMUComponent` (FMI 2.0) or :class:`FMU3Component` (FMI 3.0) for ``config.fmu``.

    ``config`` is a resolved PlantConfig (or an FMU component's config); ``kwargs`` go to the adapter
    (``input_period``, ``own_inputs``).
    """
    cls = FMU3Component if fmi_version(config.fmu).startswith("3.") else FMUComponent
    return cls(name, config, **kwargs)
