"""Errors raised by dynid.

Every message says what was expected, what came, and how to fix it, in one sentence.  The command
line prints the message alone (no traceback) and exits with a non-zero code.
"""

from __future__ import annotations

__all__ = [
    "CompilerNotFoundError",
    "DataError",
    "DynidError",
    "GeneratorError",
    "IdentificationError",
    "ModelFileError",
    "RobotModelError",
    "ShapeError",
    "UsageError",
]


class DynidError(Exception):
    """Base class of every error dynid raises on purpose."""


class RobotModelError(DynidError, ValueError):
    """A robot description (name, URDF, modified-DH table) could not be used."""


class ShapeError(DynidError, ValueError):
    """An array has the wrong shape for the robot (e.g. q with 7 columns for a 6-joint arm)."""


class DataError(DynidError, ValueError):
    """A dataset is malformed: missing columns, NaN, non-monotonic time, wrong units."""


class IdentificationError(DynidError, ValueError):
    """An identification cannot be carried out on the data given (rank deficiency, too few samples)."""


class ModelFileError(DynidError, ValueError):
    """A model or trajectory file is missing, corrupt, or belongs to another robot."""


class CompilerNotFoundError(DynidError, RuntimeError):
    """No C or C++ compiler was found where dynid needs to build code."""


class GeneratorError(DynidError, RuntimeError):
    """The symbolic generator failed to build or to run."""


class UsageError(DynidError, ValueError):
    """An option or argument has a value dynid cannot use."""
