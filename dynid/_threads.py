"""One BLAS thread for dynid's small and tall-thin factorisations.

On a shared 2-core machine a threaded OpenBLAS spends 10-100x longer on the blocks dynid factorises
than one thread does (measured: QR of a 2,000 x 178 block, 0.1-1.7 s threaded against 0.008 s).
"""

from __future__ import annotations

import contextlib
import functools
import os
import threading
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

__all__ = ["JOINT_THREADS", "core_count", "env_threads", "one_blas_thread", "single_blas_thread"]

F = TypeVar("F", bound=Callable[..., Any])


def core_count() -> int:
    """Cores this process may run on (its CPU affinity where the system tells it)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def env_threads() -> int | None:
    """``$DYNID_NUM_THREADS`` if it is a whole number of 1 or more, else None (unset, empty or any
    other value: ignored, as the exported loader ``dynid_loader.py`` ignores it)."""
    try:
        value = int(os.environ.get("DYNID_NUM_THREADS", "").strip())
    except ValueError:
        return None
    return value if value >= 1 else None


def _joint_threads() -> int:
    return min(2, core_count(), env_threads() or 2)


JOINT_THREADS = _joint_threads()
"""Threads of an identification's large filters (the data matrix's columns, two blocks at once): two at
most, as the process's own threads run beside them; fewer when
``$DYNID_NUM_THREADS`` (:func:`env_threads`) says so, which also sets the compiled regressors' threads:
the local workers of a fleet, which share the machine's cores, get 1."""


_LOCK = threading.Lock()
_DEPTH = 0
_LIMITER: Any = None


@contextlib.contextmanager
def single_blas_thread() -> Iterator[None]:
    """Context manager limiting BLAS to one thread (threadpoolctl).

    Nested and concurrent uses share one limit, set by the first to enter and lifted by the last to
    leave: setting a limit inspects every loaded library (about 3-10 ms), and a default identification
    enters this context about a hundred times, mostly inside another one.
    """
    global _DEPTH, _LIMITER
    with _LOCK:
        if _DEPTH == 0:
            from threadpoolctl import threadpool_limits

            _LIMITER = threadpool_limits(limits=1, user_api="blas")
        _DEPTH += 1
    try:
        yield
    finally:
        with _LOCK:
            _DEPTH -= 1
            if _DEPTH == 0:
                _LIMITER.restore_original_limits()
                _LIMITER = None


def one_blas_thread(func: F) -> F:
    """Decorator: run ``func`` with one BLAS thread."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with single_blas_thread():
            return func(*args, **kwargs)

    return wrapper  # type: ignore[return-value]
