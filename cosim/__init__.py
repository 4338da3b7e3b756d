"""Co-simulation of a feed drive: scenario, master, components, monitor, recorder, CLI."""
