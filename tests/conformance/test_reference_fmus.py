"""Conformance on the Modelica Reference-FMUs: each model the master can run, FMI 2.0 and 3.0, CS and ME.

Each FMU runs alone as a component (a scenario with only ``components:``) through ``cosim run``; its
outputs are compared with fmpy's ``simulate_fmu`` (Co-Simulation: the same communication step, within
1e-6 of the signal's range; Model Exchange: both with CVode at rtol 1e-8, within ``ME_FMPY``) and with
the model's reference output ``<Model>/<Model>_out.csv`` (within ``REFERENCE`` of the signal's range:
the reference was made by fmusim in Co-Simulation, with the FMU's fixed-step Euler; Model Exchange
integrates the same ODE with CVode, the difference is Euler's error). Clocks (Scheduled Execution) is
refused in one line, exit 2. The measured maximum errors are in the README's conformance table
(``python tests/conformance/test_reference_fmus.py`` prints them once the FMUs are built).
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
import yaml
from reference_models import MODELS, SOURCE

from feeddrive.cosim.cli import main

#: (stop time [s], communication step [s]) of each model's run: its reference output's grid
EXPERIMENT = {"BouncingBall": (3.0, 0.01), "Dahlquist": (10.0, 0.1), "Feedthrough": (2.0, 0.1),
              "Resource": (1.0, 1.0), "Stair": (8.8, 0.2), "VanDerPol": (20.0, 0.01), "StateSpace": (10.0, 1.0),
              "Roberts": (1.0, 0.01)}
#: the inputs at their start values (the reference outputs are made with them)
INPUTS = {"Feedthrough": {"Float64_continuous_input": 0.0, "Float64_discrete_input": 0.0},
          "StateSpace": {"u[1]": 1.0, "u[2]": 2.0, "u[3]": 3.0}}
#: largest error against fmpy (fraction of the signal's range, at least of 1): CS same step, ME both CVode
CS_FMPY = 1e-6
ME_FMPY = 1e-4
#: largest error against the reference output (fraction of the signal's range, at least of 1). CS: the
#: same fixed-step Euler as the reference. ME: CVode against that Euler, whose own error this measures
#: (BouncingBall: a bounce one Euler step earlier flips v; VanDerPol: Euler's phase drift over 20 s)
REFERENCE = {"cs": 1e-6, "me": 1e-6}
REFERENCE_ME = {"BouncingBall": 0.6, "Dahlquist": 0.03, "VanDerPol": 0.2, "StateSpace": 0.01}
CASES = [(v, m, i) for v, models in MODELS.items() for m in models if m != "Clocks" for i in ("cs", "me")]


def run_cosim(fmu: Path, interface: str, model: str, tmp: Path) -> dict[str, np.ndarray]:
    stop, step = EXPERIMENT[model]
    scenario = {"name": f"{model}-{interface}", "step": step, "stop_time": stop,
                "components": [{"name": "m", "fmu": str(fmu), "config": {"interface": interface},
                                "inputs": {k: v for k, v in INPUTS.get(model, {}).items()
                                           if interface == "cs" or "discrete" not in k}}]}
    path = tmp / f"{model}-{interface}.yaml"
    path.write_text(yaml.safe_dump(scenario))
    assert main(["run", str(path), "--out", str(tmp / "out"), "--no-progress"]) == 0
    header = (tmp / "out" / "signals.csv").read_text().split("\n", 1)[0].split(",")
    data = np.loadtxt(tmp / "out" / "signals.csv", delimiter=",", skiprows=1, ndmin=2)
    return {name.split(" [")[0].removeprefix("m."): data[:, k] for k, name in enumerate(header)}


def run_fmpy(fmu: Path, interface: str, model: str, names: list[str]) -> dict[str, np.ndarray]:
    from fmpy import simulate_fmu

    stop, step = EXPERIMENT[model]
    kind = {"cs": "CoSimulation", "me": "ModelExchange"}[interface]
    res = simulate_fmu(str(fmu), fmi_type=kind, start_time=0.0, stop_time=stop, output_interval=step, relative_tolerance=1e-8,
                       record_events=False)
    out = {"time": res["time"]}
    for name in res.dtype.names[1:]:
        values = np.asarray(res[name], dtype=float)
        if values.ndim == 2:
            out |= {f"{name}[{k + 1}]": values[:, k] for k in range(values.shape[1])}
        else:
            out[name] = values
    return {k: v for k, v in out.items() if k in names or k == "time"}


def reference(model: str) -> dict[str, np.ndarray]:
    """The numeric columns of ``<Model>_out.csv`` (arrays as ``name[k]``, booleans as 0 / 1)."""
    with open(SOURCE / model / f"{model}_out.csv", newline="") as f:
        rows = list(csv.reader(f))
    out: dict[str, list] = {}
    for k, name in enumerate(rows[0]):
        for row in rows[1:]:
            cells = row[k].split(" ")
            try:
                values = [{"true": 1.0, "false": 0.0}.get(c, None) if c in ("true", "false") else float(c) for c in cells]
            except ValueError:
                break  # String, Binary: not signals
            keys = [name] if len(values) == 1 else [f"{name}[{j + 1}]" for j in range(len(values))]
            for key, v in zip(keys, values):
                out.setdefault(key, []).append(v)
    return {k: np.array(v) for k, v in out.items() if len(v) == len(rows) - 1}


def max_error(a: dict, b: dict, names) -> tuple[float, str]:
    """Largest |a - b| / max(range, 1) over the common signals, on the common time grid."""
    n = min(len(a["time"]), len(b["time"]))
    np.testing.assert_allclose(a["time"][:n], b["time"][:n], rtol=0, atol=1e-9)
    worst, where = 0.0, ""
    for name in names:
        x, y = a[name][:n], b[name][:n]
        scale = max(1.0, float(np.ptp(y)))
        e = float(np.max(np.abs(x - y))) / scale
        if e > worst:
            worst, where = e, name
    return worst, where


def compare(fmus: dict, version: int, model: str, interface: str, tmp: Path) -> dict:
    fmu = fmus[version] / f"{model}.fmu"
    ours = run_cosim(fmu, interface, model, tmp)
    signals = [k for k in ours if k != "time"]
    theirs = run_fmpy(fmu, interface, model, signals)
    assert set(theirs) - {"time"} == set(signals), (sorted(theirs), signals)
    result = {"fmpy": max_error(ours, theirs, signals), "n": len(ours["time"])}
    ref = reference(model)
    if model == "Roberts" and set(ref) == {"time", "h", "v"}:
        result["reference"] = None  # this source commit ships BouncingBall's output as Roberts_out.csv
    else:
        common = [k for k in signals if k in ref]
        assert common, (sorted(ref), signals)
        result["reference"] = max_error(ours, ref, common)
    return result


@pytest.mark.parametrize("version, model, interface", CASES, ids=[f"fmi{v}-{m}-{i}" for v, m, i in CASES])
def test_reference_fmu_matches_fmpy_and_its_reference_output(reference_fmus, tmp_path, version, model, interface):
    result = compare(reference_fmus, version, model, interface, tmp_path)
    stop, step = EXPERIMENT[model]
    assert result["n"] == round(stop / step) + 1
    err, name = result["fmpy"]
    assert err <= (CS_FMPY if interface == "cs" else ME_FMPY), f"{name}: {err:.3g} against fmpy"
    if result["reference"] is not None:
        err, name = result["reference"]
        limit = REFERENCE_ME.get(model, REFERENCE["me"]) if interface == "me" else REFERENCE["cs"]
        assert err <= limit, f"{name}: {err:.3g} against {model}_out.csv"


@pytest.mark.parametrize("interface", ["cs", "me"])
def test_clocks_is_refused_in_one_line(reference_fmus, tmp_path, capfd, interface):
    scenario = {"name": "clocks", "step": 0.1, "stop_time": 1.0,
                "components": [{"name": "c", "fmu": str(reference_fmus[3] / "Clocks.fmu"),
                                "config": {"interface": interface}}]}
    path = tmp_path / "clocks.yaml"
    path.write_text(yaml.safe_dump(scenario))
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0]
    assert "Clocks.fmu supports only Scheduled Execution" in err[0] and "components[0].fmu" in err[0]


def test_info_on_clocks_lists_its_variables_and_says_why_it_cannot_run(reference_fmus, tmp_path, capfd):
    # it has neither Co-Simulation nor Model Exchange: there was no binary to look for, and a traceback
    fmu = reference_fmus[3] / "Clocks.fmu"
    assert main(["info", str(fmu)]) == 0
    out, err = capfd.readouterr()
    assert "Clocks, FMI 3.0, Scheduled Execution, generated by" in out and "Traceback" not in err  # was "FMI 3.0, , "
    assert err.strip().splitlines() == [f"cosim info: warning: {fmu}: Clocks.fmu supports only Scheduled Execution "
                                        "(FMI 3.0 clocks); the master runs Co-Simulation and Model Exchange FMUs; "
                                        "cosim run refuses it (exit 2)"]
    scenario = tmp_path / "s.yaml"
    scenario.write_text(yaml.safe_dump({"name": "s", "plant": {"fmu": str(fmu)}}))
    assert main(["info", str(fmu), "--map", str(scenario)]) == 2
    assert capfd.readouterr().err.strip().splitlines()[-1].startswith(f"cosim info: error: {fmu}: Clocks.fmu supports only")


if __name__ == "__main__":  # the README's table: python tests/conformance/test_reference_fmus.py BUILD_DIR
    import sys
    import tempfile

    fmus = {2: Path(sys.argv[1]) / "b2" / "fmus", 3: Path(sys.argv[1]) / "b3" / "fmus"}
    for v, m, i in CASES:
        with tempfile.TemporaryDirectory() as tmp:
            r = compare(fmus, v, m, i, Path(tmp))
        ref = "n/a" if r["reference"] is None else f"{r['reference'][0]:.2g} ({r['reference'][1]})"
        print(f"| {m} | {v}.0 | {i.upper()} | {r['fmpy'][0]:.2g} | {ref} |")
