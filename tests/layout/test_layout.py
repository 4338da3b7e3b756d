"""The package's shape: one `feeddrive` namespace, every module importable, no import cycles."""
from __future__ import annotations

import ast
import importlib
import importlib.metadata
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

import feeddrive.cosim

PACKAGES = ("models", "fmu_build", "estimator", "cosim")
REPO = Path(__file__).resolve().parents[2]


def all_modules() -> list[str]:
    names = []
    for pkg in PACKAGES:
        mod = importlib.import_module(f"feeddrive.{pkg}")
        names.append(mod.__name__)
        names += [m.name for m in pkgutil.walk_packages(mod.__path__, prefix=f"feeddrive.{pkg}.")]
    return sorted(n for n in names if not n.endswith("__main__"))


def source_of(module: str) -> Path:
    spec = importlib.util.find_spec(module)
    assert spec is not None and spec.origin
    return Path(spec.origin)


def imports_of(module: str, known: set[str]) -> set[str]:
    """feeddrive modules that ``module`` imports anywhere in its source (function-level imports too)."""
    tree = ast.parse(source_of(module).read_text())
    is_pkg = source_of(module).name == "__init__.py"
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative import
                parts = module.split(".")[: len(module.split(".")) - node.level + (1 if is_pkg else 0)]
                base = ".".join(parts + ([base] if base else []))
            # `from pkg import sub` imports the submodule pkg.sub when there is one
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names]
        else:
            continue
        out |= {t for t in targets if t in known and t != module}
    return out


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(n: str) -> list[str] | None:
        state[n] = 1
        stack.append(n)
        for m in sorted(graph[n]):
            if state.get(m) == 1:
                return stack[stack.index(m):] + [m]
            if m not in state and (cycle := visit(m)):
                return cycle
        stack.pop()
        state[n] = 2
        return None

    for n in sorted(graph):
        if n not in state and (cycle := visit(n)):
            return cycle
    return None


def test_every_module_imports_on_its_own():
    for name in all_modules():
        # a fresh interpreter per module would be slow; importing each in turn still catches a module that
        # only imports thanks to an earlier one when run alone with `python -c`, so spot-check that below
        importlib.import_module(name)


@pytest.mark.parametrize("name", ["feeddrive.cosim.master", "feeddrive.cosim.scenario", "feeddrive.estimator.oe",
                                  "feeddrive.cosim.fmu_adapter", "feeddrive.cosim.campaign.execute"])
def test_former_cycle_members_import_alone(name):
    subprocess.run([sys.executable, "-c", f"import {name}"], check=True, capture_output=True)


def test_no_import_cycles():
    modules = all_modules()
    known = set(modules)
    graph = {m: imports_of(m, known) for m in modules}
    # a package's __init__ re-exporting its submodules is a one-way edge; a submodule importing its own
    # package __init__ back would close a cycle and is reported like any other
    assert find_cycle(graph) is None, " -> ".join(find_cycle(graph) or [])


def test_cycle_finder_finds_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_installed_top_level_names_are_only_feeddrive():
    dist = importlib.metadata.distribution("feeddrive-monitor")
    top = {p.parts[0] for p in dist.files or [] if p.suffix == ".py" and not p.parts[0].endswith((".dist-info", ".pth"))}
    top_level_txt = dist.read_text("top_level.txt")
    declared = set(top_level_txt.split()) if top_level_txt else top
    assert declared <= {"feeddrive"}, declared
    for generic in PACKAGES:
        spec = importlib.util.find_spec(generic)
        # `tests/<pkg>` folders are not packages; nothing of ours answers to the bare name
        assert spec is None or "feeddrive" not in str(spec.origin or ""), generic


def test_console_script_points_into_the_namespace():
    eps = importlib.metadata.distribution("feeddrive-monitor").entry_points
    (cosim,) = [e for e in eps if e.name == "cosim"]
    assert cosim.value == "feeddrive.cosim.cli:main"


def test_version_and_python_m():
    out = subprocess.run([sys.executable, "-m", "feeddrive.cosim", "--version"], capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.strip() == f"cosim {feeddrive.cosim.__version__}"
    assert feeddrive.cosim.__version__ == importlib.metadata.version("feeddrive-monitor")


def test_no_module_over_about_500_lines():
    long = {m: n for m in all_modules() if (n := len(source_of(m).read_text().splitlines())) > 520}
    assert not long, long


def test_old_top_level_class_name_gets_a_one_line_hint(tmp_path):
    scenario = tmp_path / "old.yaml"
    scenario.write_text("name: t\nstep: 1.0e-4\nnc: {program: [{dwell: {time: 0.1}}]}\n"
                        "monitor: {class: 'cosim.monitor:Monitor'}\n")
    out = subprocess.run([sys.executable, "-m", "feeddrive.cosim", "run", str(scenario), "--out", str(tmp_path / "o")],
                         capture_output=True, text=True, cwd=tmp_path)  # not the repo root, whose folders import bare
    assert out.returncode == 2
    (line,) = out.stderr.strip().splitlines()
    assert f"{scenario}:4: monitor.class:" in line and "write 'feeddrive.cosim.monitor' instead" in line


def test_a_users_own_models_package_is_not_mistaken_for_ours(tmp_path, monkeypatch):
    """The point of the namespace: a user's top-level `models` package is theirs, and loads."""
    from feeddrive.cosim.component import load_component_class

    pkg = tmp_path / "models"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "mine.py").write_text("from feeddrive.cosim.component import Component\n"
                                 "class Mine(Component):\n    pass\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    assert load_component_class("models.mine:Mine").__name__ == "Mine"


def test_every_package_folder_is_listed_in_pyproject():
    """A package folder missing from pyproject's `packages` is absent from a wheel (non-editable install)."""
    import tomllib

    root = Path(__file__).resolve().parents[2]
    listed = set(tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    folders = {"feeddrive." + ".".join(p.parent.relative_to(root).parts)
               for top in ("models", "fmu_build", "estimator", "cosim") for p in (root / top).rglob("__init__.py")}
    assert folders - listed == set(), f"add to pyproject.toml [tool.setuptools] packages: {sorted(folders - listed)}"
