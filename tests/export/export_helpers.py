"""Helpers of the export tests (imported by name: pytest puts this folder on sys.path)."""
from __future__ import annotations

from pathlib import Path

from feeddrive.cosim.scenario import scenario_from_dict
from feeddrive.cosim.yaml_source import read_yaml

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
HERE = Path(__file__).resolve().parent


def scenario(path: Path, **monitor: object):
    """A scenario file with its monitor section updated by ``monitor`` (e.g. a history in tmp)."""
    data, lines = read_yaml(path)
    data["monitor"] = dict(data.get("monitor") or {}) | monitor
    return scenario_from_dict(data, source=str(path), base_dir=path.parent, lines=lines)
