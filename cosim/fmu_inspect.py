"""Reading a plant FMU's archive without running it: FMI version, model description, content hash.

Each answer is kept per process, keyed by the file's identity (``_identity``: path, size, mtime, inode), so
that a campaign's runs, which resolve the same FMU hundreds of times (its check of every run, each worker's
resolution), read and hash it once per process; a file rebuilt or replaced since is read again (issue 26).
Failures are not kept. The model description is shared by the callers: treat it as read-only.
"""
from __future__ import annotations

import hashlib
import math
import os
import stat
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

#: answers by (question, ``_identity``); a few FMUs per process, at most ``CACHE_MAX`` entries
_CACHE: dict[tuple, Any] = {}
CACHE_MAX = 256


def _identity(path: Path | str) -> tuple | None:
    """(absolute path, size, mtime [ns], inode, ctime [ns]) of a regular file, or None for anything else: a
    folder (an extracted FMU, whose files may change under an unchanged folder) or a path that cannot be read
    (the question is then asked of the file itself, which raises the error the caller reports)."""
    try:
        st = os.stat(path)
    except (OSError, TypeError, ValueError):
        return None
    if not stat.S_ISREG(st.st_mode):
        return None
    return os.path.abspath(path), st.st_size, st.st_mtime_ns, st.st_ino, st.st_ctime_ns


def _cached(question: str, path: Path | str, answer: Callable[[], Any]) -> Any:
    """``answer()``, computed once per process for this file as it is now (see the module's docstring)."""
    identity = _identity(path)
    if identity is None:
        return answer()
    key = (question, identity)
    if key not in _CACHE:
        value = answer()  # raises for a bad file: nothing kept
        if len(_CACHE) >= CACHE_MAX:
            _CACHE.pop(next(iter(_CACHE)))  # the oldest (dicts keep their insertion order)
        _CACHE[key] = value
    return _CACHE[key]


def fmi_version(path: Path) -> str:
    """The ``fmiVersion`` attribute of an FMU's modelDescription.xml (raises ValueError if unreadable)."""
    return _cached("version", path, lambda: _fmi_version(path))


def _fmi_version(path: Path) -> str:
    try:
        with zipfile.ZipFile(path) as z, z.open("modelDescription.xml") as f:
            return ElementTree.parse(f).getroot().get("fmiVersion", "")
    except (zipfile.BadZipFile, KeyError, ElementTree.ParseError) as exc:
        raise ValueError(f"not an FMU (a zip file with a modelDescription.xml): {exc}") from None


def model_description(path: Path) -> Any:
    """fmpy's validated model description of an FMU.

    Raises
    ------
    ValueError
        The modelDescription.xml fails fmpy's validation; the message gives its first problem.
    """
    return _cached("description", path, lambda: _model_description(path))


def _model_description(path: Path) -> Any:
    from fmpy import read_model_description
    from fmpy.model_description import ValidationError as FMIValidationError

    try:
        return with_intermediate_update(read_model_description(str(path)), path)
    except FMIValidationError as exc:
        raise ValueError(_invalid(exc.problems)) from None
    except Exception as exc:  # fmpy raises a bare Exception for other malformed content (types, variabilities)
        md = _with_bare_display_units(path)
        if md is not None:
            return with_intermediate_update(md, path)
        raise ValueError(f"invalid modelDescription.xml: {' '.join(str(exc).split())}") from None


def _invalid(problems: list) -> str:
    """The first of fmpy's validation problems, as one line."""
    problems = [" ".join(str(p).split()) for p in problems] or ["(no detail)"]
    more = f" (and {len(problems) - 1} more problem{'s' * (len(problems) > 2)})" if len(problems) > 1 else ""
    return f"invalid modelDescription.xml: {problems[0]}{more}"


