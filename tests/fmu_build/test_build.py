"""Compiling, caching and the ``cosim build-fmu`` command; a second model through the same wrapper."""
from __future__ import annotations

import math
import zipfile
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace

import casadi as ca
import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu

import feeddrive.fmu_build.build
import feeddrive.fmu_build.codegen
from feeddrive.cosim.cli import main as cosim_main
from feeddrive.fmu_build import CompilerError, FMUBuildInputError, build_fmu, builtin_fmu
from feeddrive.models import Equation, Model, Variable, feed_drive


def rc_model() -> Model:
    """First-order lag tau dv/dt = vin - v, with a calculated output e = vin - v."""
    V = Variable
    variables = [V("v", "V", "capacitor voltage", "state", 0.0, output=True),
                 V("vin", "V", "source voltage", "input", 1.0),
                 V("tau", "s", "time constant", "physical", 0.2, lower=0.0, lower_strict=True),
                 V("e", "V", "voltage across the resistor", "algebraic", output=True)]
    s = {v.name: v.sym for v in variables}
    der_v = ca.SX.sym("der_v")
    eq = Equation("lag", s["tau"] * der_v + s["v"] - s["vin"], solves_for="v", output="vin",
                  normaliser=None, paper_ref="-")
    return Model("RCLag", variables, [eq], {}, {"e": s["vin"] - s["v"]}, "first-order lag",
                 derivative_symbols={"v": der_v})


def test_a_second_model_needs_no_c_changes(tmp_path):
    fmu = build_fmu(rc_model(), tmp_path / "RCLag.fmu", cs_substep=1e-3)
    assert validate_fmu(str(fmu)) == []
    variables = {v.name: v for v in read_model_description(str(fmu)).modelVariables}
    assert float(variables["cs_substep"].start) == 1e-3
    assert variables["tau"].unit == "s" and variables["e"].causality == "output"
    with zipfile.ZipFile(fmu) as z:  # a native library and the XML, no Python
        assert sorted(z.namelist()) == ["binaries/linux64/RCLag.so", "modelDescription.xml"]
    for kind in ("CoSimulation", "ModelExchange"):
        res = simulate_fmu(str(fmu), fmi_type=kind, stop_time=1.0, output_interval=0.01,
                           start_values={"vin": 2.0}, relative_tolerance=1e-10)
        exact = 2.0 * (1 - np.exp(-res["time"] / 0.2))
        np.testing.assert_allclose(res["v"], exact, atol=1e-7)
        np.testing.assert_allclose(res["e"], 2.0 - exact, atol=1e-7)


@pytest.mark.parametrize("substep", [0.0, -1e-5, math.nan])
def test_non_positive_substep_is_bad_input(tmp_path, substep):
    with pytest.raises(FMUBuildInputError, match="cs_substep must be a positive number of seconds"):
        build_fmu(out=tmp_path / "x.fmu", cs_substep=substep)


@pytest.mark.parametrize("cc", ["/bin/false", "definitely-not-a-compiler"])
def test_failing_compiler_is_named(tmp_path, monkeypatch, cc):
    monkeypatch.setenv("CC", cc)
    with pytest.raises(CompilerError, match=f"C compilation with '{cc}' failed") as err:
        builtin_fmu(tmp_path)
    assert err.value.compiler == cc
    assert not list(tmp_path.rglob("*.fmu"))  # nothing half-built is cached


def test_syntax_error_shows_the_compiler_message(tmp_path, monkeypatch):
    broken = tmp_path / "fmi2_wrapper.c"
    broken.write_text(feeddrive.fmu_build.codegen.WRAPPER_SOURCE.read_text() + "\nint broken( {\n")
    monkeypatch.setattr(feeddrive.fmu_build.codegen, "WRAPPER_SOURCE", broken)
    monkeypatch.setenv("CC", "gcc")
    with pytest.raises(CompilerError, match="C compilation with 'gcc' failed: .*fmi2_wrapper.c:.*error") as err:
        build_fmu(out=tmp_path / "x.fmu")
    assert "broken" in err.value.output


