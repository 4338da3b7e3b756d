"""The Modelica Reference-FMUs, built once per session from ../shared/third_party/Reference-FMUs with cmake."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest
from reference_models import MODELS, SOURCE


@pytest.fixture(scope="session")
def reference_fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Path]:
    """FMI version -> folder of ``<Model>.fmu``; only the model targets are built (-j2), never the examples."""
    if not (SOURCE / "CMakeLists.txt").is_file():
        pytest.skip(f"Reference-FMUs source not found: {SOURCE.resolve()}")
    cmake = shutil.which("cmake")
    if cmake is None:
        pytest.skip("cmake not found on PATH (needed to build the Reference-FMUs)")
    root = tmp_path_factory.mktemp("reference_fmus")
    out = {}
    for version, models in MODELS.items():
        build = root / f"fmi{version}"
        subprocess.run([cmake, "-S", str(SOURCE), "-B", str(build), f"-DFMI_VERSION={version}"],
                       check=True, capture_output=True)
        subprocess.run([cmake, "--build", str(build), "-j2", "--target", *models], check=True, capture_output=True)
        out[version] = build / "fmus"
    return out
