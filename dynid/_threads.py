"""One BLAS thread for dynid's small and tall-thin factorisations.

On a shared 2-core machine a threaded OpenBLAS spends 10-100x longer on the blocks dynid factorises
than one thread does (measured: QR of a 2,000 x 178 block, 0.1-1.7 s threaded against 0.008 s).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, TypeVar

__all__ = ["one_blas_thread", "single_blas_thread"]

F = TypeVar("F", bound=Callable[..., Any])


def single_blas_thread():
    """Context manager limiting BLAS to one thread (threadpoolctl)."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")


def one_blas_thread(func: F) -> F:
    """Decorator: run ``func`` with one BLAS thread."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with single_blas_thread():
            return func(*args, **kwargs)

    return wrapper  # type: ignore[return-value]
