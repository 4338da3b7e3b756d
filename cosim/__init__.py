"""Co-simulation of a feed drive: scenario, master, components, monitor, recorder, campaigns, CLI."""
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("feeddrive-monitor")
except PackageNotFoundError:  # a source tree that was never installed
    __version__ = "0+unknown"
