"""Two processes that need the same compiled library at once compile it once (a file lock per library): the
instruments' rollout (estimator/compiled.py) and the co-simulation's fine loop (cosim/fastloop/build.py). The
compiler is a wrapper that logs each call and takes a second, so that the two processes overlap."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

WRAPPER = """#!/bin/sh
echo "$$" >> "{log}"
sleep 1
exec cc "$@"
"""

ROLLOUT = "from feeddrive.estimator.compiled import _build; print(_build('double fd_twice(double x) { return 2 * x; }'))"
FINE_LOOP = "from feeddrive.cosim.fastloop.build import library; library(); print('ok')"


@pytest.mark.parametrize("code", [ROLLOUT, FINE_LOOP], ids=["rollout", "fine loop"])
def test_two_processes_compile_once(code, tmp_path):
    log = tmp_path / "calls.log"
    cc = tmp_path / "cc-logged"
    cc.write_text(WRAPPER.format(log=log))
    cc.chmod(0o755)
    env = os.environ | {"CC": str(cc), "FEEDDRIVE_CACHE": str(tmp_path / "cache")}
    procs = [subprocess.Popen([sys.executable, "-c", textwrap.dedent(code)], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    outs = [p.communicate(timeout=120) for p in procs]
    assert all(p.returncode == 0 for p in procs), [err for _, err in outs]
    assert len({out for out, _ in outs}) == 1  # the same library for both
    assert len(log.read_text().split()) == 1  # one compile: the second process waited and found it built
