"""When to show a progress bar: asked for, on a terminal, and not under CI.

Every step that can take more than ~2 s shows one on stderr (the FMU build, ``cosim run``'s simulation,
``cosim design``, campaigns); a pipe, a log file or a CI job gets none, so their output stays clean.
"""
from __future__ import annotations

import os
import sys


def enabled(requested: bool = True) -> bool:
    """True when a progress bar is ``requested``, stderr is a terminal and ``$CI`` is not set."""
    return bool(requested) and sys.stderr.isatty() and not os.environ.get("CI")
