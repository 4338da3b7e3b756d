"""Errors of the FMU build. They subclass builtins so callers can catch them generically."""


class FMUBuildError(RuntimeError):
    """The FMU could not be generated, compiled or packed."""


class CompilerError(FMUBuildError):
    """The C compiler failed; the message names the compiler and shows its output."""

    def __init__(self, compiler: str, command: list[str], output: str) -> None:
        self.compiler = compiler
        self.command = command
        self.output = output
        first = next((ln for ln in output.splitlines() if "error" in ln.lower()), output.strip()[:300])
        super().__init__(f"C compilation with {compiler!r} failed: {first}")


class FMUBuildInputError(ValueError):
    """Bad input to the FMU build, such as a non-positive ``cs_substep``."""
