"""Errors raised by the pentapod testbed; each subclasses the matching built-in."""


class ConfigError(ValueError):
    """A parameter file or parameter value is invalid (the message names it)."""


class UnreachablePoseError(ValueError):
    """A platform pose violates a machine limit (strut stroke, joint angle, ...)."""


class PortError(KeyError):
    """An unknown or ill-defined input/output port name."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ''


class ModelFileError(ValueError):
    """A saved model or modal data file is unreadable or inconsistent."""


class BagError(ValueError):
    """A recording is corrupt, truncated or lacks what an analysis needs."""


class RunError(RuntimeError):
    """A testbed run had to stop (silent force source, unstable loop, ...)."""


class ModalError(ArithmeticError):
    """An eigenvalue solve failed or its result contradicts the Sturm count."""
