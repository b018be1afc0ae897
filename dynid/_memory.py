"""Memory the process freed handed back to the system between the long phases of a fit.

glibc keeps freed heap memory for reuse, and a fit that runs its joints in threads spreads its
allocations over several arenas: after the cross-validation of a long recording a process held 1.8 GB
of which 0.9 GB was free.  :func:`give_back` asks the allocator to return what it can (``malloc_trim``);
elsewhere it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools

__all__ = ["give_back"]


@functools.cache
def _trim():
    name = ctypes.util.find_library("c")
    try:
        return getattr(ctypes.CDLL(name), "malloc_trim", None) if name else None
    except OSError:
        return None


def give_back() -> None:
    """Return the heap's free memory to the system where the C library can (glibc); else nothing."""
    trim = _trim()
    if trim is not None:
        trim(0)
