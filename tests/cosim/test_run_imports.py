"""What ``cosim run`` imports in the run's own process (issue 23): no module of the project imports
scipy.stats (estimator.distributions has what the estimator needs from it) and matplotlib is imported only
by the drawing processes (cosim.plot_workers), which load it while the simulation runs."""
from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _imports_scipy_stats(tree: ast.AST) -> list[int]:
    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import) and any(a.name.startswith("scipy.stats") for a in node.names):
            lines.append(node.lineno)
        elif isinstance(node, ast.ImportFrom) and node.module:
            if node.module.startswith("scipy.stats") or (node.module == "scipy" and any(a.name == "stats" for a in node.names)):
                lines.append(node.lineno)
    return lines


def test_no_module_of_the_project_imports_scipy_stats():
    found = {}
    for folder in ("estimator", "cosim", "models", "fmu_build"):
        for path in (ROOT / folder).rglob("*.py"):
            lines = _imports_scipy_stats(ast.parse(path.read_text(encoding="utf-8")))
            if lines:
                found[str(path.relative_to(ROOT))] = lines
    assert not found, f"scipy.stats imported by {found}: use feeddrive.estimator.distributions"


RUN = """
import json, sys
from feeddrive.cosim.run import run_scenario
res = run_scenario(sys.argv[1], sys.argv[2])
print(json.dumps({"matplotlib": sorted(m for m in sys.modules if m.split(".")[0] == "matplotlib"),
                  "heavy": sorted(m for m in ("scipy.signal", "statsmodels", "pandas") if m in sys.modules),
                  "plots": [p.name for p in res.paths["plots"]]}))
"""


def test_the_run_does_not_import_matplotlib_and_its_figures_are_drawn(tmp_path):
    """The example's five figures are written, by processes of their own: the run never imports matplotlib
    (its import and the figures took longer than the simulation), nor scipy.signal, statsmodels or pandas.
    scipy.stats is imported only by scipy itself, never by the project."""
    # two drawing processes whatever the CPUs (and whatever `cosim campaign`, run in this process by another
    # test, set: it asks for one)
    env = os.environ | {"FEEDDRIVE_PLOT_PROCESSES": "2"}
    proc = subprocess.run([sys.executable, "-X", "importtime", "-c", RUN, str(ROOT / "examples" / "tool_change.yaml"),
                           str(tmp_path / "run")], capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["matplotlib"] == []
    # scipy.signal's package init is ~1 s, statsmodels with pandas 0.3-0.9 s: estimator.lti and estimator.glsar
    # have what the run needs
    assert out["heavy"] == []
    assert out["plots"] == ["motion_1_profiles.png", "motion_1_currents.png", "monitor_motion1.png",
                            "monitor_correlation1.png", "monitor_trends.png"]
    for name in out["plots"]:
        png = (tmp_path / "run" / "plots" / name).read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    # -X importtime: "import time: self | cumulative | <indent>name", a module's importer is the next line less indented
    rows = [line.split("|")[2] for line in proc.stderr.splitlines() if line.startswith("import time:") and "self [us]" not in line]
    depth = [len(r) - len(r.lstrip()) for r in rows]
    names = [r.strip() for r in rows]
    for i, name in enumerate(names):
        if name == "scipy.stats":
            importer = next((names[j] for j in range(i + 1, len(names)) if depth[j] < depth[i]), None)
            assert importer is not None and importer.startswith("scipy."), f"scipy.stats imported by {importer}"
