"""report.json ``versions``: read from the loaded modules (no search of the installed distributions before the
simulation, issue 23), they are the distributions' own versions."""
from __future__ import annotations

import importlib.metadata
import platform

import casadi
import fmpy
import numpy

import feeddrive.cosim
from feeddrive.cosim.run import VERSIONED, _versions


def test_versions_are_the_installed_distributions():
    assert {casadi, fmpy, numpy, feeddrive.cosim}  # loaded: their __version__ is what is read
    expected = {"python": platform.python_version()}
    for pkg, _ in VERSIONED:
        try:
            expected[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            pass
    assert _versions() == expected
    assert set(expected) == {"python", "feeddrive-monitor", "fmpy", "numpy", "casadi"}
