"""One exception hierarchy for everything a user can get wrong.

The CLI catches :class:`RobocalError` and prints its message as one line
(exit status 2); any other exception is a bug and keeps its traceback.
Messages say what was expected and what was found, and name the file and
field when the error comes from an input file.
"""

from __future__ import annotations

__all__ = [
    "RobocalError",
    "InputError",
    "ShapeError",
    "UnitError",
    "NonFiniteError",
    "FileFormatError",
    "DegenerateGeometryError",
    "NotEnoughDataError",
    "SingularConfigurationError",
    "InconsistentDataError",
    "DetectionError",
    "ConvergenceError",
    "ImplausibleInputError",
    "ResourceError",
]


class RobocalError(Exception):
    """Base class of every error robocal raises on purpose.

    Parameters
    ----------
    message : str
        What is wrong, in one line.
    source : str, optional
        File (and field) the problem was found in; prefixed to the message.
    """

    def __init__(self, message: str, *, source: str | None = None):
        self.message = message
        self.source = source
        super().__init__(f"{source}: {message}" if source else message)

    def with_source(self, source: str) -> "RobocalError":
        """Return a copy of this error that names ``source`` (file/field)."""
        merged = f"{source}: {self.source}" if self.source else source
        err = type(self).__new__(type(self))
        RobocalError.__init__(err, self.message, source=merged)
        return err


class InputError(RobocalError, ValueError):
    """Input has the wrong type, value or structure."""


class ShapeError(InputError):
    """An array has the wrong shape."""


class UnitError(InputError):
    """A unit is missing, unknown, or of the wrong dimension."""


class NonFiniteError(InputError):
    """An input contains NaN or infinity."""


class FileFormatError(InputError):
    """A file cannot be read or does not follow its documented schema."""


class DegenerateGeometryError(RobocalError, ValueError):
    """The data cannot determine the quantity asked for (collinear points,
    coplanar points for a sphere, rotations about parallel axes, ...)."""


class NotEnoughDataError(DegenerateGeometryError):
    """Fewer observations than the problem needs."""


class SingularConfigurationError(RobocalError, ValueError):
    """A mechanism is at or too near a kinematic singularity."""


class InconsistentDataError(RobocalError, ValueError):
    """Measurements contradict each other beyond their noise."""


class DetectionError(RobocalError):
    """A target could not be found in an image."""


class ConvergenceError(RobocalError, RuntimeError):
    """An iterative solver did not reach a usable solution."""


class ImplausibleInputError(InputError):
    """The input reads without error but the fit it gives is physically implausible.

    Raised by :func:`robocal.plausibility.check_slips` when a likely slip (a
    unit off by 1000, degrees read as radians, a transposed board, swapped
    columns, an inverted pose, ...) explains the data far better, or when no
    slip does but the answer is still outside physical bounds. ``slip`` names
    the slip that explained it (``None`` when none did). The CLI's
    ``--accept-implausible`` turns it into an ``implausible_input`` warning.
    """

    def __init__(self, message: str, *, source: str | None = None, slip: str | None = None):
        super().__init__(message, source=source)
        self.slip = slip

    def with_source(self, source: str) -> "ImplausibleInputError":
        err = super().with_source(source)
        err.slip = self.slip
        return err


class ResourceError(RobocalError, MemoryError):
    """The work asked for needs more memory (or another resource) than the machine has."""
