"""Model -> C sources and modelDescription.xml: everything model-specific of the FMU.

The FMU has one flat array of reals; a variable's value reference is its index in it:

=========================  ===========================================================
block                      contents (feed drive)
=========================  ===========================================================
states                     ``i, w, theta`` (outputs), ``xi_w, xi_i, w_rf`` (local)
inputs                     ``w_ref, Tl, u_in``
parameters                 the model's physical then design parameters, then ``cs_substep``
calculated outputs         the model's outputs that are not states (``i_ref, u_ref, u, x``)
derivatives                ``der(<state>)`` in state order
=========================  ===========================================================

The C wrapper reads this layout from the generated header ``fmu_model.h``, so a second model needs no
C changes. It is one version-independent core (``fmu_build/c/fmu_core.c``: values, checks, RK4
stepping, FMU states, logging) under a thin API layer, ``fmi2_wrapper.c`` or ``fmi3_wrapper.c``
(``generate(..., fmi_version=3)``); both versions of a model compile the same generated code and core,
so they compute the same numbers. FMI 3.0 adds the independent variable ``time`` at value reference
``NR`` (read-only) and has no input derivatives (inputs held over each communication step); its
modelDescription.xml is written by ``model_description.xml3``.

Integration (Co-Simulation). ``fmi2DoStep`` splits a communication step h into
``n = ceil(h / cs_substep - 1e-9)`` equal substeps of the classical explicit RK4 method.
``cs_substep`` is at least ``MIN_CS_SUBSTEP`` = 1 ns (the FMU's ``min``; below that the substep count
of any useful step overflows) and a step needing more than ``MAX_SUBSTEPS`` = 1e7 substeps (~1 s of
CPU) is refused with fmi2Error and a log message naming h, cs_substep and the cap, rather than hang
the master or overflow the count: split such a step or raise ``cs_substep``. The fastest
modes of the feed drive are the smoothed dry friction near w = 0, ``Cd / (Jt w_eps)`` ~ 1.2e4 1/s,
and the 500 Hz current loop, ``2 pi 500`` ~ 3.1e3 1/s (the electrical pole R/L is 150 1/s). RK4 is
stable for real eigenvalues with ``|lambda dt| < 2.78``: at the default ``cs_substep = 1e-5`` s the
stiffest mode has ``|lambda dt|`` = 0.12, a 23-fold margin, and the local error per substep,
~ ``(lambda dt)^5 / 120``, is below 2e-7 of the state even there and ~1e-13 for the loops. The
system is only mildly stiff, so an implicit solver would cost a Newton iteration per substep for no
gain; RK4 also keeps the step a fixed sequence of generated expressions (deterministic, bit
reproducible for fmi2GetFMUstate round trips). A larger model (smaller ``w_eps``, stiffer loops)
needs a smaller ``cs_substep``, which is why it is an FMU parameter rather than a constant.

Input interpolation (Co-Simulation, ``canInterpolateInputs="true"``). A master may give each
continuous input a first time derivative with ``fmi2SetRealInputDerivatives`` (order 1 only). As
FMI 2.0 (section 4.2.1) says, inputs and their derivatives are set with respect to the beginning of a
communication step: ``fmi2DoStep(tc, h)`` integrates with ``u(t) = u + du (t - tc)``, evaluated at
every RK4 stage time, where ``u`` is the input's value and ``du`` its derivative as last set. Like
values, a derivative stays set until the next ``fmi2SetRealInputDerivatives`` on that input: a master
interpolating linearly sets value and derivative before every step; ``fmi2SetReal`` leaves the
derivative alone, and derivatives start at 0 (instantiation, ``fmi2Reset``), so a master that never
sets one gets held inputs (zero-order hold), bit-identical to an FMU without interpolation.
Derivatives are part of the FMU state (``fmi2GetFMUstate``). Model Exchange has none (the function
returns fmi2Error there): its inputs are whatever the master sets at each time.

FMI contract (details in the wrapper's header comment). The wrapper enforces the FMI 2.0 state
machines of both interfaces: a call in a mode where the standard does not allow it, or on the other
interface type, returns fmi2Error with a log message naming the function and the mode and changes
nothing; only ``fmi2Reset`` leaves the terminated state. Calculated outputs and derivatives that
evaluate to non-finite numbers (finite but huge inputs) are fmi2Error, not values. Serialised FMU
states start with a header (magic, GUID, size, interface type) that is checked together with every
value; restoring a state restores values, input derivatives and time but keeps the instance's mode,
and after initialisation refuses a state with other fixed parameters.
"""
from __future__ import annotations

import hashlib
import math
import tempfile
import uuid
from dataclasses import dataclass
from pathlib import Path

import casadi as ca

from feeddrive.fmu_build.errors import FMUBuildInputError
from feeddrive.fmu_build.model_description import GUID_PLACEHOLDER, FMUVariable, check_fmi_version, xml2, xml3
from feeddrive.models import Model

