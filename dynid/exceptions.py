"""Errors and warnings of dynid: every class of them lives here.

Every message says what was expected, what came, and how to fix it, in one sentence.  The command
line prints the message alone (no traceback) and exits with a non-zero code.
"""

from __future__ import annotations

__all__ = [
    "CacheWarning",
    "CompilerNotFoundError",
    "DataError",
    "DataWarning",
    "DynidError",
    "DynidWarning",
    "ExcitationError",
    "GeneratorError",
    "IdentificationError",
    "IdentificationWarning",
    "ModelFileError",
    "NotFittedError",
    "RobotModelError",
    "RobotModelWarning",
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


class ExcitationError(UsageError):
    """An excitation cannot be designed as asked (no feasible trajectory, rank-deficient regressor)."""


class NotFittedError(IdentificationError, UsageError):
    """An estimator, friction model or correction was used before ``fit``.

    The one not-fitted error of dynid, raised by :func:`dynid.identify.checks.check_is_fitted`.  It is
    a :class:`ValueError` like scikit-learn's ``NotFittedError``, and an :class:`IdentificationError`
    and a :class:`UsageError`, the types these checks raised before.
    """


class DynidWarning(UserWarning):
    """Base class of every warning dynid issues."""


class DataWarning(DynidWarning):
    """Data that can be used but look suspicious (e.g. joint angles that look like degrees)."""


class IdentificationWarning(DynidWarning):
    """An identification finished but something deserves attention (e.g. IRLS did not converge)."""


class RobotModelWarning(DynidWarning):
    """A robot description that can be used but looks slightly off (e.g. a rounded inertia)."""


class CacheWarning(DynidWarning):
    """A file of dynid's cache was damaged (truncated, garbage) and has been rebuilt."""
