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

__all__ = ["JOINT_THREADS", "core_count", "one_blas_thread", "single_blas_thread"]

F = TypeVar("F", bound=Callable[..., Any])


def core_count() -> int:
    """Cores this process may run on (its CPU affinity where the system tells it)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def _joint_threads() -> int:
    limit = os.environ.get("DYNID_NUM_THREADS", "").strip()
    cores = core_count()
    if limit.isdigit() and int(limit) >= 1:
        cores = min(cores, int(limit))
    return min(2, cores)


JOINT_THREADS = _joint_threads()
"""Threads of the per-joint work of an identification (friction searches, link steps, filters): two at
most, as the work per joint is small and the process's own threads run beside them; fewer when
``$DYNID_NUM_THREADS`` says so (as the compiled regressors' threads), as in the local workers of a fleet,
which share the machine's cores."""


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
