"""Named errors.  Every error a user can provoke with bad input derives from CablesimError."""


class CablesimError(Exception):
    """Base class of all cablesim errors."""


class ConfigError(CablesimError, ValueError):
    """An impossible configuration value; the message names the field."""

    def __init__(self, field: str, message: str):
        self.field = field
        super().__init__(f"{field}: {message}")


class InputError(CablesimError, ValueError):
    """Bad data handed to a function: wrong shape or dtype, invalid depth, missing intrinsics."""


class PhysicsDivergedError(CablesimError, RuntimeError):
    """The simulation produced NaN/inf or MuJoCo reported an instability."""


class UnreachableError(CablesimError, RuntimeError):
    """A pose the robot cannot reach (IK failure, joint limits, collision)."""


class RecordingError(CablesimError, IOError):
    """A recording on disk is truncated, corrupt or of an unknown version."""


class CalibrationError(CablesimError, ValueError):
    """A calibration file that is missing, unreadable or lacks a valid field (the message names
    the file and the field), or a calibration that could not be computed."""
