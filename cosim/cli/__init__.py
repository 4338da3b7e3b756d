"""The ``cosim`` command line: a thin dispatcher to one module per subcommand in this package.

Each subcommand lives in its own module, which exposes

* ``add_arguments(parser: argparse.ArgumentParser) -> None``
* ``main(args: argparse.Namespace) -> int`` (the exit status)

Exit status: 0 success, 2 bad input (one line on stderr, no traceback), 1 simulation or build
failure (one line on stderr).
"""
from __future__ import annotations

import argparse
import importlib
import sys

from feeddrive.cosim import __version__
from feeddrive.cosim.errors import InputError, SimulationError

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


def _input_errors() -> tuple[type[BaseException], ...]:
    from feeddrive.estimator.errors import EstimatorInputError, NotEnoughExcitation

    return (InputError, EstimatorInputError, NotEnoughExcitation, FileNotFoundError, FileExistsError,
            IsADirectoryError, NotADirectoryError, PermissionError)


def _failure_errors() -> tuple[type[BaseException], ...]:
    from feeddrive.fmu_build.errors import FMUBuildError

    return (SimulationError, FMUBuildError)


def build_parser() -> tuple[argparse.ArgumentParser, dict[str, object]]:
    parser = argparse.ArgumentParser(prog="cosim", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"cosim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    modules: dict[str, object] = {}
    for name, (module_name, help_text) in COMMANDS.items():
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name != module_name:
                raise
            continue  # subcommand not built yet
        p = sub.add_parser(name, help=help_text, description=help_text)
        module.add_arguments(p)
        modules[name] = module
    return parser, modules


def main(argv: list[str] | None = None) -> int:
    parser, modules = build_parser()
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
    except KeyboardInterrupt:
        print(f"cosim {args.command}: interrupted", file=sys.stderr)
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
