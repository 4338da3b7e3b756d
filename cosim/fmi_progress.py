"""Which FMI function is in progress: a small record in shared memory, read by a supervising process.

Each FMU component (cosim/fmu_adapter.py) has a record of its own (several FMUs, each with its own
watchdog); it writes the function's code and the simulated time into its record before each FMI call and ``IDLE`` after the step's calls; a parent process that forked the run
(cosim/supervise.py) reads it when the run dies by a signal or a call exceeds ``call_timeout``. A
write is one store into a ctypes field (~40 ns), five per communication step: nothing measurable
against a step of ~20 us.

Without a supervisor the record is private memory of this process (same cost, nobody reads it).
"""
from __future__ import annotations

import ctypes
import mmap
from typing import Any

#: FMI 2.0 functions, in the order of the standard's sections, then FMI 3.0's; the record holds an index into it
FUNCTIONS = (
    "", "fmi2Instantiate", "fmi2FreeInstance", "fmi2SetDebugLogging", "fmi2SetupExperiment",
    "fmi2EnterInitializationMode", "fmi2ExitInitializationMode", "fmi2Terminate", "fmi2Reset",
    "fmi2GetReal", "fmi2GetInteger", "fmi2GetBoolean", "fmi2GetString", "fmi2SetReal", "fmi2SetInteger",
    "fmi2SetBoolean", "fmi2SetString", "fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate",
    "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate",
    "fmi2GetDirectionalDerivative", "fmi2EnterEventMode", "fmi2NewDiscreteStates",
    "fmi2EnterContinuousTimeMode", "fmi2CompletedIntegratorStep", "fmi2SetTime", "fmi2SetContinuousStates",
    "fmi2GetDerivatives", "fmi2GetEventIndicators", "fmi2GetContinuousStates",
    "fmi2GetNominalsOfContinuousStates", "fmi2SetRealInputDerivatives", "fmi2GetRealOutputDerivatives",
    "fmi2DoStep", "fmi2CancelStep", "fmi2GetStatus", "fmi2GetRealStatus", "fmi2GetIntegerStatus",
    "fmi2GetBooleanStatus", "fmi2GetStringStatus",
    # FMI 3.0 (appended: the codes of FMI 2.0 stay as they were)
    "fmi3InstantiateModelExchange", "fmi3InstantiateCoSimulation", "fmi3FreeInstance", "fmi3SetDebugLogging",
    "fmi3EnterInitializationMode", "fmi3ExitInitializationMode", "fmi3EnterEventMode", "fmi3Terminate",
    "fmi3Reset", "fmi3GetFloat64", "fmi3SetFloat64", "fmi3GetFloat32", "fmi3GetInt32", "fmi3GetUInt32",
    "fmi3GetInt64", "fmi3GetBoolean", "fmi3UpdateDiscreteStates", "fmi3EnterContinuousTimeMode",
    "fmi3CompletedIntegratorStep", "fmi3SetTime", "fmi3SetContinuousStates",
    "fmi3GetContinuousStateDerivatives", "fmi3GetEventIndicators", "fmi3GetContinuousStates",
    "fmi3GetNominalsOfContinuousStates", "fmi3EnterStepMode", "fmi3DoStep", "fmi3GetInt8", "fmi3GetUInt8",
    "fmi3GetInt16", "fmi3GetUInt16", "fmi3GetUInt64",
)
CODE = {name: k for k, name in enumerate(FUNCTIONS)}
IDLE = 0


class Record(ctypes.Structure):
    """The shared record.

    Fields
    ------
    function : int
        Index in :data:`FUNCTIONS` of the FMI function in progress (0: none).
    time : float
        Simulated time of the call [s].
    call_timeout : float
        The component's watchdog, ``plant.call_timeout`` [s] (0: none set yet).
    component : bytes
        The component's name in the scenario.
    """

    _fields_ = [("function", ctypes.c_int32), ("_pad", ctypes.c_int32), ("time", ctypes.c_double),
                ("call_timeout", ctypes.c_double), ("component", ctypes.c_char * 64)]


#: records in the shared array: one per FMU component (each with its own watchdog); more run unwatched
SLOTS = 32
Records = Record * SLOTS

_shared: Any = None
_next = 0


def new_shared() -> tuple[mmap.mmap, Any]:
    """``SLOTS`` records in an anonymous shared mapping, inherited by a forked child (the mapping keeps them alive)."""
    buf = mmap.mmap(-1, ctypes.sizeof(Records), flags=mmap.MAP_SHARED)
    return buf, Records.from_buffer(buf)


def install(records: Any) -> None:
    """Make ``records`` (from :func:`new_shared`) the ones :func:`record` hands out in this process (None: private)."""
    global _shared, _next
    _shared, _next = records, 0


def record() -> Record:
    """A record of its own for an FMU component: the next free one of the supervisor's, else private memory."""
    global _next
    if _shared is None or _next >= SLOTS:
        return Record()
    _next += 1
    return _shared[_next - 1]


def current(records: Any) -> Record:
    """The record with an FMI call in progress, else the first one in use (the component that ran first)."""
    return next((r for r in records if r.function), None) or next((r for r in records if r.component), records[0])
