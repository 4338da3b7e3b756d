"""Model -> FMI 2.0 or FMI 3.0 FMU (Co-Simulation and Model Exchange) -> cached ``FeedDrive.fmu``.

``builtin_fmu()`` returns the cached feed-drive plant FMU, building it on first use;
``build_fmu(model, out)`` builds an FMU for any ``models.Model`` (``fmi_version=3`` for FMI 3.0).
The FMU contains a native shared library only (CasADi-generated C + one generic wrapper: a
version-independent core and a thin FMI 2.0 or FMI 3.0 API layer), no Python.
"""
from feeddrive.fmu_build.build import build_fmu, builtin_fmu
from feeddrive.fmu_build.codegen import DEFAULT_CS_SUBSTEP, MAX_SUBSTEPS, MIN_CS_SUBSTEP, FMUVariable, fmu_variables
from feeddrive.fmu_build.errors import CompilerError, FMUBuildError, FMUBuildInputError
from feeddrive.fmu_build.model_description import FMI_VERSIONS

__all__ = ["DEFAULT_CS_SUBSTEP", "FMI_VERSIONS", "MAX_SUBSTEPS", "MIN_CS_SUBSTEP", "CompilerError", "FMUBuildError",
           "FMUBuildInputError", "FMUVariable", "build_fmu", "builtin_fmu", "fmu_variables"]