def _with_bare_display_units(path: Path) -> Any:
    """The model description of an FMU with variables that declare a ``displayUnit`` but no ``unit``, or None.

    fmpy 0.3's validator fails on such a variable with ``KeyError: None`` (it looks the display unit up under
    the missing unit), which read "invalid modelDescription.xml: None". Their values' unit is undeclared, as
    for a variable with no unit at all: the master reads them only with the unit stated in the map
    (``cosim.unit_map.convert`` refuses to take the display unit on trust). The other checks still run: with
    those display units set aside, fmpy's validation must pass."""
    from fmpy import read_model_description, validation

    try:
        md = read_model_description(str(path), validate=False)
    except Exception:  # noqa: BLE001 - the caller reports fmpy's first error
        return None
    bare = [v for v in md.modelVariables if v.displayUnit and not (v.unit or getattr(v.declaredType, "unit", None))]
    if not bare:
        return None
    shown = [v.displayUnit for v in bare]
    for v in bare:
        v.displayUnit = None
    try:
        problems = validation.validate_model_description(md)
    except Exception:  # noqa: BLE001 - another defect fmpy's validator trips on
        return None
    if problems:
        raise ValueError(_invalid(problems))
    for v, unit in zip(bare, shown):
        v.displayUnit = unit
    return md


#: the variable types of FMI 2.0 and 3.0 that carry the master's signals (floats)
REAL_TYPES = ("Real", "Float64")


def interpolates_inputs(md: Any) -> bool:
    """Whether a Co-Simulation FMU can follow a first-order hold of its inputs.

    FMI 2.0: ``canInterpolateInputs`` (the master passes the slopes with fmi2SetRealInputDerivatives).
    FMI 3.0 has no input derivatives: ``providesIntermediateUpdate`` and every continuous Float64 input
    declaring ``intermediateUpdate`` (the master sets the ramped values when the FMU asks, inside fmi3DoStep).
    """
    cs = md.coSimulation
    if cs is None:
        return False
    if not md.fmiVersion.startswith("3"):
        return bool(cs.canInterpolateInputs)
    inputs = [v for v in md.modelVariables if v.causality == "input" and v.type == "Float64"
              and v.variability == "continuous"]
    return bool(cs.providesIntermediateUpdate) and bool(inputs) and all(v.intermediateUpdate for v in inputs)


def with_intermediate_update(md: Any, path: Path | str) -> Any:
    """``md`` with each FMI 3.0 variable's ``intermediateUpdate`` read from ``path``'s modelDescription.xml.

    fmpy 0.3 reads ``providesIntermediateUpdate`` but leaves every variable's ``intermediateUpdate`` False,
    which would hide an FMU's intermediate update from :func:`interpolates_inputs`. ``path``: the .fmu or
    the folder it was extracted to.
    """
    if not str(md.fmiVersion).startswith("3"):
        return md
    path = Path(path)
    if path.is_dir():
        root = ElementTree.parse(path / "modelDescription.xml").getroot()
    else:
        with zipfile.ZipFile(path) as z, z.open("modelDescription.xml") as f:
            root = ElementTree.parse(f).getroot()
    flagged = {e.get("name") for e in root.iterfind("ModelVariables/*") if e.get("intermediateUpdate") == "true"}
    for v in md.modelVariables:
        v.intermediateUpdate = v.name in flagged
    return md


def input_handling(md: Any) -> list[str]:
    """How the master feeds the FMU's continuous Real inputs between communication points, one line per
    interface (printed by ``cosim info``): the first-order hold where the FMU allows it, else the hold."""
    inputs = [v.name for v in md.modelVariables if v.causality == "input" and v.type in REAL_TYPES
              and v.variability == "continuous"]
    if not inputs:
        return ["inputs: no continuous Real inputs (nothing to hold between communication points)"]
    out, fmi3 = [], str(md.fmiVersion).startswith("3")
    held = ("held over each communication step h (input_hold zoh): a ramp of slope s is seen s h / 2 low "
            "on average over the step")
    if md.coSimulation is not None and interpolates_inputs(md):
        how = ("the master sets u_n + slope (t - t_n) when the FMU asks inside fmi3DoStep (intermediate update "
               f"of {', '.join(inputs)})" if fmi3 else
               "the master passes the slopes with fmi2SetRealInputDerivatives (canInterpolateInputs)")
        out.append(f"Co-Simulation inputs: first-order hold (input_hold foh, the default): {how}")
    elif md.coSimulation is not None:
        flagged = [v.name for v in md.modelVariables if getattr(v, "intermediateUpdate", False)]
        why = ("no canInterpolateInputs" if not fmi3 else "FMI 3.0 has no input derivatives and the FMU provides "
               "no intermediate update" if not md.coSimulation.providesIntermediateUpdate else
               f"intermediate update, but not of every input ({', '.join(n for n in inputs if n not in flagged)})")
        out.append(f"Co-Simulation inputs: {held} ({why})")
    if md.modelExchange is not None:
        out.append("Model Exchange inputs: first-order hold by the master inside CVode (input_hold foh, the default)")
    return out


