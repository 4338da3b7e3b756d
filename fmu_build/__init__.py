"""Model -> FMI 2.0 FMU (Co-Simulation and Model Exchange) -> cached ``FeedDrive.fmu``.

``builtin_fmu()`` returns the cached feed-drive plant FMU, building it on first use;
``build_fmu(model, out)`` builds an FMU for any ``models.Model``. The FMU contains a native
shared library only (CasADi-generated C + one generic FMI 2.0 wrapper), no Python.
"""
from feeddrive.fmu_build.build import build_fmu, builtin_fmu
from feeddrive.fmu_build.codegen import DEFAULT_CS_SUBSTEP, MAX_SUBSTEPS, MIN_CS_SUBSTEP, FMUVariable, fmu_variables
from feeddrive.fmu_build.errors import CompilerError, FMUBuildError, FMUBuildInputError

__all__ = ["DEFAULT_CS_SUBSTEP", "MAX_SUBSTEPS", "MIN_CS_SUBSTEP", "CompilerError", "FMUBuildError",
           "FMUBuildInputError", "FMUVariable", "build_fmu", "builtin_fmu", "fmu_variables"]
