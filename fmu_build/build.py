"""Compile generated sources with the system C compiler, pack the FMU, and cache the built-in plant."""
from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import shlex
import subprocess
import sys
import tempfile
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import fmpy

from feeddrive.fmu_build.codegen import DEFAULT_CS_SUBSTEP, Sources, generate
from feeddrive.fmu_build.errors import CompilerError, FMUBuildError, FMUBuildInputError
from feeddrive.fmu_build.model_description import check_fmi_version
from feeddrive.models import Model, feed_drive, pmsm_drive

#: Flags for the shared library. Hidden visibility exports only the fmi2 (fmi3) functions.
CFLAGS = ("-O2", "-fPIC", "-shared", "-fvisibility=hidden")
#: The FMI 2.0 and FMI 3.0 standard headers, as shipped with fmpy (BSD 2-clause, license in each header).
FMI_HEADERS = Path(fmpy.__file__).parent / "c-code"


def compiler() -> list[str]:
    """The C compiler command: ``$CC`` (may contain options) or ``cc``."""
    return shlex.split(os.environ.get("CC") or "cc")


def _compile(sources: Sources, workdir: Path) -> Path:
    for name, text in sources.files.items():
        (workdir / name).write_text(text)
    library = workdir / f"{sources.model_name}{fmpy.sharedLibraryExtension}"
    cc = compiler()
    c_files = sorted(name for name in sources.files if name.endswith(".c"))
    command = [*cc, *CFLAGS, f"-I{FMI_HEADERS}", f"-I{workdir}", "-o", str(library), *c_files, "-lm"]
    try:
        done = run_with_progress(command, workdir, f"compiling {sources.model_name}.fmu ({cc[0]})")
    except OSError as exc:
        raise CompilerError(cc[0], command, f"error: cannot run {cc[0]!r}: {exc.strerror}") from None
    if done.returncode != 0:
        output = (done.stderr + done.stdout).strip() or f"error: exited with status {done.returncode}, no output"
        raise CompilerError(cc[0], command, output)
    return library


def run_with_progress(command: list[str], cwd: Path | None, what: str,
                      timeout: float | None = None) -> subprocess.CompletedProcess:
    """``subprocess.run`` with the elapsed time on stderr while it runs (the first build of the plant takes
    10 to 60 s, of a PMSM monitor's rollout 9 s: estimator/compiled.py); only on a terminal and not under CI
    (``$CI``), so logs and pipes stay clean. ``timeout`` [s]: ``subprocess.TimeoutExpired`` after it (the
    process killed), as ``subprocess.run``'s."""
    if not sys.stderr.isatty() or os.environ.get("CI"):
        return subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=timeout)
    from tqdm import tqdm

    with subprocess.Popen(command, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as proc, \
            tqdm(desc=what, bar_format="{desc}: {elapsed}", leave=False) as bar:
        while True:
            try:
                out, err = proc.communicate(timeout=0.5)
                break
            except subprocess.TimeoutExpired:
                if timeout is not None and bar.format_dict["elapsed"] > timeout:
                    proc.kill()
                    proc.communicate()
                    raise subprocess.TimeoutExpired(command, timeout) from None
                bar.refresh()
    return subprocess.CompletedProcess(command, proc.returncode, out, err)


def _pack(sources: Sources, library: Path, out: Path) -> None:
    # FMI 2.0 names the binary folder by platform ("linux64"), FMI 3.0 by platform tuple ("x86_64-linux")
    platform = fmpy.platform_tuple if "fmi3_wrapper.c" in sources.files else fmpy.platform
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("modelDescription.xml", sources.files["modelDescription.xml"])
        z.write(library, f"binaries/{platform}/{library.name}")


def _build(sources: Sources, out: Path) -> Path:
    """Compile and pack into ``out``, atomically (a reader never sees a half-written FMU)."""
    out = Path(os.path.abspath(out))  # the compiler runs in the build directory: no relative paths
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=out.parent, prefix=".fmu_build_") as tmp:
        library = _compile(sources, Path(tmp))
        packed = Path(tmp) / out.name
        _pack(sources, library, packed)
        os.replace(packed, out)
    return out