def runnable(md: Any, interface: str, name: str) -> tuple[str, str] | None:
    """Why the master cannot run an FMU through ``interface`` (``cs`` / ``me``): (key, one-line reason), or None.

    The master runs Co-Simulation and Model Exchange without clocks: an FMI 3.0 FMU with only Scheduled
    Execution, or with Clock variables (their model partitions would never be activated), is refused.
    """
    if md.coSimulation is None and md.modelExchange is None:
        return ("fmu", f"{name} supports only Scheduled Execution (FMI 3.0 clocks); the master runs "
                       "Co-Simulation and Model Exchange FMUs")
    clocks = [v.name for v in md.modelVariables if v.type == "Clock"]
    if clocks:
        return ("fmu", f"{name} has clocks ({', '.join(clocks)}); the master runs FMUs without clocked partitions")
    if (md.coSimulation if interface == "cs" else md.modelExchange) is None:
        kind = {"cs": "Co-Simulation", "me": "Model Exchange"}[interface]
        return ("interface", f"{name} does not support {kind}; expected interface {'me' if interface == 'cs' else 'cs'}")
    return None


def fixed_step_problem(md: Any, interface: str, h: float, name: str) -> str | None:
    """Why an FMI 3.0 Co-Simulation FMU that declares a ``fixedInternalStepSize`` cannot be stepped every ``h``
    seconds, or None: ``h`` must be a whole number of its internal steps. Otherwise its outputs change only at
    its own steps (the Reference-FMUs' framework takes no partial step: Dahlquist, 0.1 s, stepped every 0.03 s
    showed x(0.1) at t = 0.12) and every sample lags by up to one of them, silently."""
    fixed = getattr(md.coSimulation, "fixedInternalStepSize", None) if interface == "cs" and md.coSimulation else None
    if not fixed or float(fixed) <= 0:
        return None
    ratio = h / float(fixed)
    if round(ratio) >= 1 and math.isclose(ratio, round(ratio), rel_tol=1e-9):
        return None
    return (f"{name} steps with a fixed internal step of {float(fixed):g} s (fixedInternalStepSize) and its "
            f"communication step would be {h:g} s, not a multiple of it: its outputs would lag up to {float(fixed):g} s; "
            f"expected a communication step that is a multiple of {float(fixed):g} s, or interface: me")


def sha256(path: Path) -> str:
    """The hex SHA-256 of a file's bytes."""
    return _cached("sha256", path, lambda: _sha256(path))


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def check_archive(path: Path, model_identifier: str | None = None) -> None:
    """Refuse an FMU archive that is unsafe to extract or cannot run on this platform.

    Raises
    ------
    ValueError
        An entry with an absolute path or a ``..`` component (it would be written outside the
        extraction folder); no ``binaries/<platform>/<model_identifier><ext>`` for this platform
        (checked when ``model_identifier`` is given). The message says what was expected.
    """
    _cached(f"archive {model_identifier}", path, lambda: _check_archive(path, model_identifier))


def _check_archive(path: Path, model_identifier: str | None) -> bool:
    import fmpy

    try:
        with zipfile.ZipFile(path) as z:
            names = z.namelist()
    except (zipfile.BadZipFile, OSError) as exc:
        raise ValueError(f"not an FMU (a zip file with a modelDescription.xml): {exc}") from None
    for name in names:
        parts = name.replace("\\", "/").split("/")
        if name.startswith(("/", "\\")) or ".." in parts or (parts and parts[0].endswith(":")):
            raise ValueError(f"archive entry {name!r} points outside the FMU; expected relative paths only")
    if model_identifier is not None:
        platform = fmpy.platform_tuple if fmi_version(path).startswith("3") else fmpy.platform  # x86_64-linux
        binary = f"binaries/{platform}/{model_identifier}{fmpy.sharedLibraryExtension}"
        if binary not in names:
            have = sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") >= 2})
            raise ValueError(f"no binary for this platform: expected {binary} in the FMU"
                             f"{' (it has binaries for ' + ', '.join(have) + ')' if have else ' (it has no binaries)'}")
    return True
