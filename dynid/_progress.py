"""Progress of a long command on stderr: stage lines with elapsed time, and a heartbeat in between.

A command (``dynid identify``, ``diagnose``, ...) opens a :func:`session`; library code marks its
long steps with :func:`stage` (a context manager) and reports countable work with :func:`advance`.
Outside a session both are silent, so ``import dynid`` used from Python prints nothing it was not
asked for.  Inside one:

* a stage (or a line said with :func:`say`) is printed, ``dynid identify: fitting the link
  parameters...``, once it has run for :data:`SHOW_AFTER_S` (a quick command, or one that refuses its
  input at once, prints nothing but its result or its one-sentence error); a printed stage prints
  ``... done (3.2 s)`` when it ends;
* a heartbeat thread prints the current stage with its elapsed time (and, for countable work, how
  much is done and an estimate of what is left) whenever nothing was printed for
  :data:`HEARTBEAT_S` seconds, so no command is silent longer than that;
* on a terminal the heartbeat redraws one line with a bar instead of adding lines; piped or in CI
  (``CI`` set) it adds plain lines, never control characters.

Everything goes to stderr: stdout and the files keep their contracts.  ``--quiet`` (every command)
opens no session.
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import time
from collections.abc import Iterator
from typing import TextIO

__all__ = ["HEARTBEAT_S", "Session", "active", "advance", "say", "session", "stage", "touch"]

HEARTBEAT_S = 3.0  # under load a beat slips by 1-2 s (a busy core, a call holding the interpreter): 5 s at most
"""Longest silence (s) inside a session before the heartbeat prints the current stage."""
SHOW_AFTER_S = 1.0
"""A stage or a said line is printed once it has lasted this long (s)."""


class Session:
    """The progress of one command: where its lines go and what it is doing now.

    Parameters
    ----------
    command : str
        The command's name, the prefix of every line (``dynid <command>: ...``).
    stream : file, optional
        Where the lines go (default ``sys.stderr``).
    heartbeat : float
        Longest silence (s) before the current stage is printed again.
    """

    def __init__(self, command: str, *, stream: TextIO | None = None, heartbeat: float = HEARTBEAT_S) -> None:
        self.command = command
        self.stream = sys.stderr if stream is None else stream
        self.heartbeat = float(heartbeat)
        self.started = time.monotonic()
        self._stages: list[list] = []  # [label, start, done, total]
        self._lock = threading.RLock()
        self._last = self.started
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        isatty = getattr(self.stream, "isatty", lambda: False)
        self.terminal = bool(isatty()) and not os.environ.get("CI") and os.environ.get("TERM") != "dumb"
        self._redraw = False  # a bar is on the current terminal line
        self._current = ["working", self.started, True]  # the last line said, when, whether printed

    # ------------------------------------------------------------------ output
    def _write(self, text: str) -> None:
        with self._lock:
            if self._redraw:
                self.stream.write("\r\033[K")
                self._redraw = False
            self.stream.write(text + "\n")
            self.stream.flush()
            self._last = time.monotonic()

    def touch(self) -> None:
        """The command printed a line of its own: the heartbeat waits its full interval again."""
        with self._lock:
            self._last = time.monotonic()

    def say(self, text: str) -> None:
        """A line of progress: what the command does now.

        A line that already names dynid (the symbolic build's) is printed at once; any other becomes
        the current activity, printed (prefixed with the command) once it has lasted
        :data:`SHOW_AFTER_S`, and repeated by the heartbeat with its elapsed time until the next one.
        """
        text = text.rstrip()
        if text.startswith("dynid"):
            self._write(text)
            return
        with self._lock:
            self._current = [text.removesuffix("...").rstrip(), time.monotonic(), False]

    # ------------------------------------------------------------------ stages
    def push(self, label: str, total: int | None) -> None:
        with self._lock:
            self._stages.append([label, time.monotonic(), 0, total, False])

    def pop(self) -> None:
        with self._lock:
            label, start, _, _, shown = self._stages.pop()
            elapsed = time.monotonic() - start
            if shown:
                self._write(f"dynid {self.command}: {label}: done ({_fmt(elapsed)})")

    def advance(self, done: int, total: int | None = None) -> None:
        with self._lock:
            if self._stages:
                self._stages[-1][2] = int(done)
                if total is not None:
                    self._stages[-1][3] = int(total)

    def status(self) -> str:
        """The heartbeat's line: the current stage, its elapsed time, what is done and what is left."""
        now = time.monotonic()
        with self._lock:
            if not self._stages:
                label, start, _ = self._current
                return f"{label} ({_fmt(now - start)})"
            label, start, done, total, _ = self._stages[-1]
        elapsed = now - start
        if total:
            frac = min(max(done / total, 0.0), 1.0)
            left = f", about {_fmt(elapsed * (1 - frac) / frac)} left" if done > 0 else ""
            if self.terminal:
                bar = "#" * round(20 * frac) + "." * (20 - round(20 * frac))
                return f"{label} [{bar}] {done}/{total} ({_fmt(elapsed)}{left})"
            return f"{label}: {done}/{total} ({_fmt(elapsed)}{left})"
        return f"{label} ({_fmt(elapsed)})"

    def _opening(self) -> str | None:
        """The current activity's first line, once it has lasted :data:`SHOW_AFTER_S` (None otherwise)."""
        now = time.monotonic()
        item = self._stages[-1] if self._stages else self._current
        shown_at = 4 if self._stages else 2
        if item[shown_at] or now - item[1] < SHOW_AFTER_S or item[0] == "working":
            return None
        item[shown_at] = True
        return f"dynid {self.command}: {item[0]}..."

    def _beat(self) -> None:
        while not self._stop.wait(0.1):
            with self._lock:
                opening = self._opening()
                if opening is not None:
                    self._write(opening)
                    continue
                item = self._stages[-1] if self._stages else self._current
                if not item[4 if self._stages else 2]:
                    continue  # not shown yet: its opening line comes first
                quiet_for = time.monotonic() - self._last
                if quiet_for < self.heartbeat and not (self.terminal and self._redraw and quiet_for >= 1.0):
                    continue
                line = f"dynid {self.command}: {self.status()}"
                if self.terminal:
                    self.stream.write("\r\033[K" + line[: _width() - 1])
                    self.stream.flush()
                    self._redraw = True
                    self._last = time.monotonic()
                else:
                    self._write(line)

    def start(self) -> Session:
        self._thread = threading.Thread(target=self._beat, name="dynid-progress", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        with self._lock:
            if self._redraw:
                self.stream.write("\r\033[K")
                self.stream.flush()
                self._redraw = False


def _fmt(seconds: float) -> str:
    if seconds < 60:
        return f"{seconds:.1f} s" if seconds < 10 else f"{seconds:.0f} s"
    return f"{int(seconds // 60)} min {int(seconds % 60):02d} s"


def _width() -> int:
    try:
        return os.get_terminal_size(sys.stderr.fileno()).columns
    except (OSError, ValueError):
        return 100


_SESSIONS: list[Session] = []


def active() -> Session | None:
    """The open session, or None (library use: nothing is printed)."""
    return _SESSIONS[-1] if _SESSIONS else None


@contextlib.contextmanager
def session(command: str, *, quiet: bool = False, stream: TextIO | None = None) -> Iterator[Session | None]:
    """Show the progress of a command on stderr while the block runs (nothing when ``quiet``).

    Parameters
    ----------
    command : str
        The command's name.
    quiet : bool
        Open no session: every :func:`stage` and :func:`say` stays silent.
    stream : file, optional
        Where the lines go (default ``sys.stderr``).
    """
    if quiet:
        yield None
        return
    s = Session(command, stream=stream).start()
    _SESSIONS.append(s)
    try:
        yield s
    finally:
        _SESSIONS.remove(s)
        s.stop()


@contextlib.contextmanager
def stage(label: str, total: int | None = None) -> Iterator[None]:
    """Mark a long step of the current command (silent outside a session).

    Parameters
    ----------
    label : str
        What the step does, as a person reads it ("fitting the friction").
    total : int, optional
        How many units of work the step has, when it is countable (see :func:`advance`).
    """
    s = active()
    if s is None:
        yield
        return
    s.push(label, total)
    try:
        yield
    finally:
        s.pop()


def advance(done: int, total: int | None = None) -> None:
    """How much of the current stage's countable work is done (for the estimate of what is left)."""
    s = active()
    if s is not None:
        s.advance(done, total)


def say(text: str) -> None:
    """One line of progress for the current command (silent outside a session)."""
    s = active()
    if s is not None:
        s.say(text)


def touch() -> None:
    """Note that the command printed something of its own (the heartbeat waits again)."""
    s = active()
    if s is not None:
        s.touch()
