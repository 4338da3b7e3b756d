"""A campaign worker imports, once, every module a run imports (``cosim_run.RUN_IMPORTS``, ``prepare``): a module
missing there is imported again by every run's forked child. A new lazily imported module (estimator.toeplitz)
was, and the speed-up on 2 workers fell from ~1.9 to 1.67 (pool) and 1.58 (Dask) with only bench_campaign's
warning to say so (issue 26, item 3)."""
from __future__ import annotations

import subprocess
import sys

import pytest

CHILD = """
import os, sys
from feeddrive.cosim.campaign.cosim_run import run_cosim
from feeddrive.cosim.campaign.schema import Campaign, expand

run_cosim.prepare()
base = {"name": "preload", "step": 1e-4, "stop_time": 2.1, "plant": {"fmu": "builtin"},
        "nc": {"program": [{"dwell": {"time": 0.02}},
                           {"tool_change": {"position": 0.15, "v_max": 0.22, "accel": 0.8, "time": 0.02}}]},
        "monitor": {"baseline": "nominal"}}
spec = expand(Campaign(name="preload", base=base, seed=1, repetitions=1, run_options={"methods": ["ls", "iv"]}))[0]
run_cosim.validate(spec)
read, write = os.pipe()
pid = os.fork()
if pid == 0:  # as a campaign's run: a child forked from the prepared worker
    before = set(sys.modules)
    result = run_cosim(spec)
    ok = bool(result["motions"]) and "parameters" in result["motions"][0]
    os.write(write, ("ran " if ok else "no-motion ").encode() + " ".join(sorted(set(sys.modules) - before)).encode())
    os._exit(0)
os.close(write)
with os.fdopen(read) as f:
    print(f.read())
os.waitpid(pid, 0)
"""


@pytest.mark.slow
def test_a_run_imports_nothing_its_prepared_worker_has_not(feeddrive_fmu):
    out = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    status, *late = out.stdout.split()
    assert status == "ran", out.stdout  # the run estimated its motion: the monitor's whole path was taken
    assert late == [], f"imported by the run, not by cosim_run.prepare (add them to RUN_IMPORTS): {late}"