#: Default RK4 substep of the Co-Simulation interface [s]; see the module docstring.
DEFAULT_CS_SUBSTEP = 1e-5
#: Smallest allowed ``cs_substep`` [s] (the FMU variable's ``min``).
MIN_CS_SUBSTEP = 1e-9
#: Most RK4 substeps one ``fmi2DoStep`` may take; a longer step is refused with fmi2Error.
MAX_SUBSTEPS = 10_000_000

WRAPPER_SOURCE = Path(__file__).parent / "c" / "fmi2_wrapper.c"
#: The FMI 3.0 API layer over the same core.
WRAPPER3_SOURCE = Path(__file__).parent / "c" / "fmi3_wrapper.c"
#: The version-independent core both API layers share (state, checks, RK4 stepping, FMU states, logging).
CORE_SOURCES = (Path(__file__).parent / "c" / "fmu_core.h", Path(__file__).parent / "c" / "fmu_core.c")


@dataclass(frozen=True)
class Sources:
    """Everything the FMU is built from: generated texts and the content hash.

    Attributes
    ----------
    model_name : str
        Model identifier: shared-library name and prefix of every CasADi function.
    files : dict[str, str]
        File name -> text, to be compiled or packed (C sources, headers, ``modelDescription.xml``).
    variables : tuple[FMUVariable, ...]
        The FMU's variables in value-reference order.
    digest : str
        SHA-256 of all texts (before the GUID is inserted); the GUID derives from it.
    """

    model_name: str
    files: dict[str, str]
    variables: tuple[FMUVariable, ...]
    digest: str

    @property
    def guid(self) -> str:
        return _guid(self.digest)


def _guid(digest: str) -> str:
    return "{" + str(uuid.UUID(digest[:32])) + "}"


def fmu_variables(model: Model, cs_substep: float = DEFAULT_CS_SUBSTEP) -> list[FMUVariable]:
    """The FMU's variables, in value-reference order (see the module docstring for the layout).

    Parameters
    ----------
    model : Model
        The model to wrap.
    cs_substep : float
        Default of the fixed parameter ``cs_substep`` [s], the Co-Simulation RK4 substep.

    Raises
    ------
    FMUBuildInputError
        ``cs_substep`` is not a finite number of seconds >= ``MIN_CS_SUBSTEP``.
    """
    if not (cs_substep >= MIN_CS_SUBSTEP and math.isfinite(cs_substep)):
        raise FMUBuildInputError(f"cs_substep must be a positive number of seconds >= {MIN_CS_SUBSTEP:g}, "
                                 f"got {cs_substep!r}")
    out: list[FMUVariable] = []

    def add(**kw) -> FMUVariable:
        var = FMUVariable(vr=len(out), **kw)
        out.append(var)
        return var

    states = [add(name=v.name, kind="s", unit=v.unit, description=v.description,
                  causality="output" if v.output else "local", variability="continuous",
                  start=v.nominal, lower=v.lower, lower_strict=v.lower_strict, upper=v.upper)
              for v in model.states]
    for v in model.inputs:
        add(name=v.name, kind="i", unit=v.unit, description=v.description, causality="input",
            variability="continuous", start=v.nominal, lower=v.lower, lower_strict=v.lower_strict, upper=v.upper)
    for v in model.parameters:
        add(name=v.name, kind="t" if v.tunable else "f", unit=v.unit, description=v.description,
            causality="parameter", variability="tunable" if v.tunable else "fixed", start=v.nominal,
            lower=v.lower, lower_strict=v.lower_strict, upper=v.upper)
    add(name="cs_substep", kind="f", unit="s", causality="parameter", variability="fixed",
        description=f"Co-Simulation RK4 substep (fmi2DoStep uses ceil(h/cs_substep) equal substeps, "
                    f"at most {MAX_SUBSTEPS:.0e})", start=cs_substep, lower=MIN_CS_SUBSTEP)
    state_names = {v.name for v in model.states}
    for v in model.outputs:
        if v.name not in state_names:
            add(name=v.name, kind="c", unit=v.unit, description=v.description, causality="output",
                variability="continuous")
    for s in states:
        add(name=f"der({s.name})", kind="c", unit=f"{s.unit}/s", description=f"time derivative of {s.name}",
            causality="local", variability="continuous", derivative_of=s.vr)
    return out


def _casadi_functions(model: Model) -> list[ca.Function]:
    """``<name>_rhs(x,u,p)``, ``<name>_out(x,u,p)`` (calculated outputs) and
    ``<name>_rk4(x,u,du,p,dt,tau)``: one RK4 substep from ``tau`` to ``tau + dt`` [s after the
    communication point] with the inputs ``u + du * t`` (first-order hold; ``du = 0``: held inputs)."""
    x, u, p = model.vectors()
    rhs = model.rhs_function(f"{model.name}_rhs")
    state_names = {v.name for v in model.states}
    y = model.output_expressions()
    calculated = [k for k, v in enumerate(model.outputs) if v.name not in state_names]
    out = ca.Function(f"{model.name}_out", [x, u, p], [y[calculated]], ["x", "u", "p"], ["y"])
    du = ca.SX.sym("du", u.numel())
    dt, tau = ca.SX.sym("dt"), ca.SX.sym("tau")
    k1 = rhs(x, u + du * tau, p)
    k2 = rhs(x + dt / 2 * k1, u + du * (tau + dt / 2), p)
    k3 = rhs(x + dt / 2 * k2, u + du * (tau + dt / 2), p)
    k4 = rhs(x + dt * k3, u + du * (tau + dt), p)
    rk4 = ca.Function(f"{model.name}_rk4", [x, u, du, p, dt, tau], [x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)],
                      ["x", "u", "du", "p", "dt", "tau"], ["x_next"])
    return [rhs, out, rk4]


