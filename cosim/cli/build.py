"""``cosim build-fmu [--out PATH] [--overwrite] [--fmi-version 2|3]``: build the built-in feed-drive plant FMU."""
from __future__ import annotations

import argparse
from pathlib import Path

from feeddrive.cosim.errors import InputError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", type=Path, default=Path("FeedDrive.fmu"),
                        help="FMU file to write (default: ./FeedDrive.fmu)")
    parser.add_argument("--overwrite", action="store_true", help="replace --out if it exists")
    # --force was this command's name for --overwrite: kept working, no longer shown
    parser.add_argument("--force", dest="overwrite", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--fmi-version", type=int, choices=(2, 3), default=2,
                        help="FMI version of the FMU: 2 (default) or 3; the same model code and wrapper core")


def main(args: argparse.Namespace) -> int:
    from feeddrive.fmu_build import build_fmu, fmu_variables
    from feeddrive.models import feed_drive

    out: Path = args.out
    if out.is_dir():
        raise InputError(f"--out {out}: is a directory, expected a .fmu file path")
    if out.exists() and not args.overwrite:
        raise InputError(f"--out {out}: file exists (use --overwrite to replace it)")
    model = feed_drive()
    build_fmu(model, out, fmi_version=args.fmi_version)
    variables = fmu_variables(model)
    count = {c: sum(v.causality == c for v in variables) for c in ("input", "output", "parameter")}
    print(out)
    print(f"{model.name}: FMI {args.fmi_version}.0 Co-Simulation + Model Exchange, {len(model.states)} states, "
          f"{count['input']} inputs, {count['output']} outputs, {count['parameter']} parameters, "
          f"{out.stat().st_size / 1024:.0f} KiB")
    return 0
