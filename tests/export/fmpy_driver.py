"""Drive an FMU with fmpy from an input table, in a child process: ``python fmpy_driver.py FMU TABLE.npz OUT.json``.

TABLE.npz holds ``names`` (the FMU's inputs), ``table`` (one row per step, those inputs), ``h`` (the
step [s]) and ``outputs`` (names to read at the end). The results go to OUT.json; the process then leaves
with ``os._exit`` (pythonfmu 0.7's binary crashes the interpreter's shutdown of a process hosting it).
"""
from __future__ import annotations

import json
import os
import sys
import tempfile

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave


def main(fmu: str, table_file: str, out: str) -> None:
    data = np.load(table_file)
    names, table, h = [str(n) for n in data["names"]], data["table"], float(data["h"])
    md = read_model_description(fmu)
    variables = {v.name: v for v in md.modelVariables}
    slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(fmu, tempfile.mkdtemp()),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="driven")
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    refs = [variables[n].valueReference for n in names]
    for n, row in enumerate(table.tolist()):
        slave.setReal(refs, row)
        slave.doStep(currentCommunicationPoint=n * h, communicationStepSize=h)
    results = {}
    for name in (str(n) for n in data["outputs"]):
        v = variables[name]
        get = slave.getInteger if v.type == "Integer" else slave.getReal
        results[name] = get([v.valueReference])[0]
    slave.terminate()
    with open(out, "w", encoding="utf-8") as f:
        json.dump(results, f)


if __name__ == "__main__":
    main(*sys.argv[1:4])
    sys.stdout.flush()
    os._exit(0)
