"""Named errors.  Every error a user can provoke with bad input derives from CablesimError."""

from cablesim.outcomes import Outcome


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

    outcome = Outcome.DIVERGED


class UnreachableError(CablesimError, RuntimeError):
    """A pose the robot cannot reach (IK failure, joint limits, collision)."""


class RecordingError(CablesimError, IOError):
    """A recording on disk is truncated, corrupt or of an unknown version, or a file of one
    could not be written."""


class DiskFullError(RecordingError):
    """A file could not be written because its file system (or the user's quota) is full
    (``ENOSPC``, ``EDQUOT``); ``path`` is that file.  What was written before it stays
    readable: a recording keeps its finished frames, a dataset or benchmark its finished jobs
    (the unfinished one is redone by the next run)."""

    outcome = "disk_full"

    def __init__(self, path: object, detail: str = ""):
        self.path = str(path)
        self.detail = detail
        super().__init__(
            f"{self.path}: no space left on device" + (f" ({detail})" if detail else "")
        )

    def __reduce__(self) -> tuple[type, tuple[str, str]]:  # across worker processes
        return (type(self), (self.path, self.detail))


class OutputBusyError(CablesimError, RuntimeError):
    """Another process is writing into the same output folder (it holds ``path``, the folder's
    lock file); the message names the holder's process id and command."""

    def __init__(self, path: object, holder: str = ""):
        self.path = str(path)
        self.holder = holder
        super().__init__(
            f"{self.path}: the folder is in use by another cablesim process "
            f"({holder or 'unknown holder'}); wait for it to finish or write somewhere else"
        )

    def __reduce__(self) -> tuple[type, tuple[str, str]]:
        return (type(self), (self.path, self.holder))


class CalibrationError(CablesimError, ValueError):
    """A calibration file that is missing, unreadable or lacks a valid field (the message names
    the file and the field), or a calibration that could not be computed."""


class SceneError(CablesimError, RuntimeError):
    """A simulated scene that cannot give an experiment what it needs.  ``outcome`` is the
    name under which a run records it (``InteractionResult.outcome``)."""

    outcome = Outcome.SCENE_ERROR


class SceneUnsettledError(SceneError):
    """The scene did not come to rest within the settle time (no divergence: its hoses still
    creep or chatter faster than ``physics.settle_speed``)."""

    outcome = Outcome.SCENE_UNSETTLED

    def __init__(self, message: str, speed: float = float("nan"), limit: float = float("nan")):
        self.speed, self.limit = speed, limit
        super().__init__(message)


class NoGraspableSegmentError(SceneError, UnreachableError):
    """The hose of interest shows no visible, reachable, graspable segment; ``reasons`` counts
    why the candidates were turned down."""

    outcome = Outcome.NO_GRASPABLE_SEGMENT

    def __init__(self, message: str, reasons: dict[str, int] | None = None):
        self.reasons = dict(reasons or {})
        super().__init__(message)


def outcome_of(error: BaseException) -> str:
    """The named outcome a run records for ``error``: the error's own ``outcome`` (scene
    errors, ``diverged``), else ``error:<ErrorType>``."""
    return getattr(error, "outcome", None) or f"error:{type(error).__name__}"
