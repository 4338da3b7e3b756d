"""The monitor FMU under fmpy, driven by a ``cosim run`` signals.csv, against ``cosim monitor`` on that CSV."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("pythonfmu")

from export_helpers import EXAMPLES, HERE, scenario  # noqa: E402
from fmpy import read_model_description  # noqa: E402

from feeddrive.cosim.cli import main as cosim  # noqa: E402
from feeddrive.cosim.export.build import build_component_fmu  # noqa: E402
from feeddrive.cosim.export.slave import PARAMETERS  # noqa: E402
from feeddrive.cosim.monitor import MEASUREMENTS  # noqa: E402
from feeddrive.cosim.recorded import load_recording  # noqa: E402

#: cosim monitor role -> signals.csv column
ROLES = {"time": "time", "voltage": "sensors.u", "voltage_ref": "sensors.u_ref", "current1": "sensors.Im1",
         "current2": "sensors.Im2", "speed": "sensors.w_tach", "position": "sensors.theta_enc", "state": "nc.state"}


def test_monitor_fmu_on_a_recorded_table_gives_cosim_monitors_parameters(healthy_zoh_run, tmp_path, capsys):
    csv = healthy_zoh_run.paths["signals"]
    assert cosim(["monitor", str(csv), *[a for r, c in ROLES.items() for a in ("--map", f"{r}={c}")],
                  "--db", str(tmp_path / "cli.sqlite"), "--sample-time", "1e-4", "--json"]) == 0
    # the step is given: derived from the CSV's 10-digit times it would differ by 1e-13, which moves R by 7e-7
    (expected,) = json.loads(capsys.readouterr().out)["motions"]
    assert expected["validated"] is True

    # the same information for the FMU: cosim monitor differentiates the encoder angle by central differences
    # (np.gradient), which is the monitor's centred speed with a window of two samples
    rec = load_recording(csv, {"time": "time", "position": "sensors.theta_enc", "motion": "nc.motion",
                               **{k: f"sensors.{k}" for k in MEASUREMENTS if k not in ("w_enc", "theta_enc")},
                               "state": "nc.state"}, sample_time=1e-4)
    s = scenario(EXAMPLES / "tool_change.yaml", db=str(tmp_path / "fmu.sqlite"), encoder_window_s=2 * rec.h)
    fmu = build_component_fmu("monitor", s, tmp_path)
    columns = {k: rec.signals[k] for k in ("Im1", "Im2", "u", "u_ref", "w_tach", "state", "motion")}
    columns |= {"theta_enc": rec.signals["position"], "w_enc": np.gradient(rec.signals["position"], rec.h)}

    md = read_model_description(str(fmu))
    inputs = [v.name for v in md.modelVariables if v.causality == "input"]
    outputs = list(PARAMETERS) + [f"{p}_std" for p in PARAMETERS] + ["validated", "motions"]
    np.savez(tmp_path / "table.npz", names=inputs, table=np.column_stack([columns[n] for n in inputs]), h=s.step,
             outputs=outputs)
    subprocess.run([sys.executable, str(HERE / "fmpy_driver.py"), str(fmu), str(tmp_path / "table.npz"),
                    str(tmp_path / "out.json")], check=True, timeout=600)
    out = json.loads((tmp_path / "out.json").read_text())
    got = {p: out[p] for p in PARAMETERS}
    std = {p: out[f"{p}_std"] for p in PARAMETERS}
    validated, motions = out["validated"], out["motions"]

    assert (validated, motions) == (1, 1)
    for p in PARAMETERS:
        assert got[p] == pytest.approx(expected["parameters"][p]["value"], rel=1e-9), p
        assert std[p] == pytest.approx(expected["parameters"][p]["std"], rel=1e-9), p
    (reported,) = json.loads((tmp_path / "fmu.report.json").read_text())["motions"]
    assert reported["parameters"]["R"]["ci95"] == pytest.approx(expected["parameters"]["R"]["ci95"], rel=1e-9)