def test_cache_is_reused_and_rebuilt_when_the_sources_change(tmp_path, monkeypatch):
    first = builtin_fmu(tmp_path)
    stamp = first.stat().st_mtime_ns
    assert builtin_fmu(tmp_path) == first and first.stat().st_mtime_ns == stamp  # not rebuilt

    def not_generated(*args):  # the inputs' key finds the FMU: its sources are not generated again
        raise AssertionError("sources generated again")

    with monkeypatch.context() as patch:
        patch.setattr(feeddrive.fmu_build.build, "_generated", not_generated)
        assert builtin_fmu(tmp_path) == first

    def heavier_drive(backlash: bool = False) -> Model:  # a model edit: the default inertia
        m = feed_drive(backlash)
        m.variables["Jt"] = replace(m.variables["Jt"], nominal=0.2)
        return m

    monkeypatch.setattr(feeddrive.fmu_build.build, "feed_drive", heavier_drive)
    second = builtin_fmu(tmp_path)
    assert second != first and second.name == first.name
    jt = {v.name: v for v in read_model_description(str(second)).modelVariables}["Jt"]
    assert float(jt.start) == 0.2
    assert first.stat().st_mtime_ns == stamp

    edited = tmp_path / "fmi2_wrapper.c"  # so does a wrapper edit
    edited.write_text(feeddrive.fmu_build.codegen.WRAPPER_SOURCE.read_text() + "/* edited */\n")
    monkeypatch.setattr(feeddrive.fmu_build.codegen, "WRAPPER_SOURCE", edited)
    assert builtin_fmu(tmp_path) not in (first, second)


def test_parallel_builds_into_one_cache_agree(tmp_path, monkeypatch):
    """Two processes asking for the same FMU at once: one compiles it, the other waits for it (the cache key's
    lock) and takes it; the compiler (a logging $CC) ran once."""
    log = tmp_path / "cc.log"
    cc = tmp_path / "logging-cc"
    cc.write_text(f'#!/bin/sh\necho "$$" >> {log}\nexec cc "$@"\n')
    cc.chmod(0o755)
    monkeypatch.setenv("CC", str(cc))
    cache = tmp_path / "cache"
    with ProcessPoolExecutor(2) as pool:
        paths = list(pool.map(builtin_fmu, [cache, cache]))
    assert paths[0] == paths[1]
    assert validate_fmu(str(paths[0])) == []
    assert [p.name for p in paths[0].parent.iterdir()] == ["FeedDrive.fmu"]  # no temporary left over
    assert len(log.read_text().splitlines()) == 1


def test_cli_builds_and_refuses_to_overwrite(tmp_path, capsys):
    out = tmp_path / "plant.fmu"
    assert cosim_main(["build-fmu", "--out", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == str(out)
    assert lines[1].startswith("FeedDrive: FMI 2.0 Co-Simulation + Model Exchange, 6 states, 3 inputs, 7 outputs")
    stamp = out.stat().st_mtime_ns
    assert cosim_main(["build-fmu", "--out", str(out)]) == 2
    assert "file exists (use --overwrite to replace it)" in capsys.readouterr().err
    assert out.stat().st_mtime_ns == stamp
    assert cosim_main(["build-fmu", "--out", str(out), "--overwrite"]) == 0
    assert validate_fmu(str(out)) == []


def test_cli_default_out_is_relative_to_the_working_directory(tmp_path, monkeypatch):
    """The default --out is ./FeedDrive.fmu: a relative path must survive the compiler's own cwd."""
    monkeypatch.chdir(tmp_path)
    assert cosim_main(["build-fmu"]) == 0
    assert validate_fmu(str(tmp_path / "FeedDrive.fmu")) == []
    assert not list(tmp_path.glob(".fmu_build_*"))  # the build directory is gone
