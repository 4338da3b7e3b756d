"""The ``cosim`` command line: a thin dispatcher to one module per subcommand in this package.

Each subcommand lives in its own module, which exposes

* ``add_arguments(parser: argparse.ArgumentParser) -> None``
* ``main(args: argparse.Namespace) -> int`` (the exit status)

Only the chosen subcommand's module is imported (and it imports numpy, scipy, fmpy... inside its
``main``), so ``cosim --help`` and ``cosim --version`` answer at once.

Exit status: 0 success, 2 bad input (one line on stderr, no traceback), 1 simulation or build
failure (one line on stderr).
"""
from __future__ import annotations

import argparse
import gc
import importlib
import os
import sys

#: one BLAS / OpenMP thread per process unless the environment says otherwise, set before numpy loads its BLAS:
#: the work is many small matrices, and OpenBLAS's threads spin while they wait for one another, so any other
#: busy process (a campaign's other worker, a run's figures drawn beside it, the rest of the machine) made them
#: slower than one: 2 campaign workers were 1.13 times one (1.9 with one thread each) and the serial campaign
#: took 1.5 times as long (bench_campaign without OPENBLAS_NUM_THREADS, issue 26). Set the variable to use more.
BLAS_THREADS = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
for _name, _value in BLAS_THREADS.items():
    os.environ.setdefault(_name, _value)

from feeddrive.cosim import __version__  # noqa: E402 - after the threads are set (it imports nothing numerical)
from feeddrive.cosim.errors import InputError, SimulationError  # noqa: E402

#: subcommand -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "run": ("feeddrive.cosim.cli.run", "run a co-simulation scenario (plant FMU + NC + sensors + monitor)"),
    "build-fmu": ("feeddrive.cosim.cli.build", "build the built-in feed-drive plant FMU"),
    "info": ("feeddrive.cosim.cli.info", "list an FMU's variables (and check a scenario's mapping), or what a recording holds"),
    "estimate": ("feeddrive.cosim.cli.estimate", "estimate R, L, K, Jt, ft, Cd from a recording (CSV, MATLAB, Parquet, text log)"),
    "monitor": ("feeddrive.cosim.cli.monitor", "run the monitor (validation, estimation, diagnosis) on a recording"),
    "history": ("feeddrive.cosim.cli.history", "print and plot the parameter history of an axis"),
    "campaign": ("feeddrive.cosim.cli.campaign", "run a Monte Carlo / sweep campaign of scenarios"),
    "design": ("feeddrive.cosim.cli.design", "choose the rapid-move acceleration that minimises parameter variance"),
    "export-fmu": ("feeddrive.cosim.cli.export_fmu", "build an FMU of the scenario's NC, sensors or monitor (pythonfmu)"),
    "export-system": ("feeddrive.cosim.cli.export_system",
                      "write the scenario as an OSP system (FMUs, OspSystemStructure.xml, events, SSP)"),
}

USAGE = """\
Model-based monitoring of NC machine-tool feed drives: estimate R, L, K, Jt, ft, Cd once per
high-speed motion, validate the redundant measurements, check the model, diagnose drifts, keep
a history per axis.

Three jobs:
  1. co-simulate a feed drive (built-in plant FMU + NC + sensors + monitor):
       cosim run examples/tool_change.yaml
  2. your own plant: a vendor's FMI 2.0 FMU mapped in the scenario:
       cosim info vendor.fmu --map examples/vendor_fmu.yaml
       cosim run examples/vendor_fmu.yaml
  3. recorded data from a real machine (CSV):
       cosim estimate rec.csv --map time=t current=i voltage=u speed=w
       cosim monitor rec.csv --map time=t current=i voltage=u speed=w --axis X
"""

EPILOG = """\
then:
  cosim history --axis X             the axis's stored motions, parameters with 95 % intervals
  cosim history --axis X --plot      their trends (history_X.png)
  cosim COMMAND --help               the options of one command

exit status: 0 success, 2 bad input (one line naming file, key and what was expected),
1 simulation or build failure (one line)
"""


def _input_errors() -> tuple[type[BaseException], ...]:
    from feeddrive.estimator.errors import EstimatorInputError, NotEnoughExcitation

    return (InputError, EstimatorInputError, NotEnoughExcitation, FileNotFoundError, FileExistsError,
            IsADirectoryError, NotADirectoryError, PermissionError)


def _failure_errors() -> tuple[type[BaseException], ...]:
    from feeddrive.fmu_build.errors import FMUBuildError

    return (SimulationError, FMUBuildError)


def chosen_command(argv: list[str]) -> str | None:
    """The subcommand named in ``argv``: its first word that is not an option (the top level has
    only ``-h`` and ``--version``, which take no value)."""
    return next((a for a in argv if not a.startswith("-")), None)


def build_parser(argv: list[str] | None = None) -> tuple[argparse.ArgumentParser, dict[str, object]]:
    """The parser, with the options of the subcommand chosen in ``argv`` only (None: of every one).

    Returns the parser and the imported subcommand modules by name."""
    parser = argparse.ArgumentParser(prog="cosim", description=USAGE, epilog=EPILOG,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"cosim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands")
    chosen = None if argv is None else chosen_command(argv)
    modules: dict[str, object] = {}
    for name, (module_name, help_text) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        if argv is not None and name != chosen:
            continue  # its module is imported only when it is chosen
        module = importlib.import_module(module_name)
        module.add_arguments(p)
        modules[name] = module
    return parser, modules


def main(argv: list[str] | None = None) -> int:
    """Run the command line ``argv`` (None: the program's, ``sys.argv[1:]``); returns the exit status."""
    status = _main(sys.argv[1:] if argv is None else list(argv))
    if argv is None:
        # the program ends now: the objects alive are left out of the interpreter's last garbage collection,
        # which walks each of them (numpy, fmpy, casadi, pydantic...: 0.2 to 0.35 s of a command's wall time) and
        # frees nothing the end of the process does not
        gc.freeze()
    return status


def _main(argv: list[str]) -> int:
    parser, modules = build_parser(argv)
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    try:
        return int(modules[args.command].main(args) or 0)
    except _input_errors() as exc:
        print(f"cosim {args.command}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except _failure_errors() as exc:
        print(f"cosim {args.command}: failed: {_one_line(exc)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:  # a run's says until when and what was kept (cosim/supervise.py)
        print(f"cosim {args.command}: interrupted{' ' + str(exc) if str(exc) else ''}", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into `head` and the like
        sys.stderr.close()
        return 0


def _one_line(exc: BaseException) -> str:
    text = str(exc) or type(exc).__name__
    if isinstance(exc, OSError) and exc.filename and str(exc.filename) not in text:
        text = f"{exc.filename}: {text}"
    return " ".join(text.split())


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