def _c_double(value: float | None, missing: str) -> str:
    if value is None:
        return missing
    if math.isinf(value):
        return "INFINITY" if value > 0 else "-INFINITY"
    return repr(float(value))


def _model_header(model: Model, variables: list[FMUVariable], casadi_header: str) -> str:
    def count(kind: str) -> int:
        return sum(v.kind == kind for v in variables)

    nx, nu = count("s"), count("i")
    npar = count("t") + count("f")
    ny = count("c") - nx

    def table(ctype: str, name: str, cells: list[str]) -> str:
        return f"static const {ctype} {name}[NR] = {{{', '.join(cells)}}};"

    substep = next(v.vr for v in variables if v.name == "cs_substep")
    lines = [
        f"/* Generated by fmu_build.codegen for model {model.name}. Do not edit. */",
        "#include <math.h>",
        f'#include "{casadi_header}"',
        f'#define MODEL_GUID "{GUID_PLACEHOLDER}"',
        f"#define NX {nx}", f"#define NU {nu}", f"#define NP {npar}", f"#define NY {ny}",
        "#define NR (2 * NX + NU + NP + NY)",
        "#define VR_X 0", "#define VR_U NX", "#define VR_P (VR_U + NU)", "#define VR_Y (VR_P + NP)",
        "#define VR_DX (VR_Y + NY)", f"#define VR_CS_SUBSTEP {substep}", f"#define MAX_SUBSTEPS {MAX_SUBSTEPS}",
    ]
    for role in ("rhs", "out", "rk4"):
        macro = "STEP" if role == "rk4" else role.upper()
        lines += [f"#define MODEL_{macro} {model.name}_{role}", f"#define MODEL_{macro}_WORK {model.name}_{role}_work"]
    lines += [
        table("char *const", "VR_NAME", [f'"{v.name}"' for v in variables]),
        table("char", "VR_KIND", [f"'{v.kind}'" for v in variables]),
        table("double", "VR_START", [_c_double(v.start, "NAN") for v in variables]),
        table("double", "VR_MIN", [_c_double(v.lower, "-INFINITY") for v in variables]),
        table("char", "VR_MIN_STRICT", ["1" if v.lower_strict else "0" for v in variables]),
        table("double", "VR_MAX", [_c_double(v.upper, "INFINITY") for v in variables]),
    ]
    return "\n".join(lines) + "\n"


def generate(model: Model, cs_substep: float = DEFAULT_CS_SUBSTEP, fmi_version: int = 2) -> Sources:
    """Generate the C sources and modelDescription.xml of ``model``'s FMU.

    Parameters
    ----------
    model : Model
        Any ``models.Model``; its name becomes the model identifier.
    cs_substep : float
        Default Co-Simulation RK4 substep [s].
    fmi_version : {2, 3}
        FMI version of the API layer and modelDescription.xml; the generated model code and the
        core are the same for both.

    Returns
    -------
    Sources
        Texts to compile and pack, with their content hash and the derived GUID filled in.
    """
    check_fmi_version(fmi_version)
    variables = fmu_variables(model, cs_substep)
    stem = f"{model.name}_casadi"
    cg = ca.CodeGenerator(f"{stem}.c", {"with_header": True})
    for f in _casadi_functions(model):
        cg.add(f)
    with tempfile.TemporaryDirectory() as tmp:
        cg.generate(tmp + "/")
        files = {name: (Path(tmp) / name).read_text() for name in (f"{stem}.c", f"{stem}.h")}
    files["fmu_model.h"] = _model_header(model, variables, f"{stem}.h")
    for core in CORE_SOURCES:
        files[core.name] = core.read_text()
    if fmi_version == 2:
        files["fmi2_wrapper.c"] = WRAPPER_SOURCE.read_text()
        files["modelDescription.xml"] = xml2(model, variables)
    else:
        files["fmi3_wrapper.c"] = WRAPPER3_SOURCE.read_text()
        files["modelDescription.xml"] = xml3(model, variables)
    digest = hashlib.sha256("\0".join(f"{k}\0{files[k]}" for k in sorted(files)).encode()).hexdigest()
    guid = _guid(digest)
    files = {name: text.replace(GUID_PLACEHOLDER, guid) for name, text in files.items()}
    return Sources(model.name, files, tuple(variables), digest)
