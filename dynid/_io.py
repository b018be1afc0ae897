"""The ``default`` of :func:`json.dumps` for dynid's figures and files: arrays, numpy scalars, paths."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["jsonable"]


def jsonable(value: Any) -> Any:
    """A JSON value for what :mod:`json` cannot write itself: arrays to lists, numpy scalars, paths.

    Parameters
    ----------
    value : Any
        What :func:`json.dumps` met and could not write.

    Raises
    ------
    TypeError
        Anything else, as :func:`json.dumps` expects of its ``default``.
    """
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")
