"""Lazy public names for dynid's packages: each submodule is imported on first use of one of its names.

CasADi, scikit-learn and matplotlib are slow to import; ``dynid --help`` and ``import dynid`` should not
pay for them.  A package lists its public names and the submodule that holds each, and takes its
``__getattr__`` and ``__dir__`` from :func:`lazy_exports`.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(
    package: str, exports: Mapping[str, str], eager: tuple[str, ...] = ()
) -> tuple[list[str], Callable[[str], Any], Callable[[], list[str]]]:
    """``__all__``, ``__getattr__`` and ``__dir__`` for a package whose names load on first use.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    exports : mapping of str to str
        Public name -> the submodule (relative to ``package``) that defines it.
    eager : tuple of str
        Public names the package defines itself (listed in ``__all__`` too).

    Returns
    -------
    (list of str, callable, callable)
        ``__all__``, ``__getattr__`` and ``__dir__``.
    """
    names = sorted({*exports, *eager})

    def __getattr__(name: str) -> Any:
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module '{package}' has no attribute {name!r}")
        return getattr(importlib.import_module(f"{package}.{module}"), name)

    def __dir__() -> list[str]:
        return names

    return names, __getattr__, __dir__