def build_fmu(model: Model | None = None, out: Path | str | None = None, *,
              cs_substep: float = DEFAULT_CS_SUBSTEP, fmi_version: int = 2) -> Path:
    """Generate, compile and pack an FMI 2.0 or 3.0 FMU (Co-Simulation and Model Exchange).

    Parameters
    ----------
    model : Model or None
        The model; None is the feed drive ``models.feed_drive()``.
    out : path or None
        The ``.fmu`` file to write (replaced if it exists: callers guard user files); None is
        ``<model name>.fmu`` in the working directory.
    cs_substep : float
        Default of the FMU's fixed parameter ``cs_substep`` [s], the Co-Simulation RK4 substep.
    fmi_version : {2, 3}
        FMI version. Both are built from the same generated model code and the same wrapper core,
        and compute bit-identical numbers for the same calls.

    Returns
    -------
    pathlib.Path
        The written FMU.

    Raises
    ------
    CompilerError
        The C compiler (``$CC`` or ``cc``) failed; the message names it and shows its error.
    FMUBuildInputError
        ``fmi_version`` is not 2 or 3, or ``cs_substep`` is not a valid substep.
    """
    model = model or feed_drive()
    return _build(generate(model, cs_substep, fmi_version), Path(out or f"{model.name}.fmu"))


def cache_key(sources: Sources) -> str:
    """Hash of the generated sources, the wrapper, the XML, the compiler command and its flags."""
    text = "\0".join([sources.digest, *compiler(), *CFLAGS])
    return hashlib.sha256(text.encode()).hexdigest()[:20]


#: ``builtin_fmu(motor=...)``: the built-in plants' motors
MOTORS = ("dc", "pmsm")


def _generated(backlash: bool, fmi_version: int = 2, motor: str = "dc") -> tuple[Model, Sources]:
    """The model and its generated sources, generated once per process and input (~60 ms each: every
    scenario load needs the cache key). The memo's key is what they are made of: the model function,
    the variant, the FMI version and the C source files (wrapper and core) with their modification times."""
    from feeddrive.fmu_build import codegen

    check_fmi_version(fmi_version)
    c_files = (Path(codegen.WRAPPER_SOURCE if fmi_version == 2 else codegen.WRAPPER3_SOURCE), *codegen.CORE_SOURCES)
    stamps = tuple((path, path.stat().st_mtime_ns) for path in c_files)
    # the model function is looked up at each call, so the memo sees a replaced function as another model
    return _generate(feed_drive if motor == "dc" else pmsm_drive, backlash, fmi_version, stamps)


@functools.lru_cache(maxsize=8)
def _generate(model_function: Any, backlash: bool, fmi_version: int, c_files: tuple) -> tuple[Model, Sources]:
    model = model_function(backlash=True) if backlash else model_function()
    return model, generate(model, fmi_version=fmi_version)


def builtin_fmu(cache_dir: Path | str | None = None, *, backlash: bool = False, fmi_version: int = 2,
                motor: str = "dc") -> Path:
    """The built-in feed-drive plant FMU, built once and cached.

    The cache is ``<cache_dir>/<hash>/FeedDrive.fmu`` with ``cache_dir`` defaulting to
    ``$FEEDDRIVE_CACHE`` or ``~/.cache/feeddrive``. The hash covers everything the FMU is built
    from, so any change of the model rebuilds it. Safe for parallel processes: each builds in a
    private temporary directory and moves the result in place atomically, and a process that finds another
    building the same FMU (a lock file per cache key, ``<cache_dir>/locks``) waits for it and takes its FMU
    rather than compile it a second time.

    Parameters
    ----------
    cache_dir : path or None
        Cache root directory.
    backlash : bool
        Build the ``FeedDriveBacklash`` variant (``models.feed_drive(backlash=True)``), a plant
        with backlash in the drive chain that the monitor's model does not describe.
    fmi_version : {2, 3}
        FMI version of the FMU. The hash covers it (the API layer and the XML differ), so the two
        versions are cached side by side.
    motor : {"dc", "pmsm"}
        The motor: the paper's DC drive (``models.feed_drive``, model ``FeedDrive``) or the PMSM servo
        drive (``models.pmsm_drive``, model ``PMSMFeedDrive``). Both go through the same generic wrapper.

    Returns
    -------
    pathlib.Path
        Path of the cached ``<model name>.fmu``.
    """
    if motor not in MOTORS:
        raise FMUBuildInputError(f"motor {motor!r}: expected one of {', '.join(MOTORS)}")
    if backlash and motor != "dc":
        raise FMUBuildInputError(f"backlash: only the DC drive has a backlash variant, not motor {motor!r}")
    root = Path(cache_dir or os.environ.get("FEEDDRIVE_CACHE") or Path.home() / ".cache" / "feeddrive")
    # the FMU made from these inputs before, found without generating its sources (~60 ms of every scenario load)
    index = root / "inputs" / _inputs_key(backlash, fmi_version, motor)
    try:
        target = root / index.read_text(encoding="utf-8").strip()
    except OSError:
        target = None
    if target is not None and target.parent.parent == root and target.is_file():
        return target
    model, sources = _generated(backlash, fmi_version, motor)
    target = root / cache_key(sources) / f"{model.name}.fmu"
    try:
        if not target.is_file():
            with build_lock(root, target.parent.name):
                if not target.is_file():  # another process may have built it while this one waited
                    _build(sources, target)
        _write_atomically(index, f"{target.parent.name}/{target.name}\n")
    except OSError as exc:
        raise FMUBuildError(f"cannot write the FMU cache {target.parent}: {exc.strerror}") from exc
    return target


