"""A compile longer than a moment shows its elapsed time on a terminal (issue 23: progress on every step over
2 s; the FMU build, and the PMSM monitor's model simulation compiled on its first run, 9 s of gcc, which was
silent), and nothing in a pipe; both stop a compiler that hangs at the stated timeout."""
from __future__ import annotations

import fcntl
import os
import pty
import struct
import subprocess
import sys
import termios
import time

import pytest

from feeddrive.fmu_build.build import run_with_progress

CHILD = """
import subprocess, sys
from feeddrive.fmu_build.build import run_with_progress
done = run_with_progress([sys.executable, "-c", "import time; time.sleep(1.3); print('built')"], None, "compiling x")
print("exit", done.returncode, done.stdout.strip(), file=sys.stderr)
try:
    run_with_progress([sys.executable, "-c", "import time; time.sleep(30)"], None, "compiling y", timeout=1.0)
except subprocess.TimeoutExpired:
    print("timed out", file=sys.stderr)
"""


def test_the_elapsed_time_is_shown_on_a_terminal_and_a_hung_compiler_is_stopped():
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 120, 0, 0))  # a terminal has a width
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", CHILD], stderr=slave, stdout=subprocess.DEVNULL, env=env)
    os.close(slave)
    out = b""
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:  # the child closed the terminal
            break
        if not chunk:
            break
        out += chunk
    proc.wait(timeout=30)
    os.close(master)
    text = out.decode(errors="replace")
    assert "compiling x: 00:01" in text, text  # refreshed while it ran
    assert "exit 0 built" in text and "timed out" in text, text
    assert time.perf_counter() - t0 < 10  # the 30 s sleep was killed at 1 s


def test_nothing_is_shown_in_a_pipe_and_the_timeout_holds_there_too(capfd):
    done = run_with_progress([sys.executable, "-c", "print('ok')"], None, "compiling z")
    assert done.returncode == 0 and done.stdout.strip() == "ok"
    with pytest.raises(subprocess.TimeoutExpired):
        run_with_progress([sys.executable, "-c", "import time; time.sleep(30)"], None, "compiling z", timeout=0.5)
    assert "compiling z" not in capfd.readouterr().err
