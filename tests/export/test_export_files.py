"""The exported FMUs and system description: FMI validity, ports and units, the wiring of ``cosim run``, CLI."""
from __future__ import annotations

import zipfile
from xml.etree import ElementTree

import pytest
from export_helpers import EXAMPLES, HERE
from fmpy import read_model_description
from fmpy.validation import validate_fmu

from feeddrive.cosim.cli import main as cosim
from feeddrive.cosim.export.system import OSP_NS, SSD_NS
from feeddrive.cosim.master import Master

NS = {"osp": OSP_NS}


def osp_links(path) -> set[tuple[str, str, str, str]]:
    root = ElementTree.parse(path).getroot()
    links = set()
    for c in root.iterfind("osp:Connections/osp:VariableConnection", NS):
        (a, b) = c.iterfind("osp:Variable", NS)
        links.add((a.get("simulator"), a.get("name"), b.get("simulator"), b.get("name")))
    return links


def test_every_exported_fmu_passes_fmpy_validation(healthy_system):
    _, paths = healthy_system
    for name in ("nc", "plant", "sensors", "monitor"):
        assert validate_fmu(str(paths[name])) == [], name


def test_ports_units_and_parameters_come_from_the_components_and_the_scenario(healthy_system):
    _, paths = healthy_system
    md = {n: {v.name: v for v in read_model_description(str(paths[n])).modelVariables}
          for n in ("nc", "sensors", "monitor")}
    assert (md["nc"]["speed_ref"].causality, md["nc"]["speed_ref"].unit) == ("output", "rad/s")
    assert (md["nc"]["position"].causality, md["nc"]["position"].unit) == ("input", "m")
    assert md["nc"]["kv"].causality == "parameter" and float(md["nc"]["kv"].start) == 30.0
    # every real parameter carries its unit (on main the monitor's filter_cutoff_hz, window_s, ... had none)
    assert (md["nc"]["kv"].unit, md["nc"]["pitch"].unit, md["nc"]["accel"].unit) == ("1/s", "m", "m/s2")
    assert {n: md["monitor"][n].unit for n in ("filter_cutoff_hz", "window_s", "budget_s", "max_age_s", "alpha",
                                               "gain_tol", "min_relative_drift")} == {
        "filter_cutoff_hz": "Hz", "window_s": "s", "budget_s": "s", "max_age_s": "s", "alpha": "1",
        "gain_tol": "1", "min_relative_drift": "1"}
    assert not [v.name for v in md["monitor"].values() if v.type == "Real" and v.causality == "parameter"
                and not v.unit]
    assert (md["sensors"]["Im1"].unit, md["sensors"]["theta_enc"].unit) == ("A", "rad")
    assert int(md["sensors"]["seed"].start) == 1  # the scenario's seed
    assert md["sensors"]["Im1.gain"].variability == "tunable"
    assert (md["sensors"]["Im1.offset"].unit, md["sensors"]["w_tach.noise"].unit) == ("A", "rad/s")
    assert (md["monitor"]["R"].unit, md["monitor"]["Cd_std"].unit) == ("Ohm", "N.m")
    assert md["monitor"]["db"].type == "String" and md["monitor"]["motions"].type == "Integer"
    assert float(md["monitor"]["step_size"].start) == 1e-4