@contextlib.contextmanager
def build_lock(root: Path, key: str) -> Iterator[None]:
    """Hold ``<root>/locks/<key>`` exclusively (``flock``): one build per cache key at a time. The kernel drops the
    lock when its process ends, so a killed build never blocks the next one; the file itself is left (empty)."""
    import fcntl

    folder = root / "locks"
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / key, "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def _inputs_key(backlash: bool, fmi_version: int, motor: str) -> str:
    """Hash of what the built-in FMU is generated and built from: the model function (its name and its module's
    source), the sources of the models and of this package (the code generator, the C wrapper and core), the
    versions of CasADi (its C code generator) and fmpy (the FMI headers), the variant, the FMI version, the compiler
    command and its flags. Equal keys give equal generated sources, so :func:`cache_key` of the sources is looked
    up by it; any edit of these inputs makes another key, and the sources are generated again."""
    from feeddrive.fmu_build import codegen

    function = feed_drive if motor == "dc" else pmsm_drive  # looked up at each call: a replaced one is another model
    digest = hashlib.sha256()
    for text in (function.__module__, function.__qualname__, repr((backlash, fmi_version, motor)),
                 getattr(fmpy, "__version__", "?"), _casadi_version(), *compiler(), *CFLAGS):
        digest.update(text.encode() + b"\0")
    module_file = getattr(sys.modules.get(function.__module__), "__file__", None)
    files = [Path(codegen.WRAPPER_SOURCE), Path(codegen.WRAPPER3_SOURCE), *map(Path, codegen.CORE_SOURCES)]
    files += sorted(Path(__file__).parent.glob("*.py")) + sorted(_models_dir().glob("*.py"))
    files += [Path(module_file)] if module_file else []
    # the files' contents are hashed again only when one of them changed (size, mtime) or another came: reading
    # the 15 files was ~1.3 ms of every scenario resolved, a campaign resolving each of its runs (issue 26)
    stats = (digest.hexdigest(), tuple((str(path), *_stat(path)) for path in files))
    if stats not in _INPUTS_KEYS:
        for path in files:
            digest.update(str(path.name).encode() + b"\0" + path.read_bytes() + b"\0")
        while len(_INPUTS_KEYS) >= 16:  # the oldest first: an edited file's older keys are never asked again
            _INPUTS_KEYS.pop(next(iter(_INPUTS_KEYS)))
        _INPUTS_KEYS[stats] = digest.hexdigest()[:24]
    return _INPUTS_KEYS[stats]


#: ``_inputs_key``'s last answers, by its string inputs' hash and the (path, size, mtime) of every file it hashes
_INPUTS_KEYS: dict[tuple, str] = {}


def _stat(path: Path) -> tuple[int, int]:
    st = path.stat()
    return st.st_size, st.st_mtime_ns


def _models_dir() -> Path:
    """The folder of the models package (feeddrive.models)."""
    return Path(sys.modules[Model.__module__].__file__).parent


def _casadi_version() -> str:
    import casadi

    return casadi.__version__


def _write_atomically(path: Path, text: str) -> None:
    """``path`` written whole or not at all (parallel processes may write the same index)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".index_")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
