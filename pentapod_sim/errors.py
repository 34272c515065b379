"""Errors raised by the pentapod testbed; each subclasses the matching built-in."""
from pentapod_sim import exits


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

    #: The exit code of a node that stops with this error (:mod:`pentapod_sim.exits`).
    exit_code = exits.ERROR


class RecordingError(RunError):
    """A recording is incomplete or not trustworthy (missing steps, a foreign writer, ...)."""

    exit_code = exits.RECORDING_FAILED


class PlantStalledError(RunError):
    """No message from the plant for ``plant_stall_timeout`` s of wall time during its run."""

    exit_code = exits.PLANT_STALLED


class ModalError(ArithmeticError):
    """An eigenvalue solve failed or its result contradicts the Sturm count."""