def test_the_system_has_the_connections_step_and_initial_values_of_cosim_run(healthy_system):
    s, paths = healthy_system
    with Master.from_scenario(s) as master:
        master.setup()
        wiring = master.connections
    plant_var = {role: e.var for role, e in s.plant.map.items()}

    def var(comp: str, port: str) -> str:
        return plant_var[port] if comp == "plant" else port

    expected = {(src.split(".")[0], var(*src.split(".")), dst.split(".")[0], var(*dst.split(".")))
                for dst, src in wiring.items()}
    assert osp_links(paths["system"]) == expected
    assert ("monitor", "request", "nc", "request") in expected and ("plant", "x", "nc", "position") in expected
    root = ElementTree.parse(paths["system"]).getroot()
    assert float(root.findtext("osp:BaseStepSize", namespaces=NS)) == s.step
    plant = root.find("osp:Simulators/osp:Simulator[@name='plant']", NS)
    values = {iv.get("variable"): float(iv[0].get("value")) for iv in plant.iterfind(".//osp:InitialValue", NS)}
    # the axis's drive chain (scenario `axis:`) reaches the plant FMU with its parameters
    assert values == {"R": 0.6, "L": 4.0e-3, "K": 1.05, "Jt": 0.1, "ft": 0.02, "Cd": 1.2,
                      "pitch": s.axis.pitch, "belt_ratio": s.axis.ratio}
    with zipfile.ZipFile(paths["ssp"]) as z:
        ssd = ElementTree.fromstring(z.read("SystemStructure.ssd"))
        assert {f"resources/{paths[n].name}" for n in ("nc", "plant", "sensors", "monitor")} <= set(z.namelist())
    ssp_links = {(c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"))
                 for c in ssd.iter(f"{{{SSD_NS}}}Connection")}
    assert ssp_links == expected


def test_cli_exports_and_info_shows_the_ports(feeddrive_fmu, tmp_path, capsys):
    assert cosim(["export-fmu", "nc", str(EXAMPLES / "tool_change.yaml"), "--out", str(tmp_path)]) == 0
    capsys.readouterr()
    assert cosim(["export-fmu", "nc", str(EXAMPLES / "tool_change.yaml"), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "FeedDriveNC.fmu exists" in err and "--overwrite" in err
    assert cosim(["info", str(tmp_path / "FeedDriveNC.fmu")]) == 0
    out = capsys.readouterr().out
    assert "feeddrive nc of scenario tool-change" in out
    assert any(line.split()[:2] == ["speed_ref", "Real"] and "rad/s" in line for line in out.splitlines())


@pytest.mark.parametrize("extra, message", [
    ("components:\n  - {name: mine, class: 'feeddrive.cosim.monitor:Monitor'}\n", "components: user components"),
    ("monitor: {class: 'feeddrive.cosim.monitor:Monitor2'}\n", "monitor"),
    ("", "plant.oversample: 4; the exported system steps every FMU at `step`, expected 1"),
    ("", "nc.cycle: 0.002 s; the exported system steps the NC at `step` = 0.0001 s"),
])
def test_cli_refuses_what_an_osp_system_cannot_hold(feeddrive_fmu, tmp_path, capsys, extra, message):
    text = (HERE / "sensor_fault_short.yaml").read_text().replace('monitor: {db: ":memory:"}\n', "")
    path = tmp_path / "s.yaml"
    if "oversample" in message:
        text = text.replace("  fmu: builtin\n", "  fmu: builtin\n  oversample: 4\n")
    if "cycle" in message:
        text = text.replace("nc:\n", "nc:\n  cycle: 2.0e-3\n")
    path.write_text(text + extra)
    status = cosim(["export-system", str(path), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and message in err, err
    assert not (tmp_path / "out" / "OspSystemStructure.xml").exists()


def test_an_fmu_refuses_a_step_other_than_the_scenarios(healthy_system, tmp_path):
    """The NC's feed-forward and the sensors' encoder window are built on the step: another one is an error."""
    import subprocess
    import sys

    import numpy as np

    _, paths = healthy_system
    np.savez(tmp_path / "table.npz", names=["position", "request"], table=np.zeros((3, 2)), h=2e-4, outputs=[])
    proc = subprocess.run([sys.executable, str(HERE / "fmpy_driver.py"), str(paths["nc"]), str(tmp_path / "table.npz"),
                           str(tmp_path / "out.json")], capture_output=True, text=True, timeout=300)
    assert proc.returncode != 0 and "doStep" in proc.stderr
    assert not (tmp_path / "out.json").exists()
