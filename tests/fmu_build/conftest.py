"""Helpers for the plant-FMU tests: an extracted FMU and instances that record the FMU's log."""
from __future__ import annotations

from collections.abc import Callable, Iterator
from ctypes import byref
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi2 import (
    FMU2Model,
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)
from fmpy.logging import addLoggerProxy


@dataclass
class Instance:
    """An instantiated and initialised FMU (``fmu``) with its log messages and a name -> vr map."""

    fmu: FMU2Slave | FMU2Model
    vr: dict[str, int]
    log: list[str] = field(default_factory=list)

    def get(self, *names: str) -> np.ndarray:
        return np.array(self.fmu.getReal([self.vr[n] for n in names]))

    def set(self, **values: float) -> None:
        self.fmu.setReal([self.vr[n] for n in values], list(values.values()))


@pytest.fixture(scope="session")
def fmu_dir(feeddrive_fmu: Path, tmp_path_factory: pytest.TempPathFactory) -> str:
    return extract(str(feeddrive_fmu), str(tmp_path_factory.mktemp("fmu_extracted")))


@pytest.fixture
def instance(fmu_dir: str) -> Iterator[Callable[..., Instance]]:
    """Factory ``instance(kind="cs" | "me", init=True, **start_values)`` -> ``Instance`` at t = 0,
    initialised unless ``init`` is False (then still in the instantiated state)."""
    made: list[Instance] = []
    logs: dict[str, list[str]] = {}  # by instance name: fmpy's logger proxy is one global, the last one added

    def make(kind: str = "cs", init: bool = True, **start: float) -> Instance:
        md = read_model_description(fmu_dir)
        cls, ident = (FMU2Slave, md.coSimulation) if kind == "cs" else (FMU2Model, md.modelExchange)
        name = f"{kind}{len(made)}"
        fmu = cls(guid=md.guid, unzipDirectory=fmu_dir, modelIdentifier=ident.modelIdentifier, instanceName=name)
        inst = Instance(fmu, {v.name: v.valueReference for v in md.modelVariables}, logs.setdefault(name, []))
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(
            lambda env, instance_name, status, cat, msg: logs[instance_name.decode()].append(msg.decode()))
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(byref(callbacks))  # formats the variadic message in C
        fmu.instantiate(callbacks=callbacks)
        made.append(inst)
        fmu.setupExperiment(startTime=0.0)
        inst.set(**start)
        if not init:
            return inst
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        if kind == "me":
            fmu.enterContinuousTimeMode()
        return inst

    yield make
    for inst in made:  # fmi2FreeInstance is allowed in every mode (tests leave instances in any of them)
        inst.fmu.freeInstance()
