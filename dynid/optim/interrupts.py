"""Signals during an excitation design: Ctrl-C, SIGTERM and SIGHUP end IPOPT at its next iteration.

CasADi checks for signals while IPOPT runs and swallows the ``KeyboardInterrupt`` that Ctrl-C or
dynid's SIGTERM handler raises there (a warning, and the solve goes on): the design would carry on
for minutes.  :func:`interruptible` records the signal before the handler raises, the solver's
iteration callback (:class:`StopCallback`) then ends IPOPT at its next iteration, and the try raises
``KeyboardInterrupt`` again once the solver has returned (:func:`check_stop`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import casadi as ca

__all__ = ["StopCallback", "check_stop", "interruptible", "solving"]

_STOP: list[str] = []
"""Name of the signal that interrupted the design in this process (empty while none did)."""

_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")
_DEPTH = [0]
_SOLVING: set[int] = set()
"""Threads inside IPOPT.  A signal there is only recorded: raised inside the objective's callback, the
exception would be printed with its traceback by CasADi and the solve would go on."""


@contextmanager
def interruptible() -> Iterator[None]:
    """Record SIGINT, SIGTERM and SIGHUP in :data:`_STOP`, then run the handler that was in place.

    Only handlers that are Python callables are wrapped (Ctrl-C's default, dynid's command line):
    a signal left at its default action still ends the process as before.  Outside the main thread
    (where signals cannot be set) nothing changes.
    """
    import signal

    if _DEPTH[0]:  # inside a design (a try run in the designing process): its guard is in place
        yield
        return
    _STOP.clear()
    _DEPTH[0] += 1
    previous: dict[int, Callable] = {}
    if threading.current_thread() is threading.main_thread():
        for name in _SIGNALS:
            sig = getattr(signal, name, None)
            handler = None if sig is None else signal.getsignal(sig)
            if callable(handler):
                previous[sig] = handler

                def record(signum: int, frame: object, handler: Callable = handler) -> None:
                    _STOP.append(signal.Signals(signum).name)
                    if threading.get_ident() not in _SOLVING:  # see _SOLVING
                        handler(signum, frame)

                signal.signal(sig, record)
    try:
        yield
        check_stop()
    finally:
        _DEPTH[0] -= 1
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def check_stop() -> None:
    """Raise ``KeyboardInterrupt`` (with the signal's name) when a signal came during the design."""
    if _STOP:
        name = _STOP[0]
        raise KeyboardInterrupt(*(() if name == "SIGINT" else (name,)))


@contextmanager
def solving() -> Iterator[None]:
    """Mark the calling thread as inside IPOPT (see :data:`_SOLVING`) while the block runs."""
    me = threading.get_ident()
    _SOLVING.add(me)
    try:
        yield
    finally:
        _SOLVING.discard(me)


class StopCallback(ca.Callback):
    """IPOPT's iteration callback: returns 1 (IPOPT stops: User_Requested_Stop) once a signal came."""

    def __init__(self, name: str, nx: int, ng: int, npar: int) -> None:
        ca.Callback.__init__(self)
        self._sizes = {"x": nx, "lam_x": nx, "g": ng, "lam_g": ng, "lam_p": npar, "f": 1}
        self.construct(name, {})

    def get_n_in(self) -> int:
        return ca.nlpsol_n_out()

    def get_n_out(self) -> int:
        return 1

    def get_name_in(self, i: int) -> str:
        return ca.nlpsol_out(i)

    def get_name_out(self, i: int) -> str:
        return "ret"

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        return ca.Sparsity.dense(self._sizes.get(ca.nlpsol_out(i), 0), 1)

    def eval(self, arg):
        return [1 if _STOP else 0]

