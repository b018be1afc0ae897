"""The ``dynid`` command.

Each subcommand lives in its own module under :mod:`dynid.commands` and defines

* ``HELP``: one line shown by ``dynid --help``;
* ``add_arguments(parser)``: its options;
* ``run(args) -> int``: the work, returning the exit code.

Modules are imported only when their command runs, so ``dynid --help`` starts fast.  A user's
mistake (any :class:`dynid.exceptions.DynidError`, a file the system refuses, an option argparse
refuses) ends with one line on stderr and exit code 2, never a traceback or a usage block.  A value
that starts with a minus (``--q-min -1,-1,-1``) is taken as the option's value.  A termination signal
(SIGTERM, SIGHUP) interrupts the command like Ctrl-C, so every file being written is removed, not left
half written.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import re
import signal
import sys
import warnings
from collections.abc import Iterator, Sequence

__all__ = ["main"]

# Command name -> module in dynid.commands.  Listed in the order of the user's path.
COMMANDS = {
    "demo": "demo",
    "info": "info",
    "excite": "excite",
    "simulate": "simulate",
    "convert": "convert",
    "identify": "identify",
    "validate": "validate",
    "payload": "payload",
    "diagnose": "diagnose",
    "fleet": "fleet",
    "export": "export",
    "export-c": "export_c",
}


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line: the message and where the help is."""

    def error(self, message: str) -> None:  # type: ignore[override]
        message = message.rstrip(".")
        self.exit(2, f"{self.prog}: error: {message}; see '{self.prog} --help'\n")


# A value such as -1,-1,-1 or -.5,2 or -1e-3: argparse would read it as an option.
_NEGATIVE = re.compile(r"^-(\d|\.\d)[\d.,eE+\-]*$")


def _join_negative_values(argv: Sequence[str]) -> Iterator[str]:
    """``--opt -1,-1`` -> ``--opt=-1,-1``: dynid has no positional arguments, so such a token is a value."""
    argv = list(argv)
    k = 0
    while k < len(argv):
        token = argv[k]
        if token.startswith("--") and "=" not in token and k + 1 < len(argv) and _NEGATIVE.match(argv[k + 1]):
            yield f"{token}={argv[k + 1]}"
            k += 2
            continue
        yield token
        k += 1


def _terminate(signum: int, frame: object) -> None:
    raise KeyboardInterrupt(signal.Signals(signum).name)


def _forget_nested_interrupt() -> None:
    """Clear CPython's record of an uncaught KeyboardInterrupt, once dynid has caught it.

    An interrupt that lands while an extension runs Python code through ``PyRun_String`` leaves that
    code uncaught, and CPython records it; at exit the interpreter then kills itself with SIGINT
    (status -2) instead of returning dynid's exit code 130, though dynid caught the interrupt, removed
    its files and said so.  Every ``PyRun_*`` evaluation clears the record: one of ``pass`` does.
    """
    try:
        import ctypes

        ctypes.pythonapi.PyRun_SimpleStringFlags(b"pass", None)
    except (AttributeError, OSError):  # not CPython: no such record
        pass


_BUILTIN_BACKENDS = frozenset(
    "agg cairo pdf pgf ps svg template gtk3agg gtk3cairo gtk4agg gtk4cairo macosx nbagg notebook qtagg "
    "qtcairo qt5agg qt5cairo tkagg tkcairo webagg wx wxagg wxcairo".split()
)  # matplotlib's built-in backends (matplotlib.backends.registry.BackendRegistry); others are checked by import


def _check_matplotlib_backend() -> None:
    """Refuse an ``MPLBACKEND`` that matplotlib does not know, before a report's figures fail on it.

    matplotlib reads the variable when it is first imported and raises a ValueError from deep inside;
    dynid draws its figures into files (no window), any valid backend will do.
    """
    import os

    value = os.environ.get("MPLBACKEND")
    if not value or "matplotlib" in sys.modules:
        return
    if value.lower() in _BUILTIN_BACKENDS:
        return  # a name matplotlib ships: valid without importing it (0.15-0.25 s of every command)
    try:
        import matplotlib  # noqa: F401
    except ValueError as exc:
        if "backend" not in str(exc):
            raise
        from dynid.exceptions import UsageError

        raise UsageError(
            f"the environment variable MPLBACKEND is '{value}', which matplotlib does not know; unset it or set "
            "it to Agg (dynid draws its figures into files, no window)"
        ) from None
    except ImportError:  # no matplotlib: the commands that need it say so
        return


def build_parser() -> argparse.ArgumentParser:
    from dynid import __version__

    parser = _Parser(
        prog="dynid",
        description="Identify the dynamic model of a robot arm and diagnose what it still gets wrong.",
    )
    parser.add_argument("--version", action="version", version=f"dynid {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, module in COMMANDS.items():
        mod = importlib.import_module(f"dynid.commands.{module}")
        p = sub.add_parser(name, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.add_argument(
            "--quiet", action="store_true", help="print no progress lines on stderr (results and errors still)"
        )
        p.set_defaults(_module=mod, _parser=p)
    return parser


class _ReaderMayStop:
    """stdout for the console command: a reader that stops (``dynid validate ... | head -1``) ends the
    printing, not the command, which writes its files to the end (a ``BrokenPipeError`` on the second line
    had stopped validate before its report, with an error about the system refusing an operation)."""

    def __init__(self, stream) -> None:
        self._stream = stream
        self._gone = False

    def _stopped(self) -> None:
        self._gone = True
        try:  # the interpreter flushes stdout at exit: point the descriptor at nothing
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self._stream.fileno())
            os.close(devnull)
        except (OSError, ValueError):
            pass

    def write(self, text: str) -> int:
        if not self._gone:
            try:
                return self._stream.write(text)
            except BrokenPipeError:
                self._stopped()
        return len(text)

    def flush(self) -> None:
        if not self._gone:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self._stopped()

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def _one_line_warnings(command: str, fallback):
    """A ``warnings.showwarning`` that prints dynid's own warnings as one line each, once per message.

    Python's default prints ``file:line: Category: message`` and the source line; a user of the command needs
    the message alone, and the same message (a gap in one recording, seen by each stage that reads it) once.
    Other packages' warnings keep their default form.
    """
    from dynid.exceptions import DynidWarning

    seen: set[str] = set()

    def show(message, category, filename, lineno, file=None, line=None) -> None:
        if not issubclass(category, DynidWarning):
            fallback(message, category, filename, lineno, file, line)
            return
        text = " ".join(str(message).split())
        if text not in seen:
            seen.add(text)
            print(f"dynid {command}: warning: {text}", file=sys.stderr if file is None else file)

    return show


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``dynid`` command; returns the exit code."""
    from dynid import _progress
    from dynid.exceptions import DynidError

    parser = build_parser()
    args, extra = parser.parse_known_args(list(_join_negative_values(sys.argv[1:] if argv is None else argv)))
    if extra:
        getattr(args, "_parser", parser).error(f"unrecognized arguments: {' '.join(extra)}")
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    previous = {}
    try:
        for sig in (signal.SIGTERM, signal.SIGHUP):
            previous[sig] = signal.signal(sig, _terminate)
    except ValueError:  # not the main thread: signals stay as they are
        pass
    try:
        with warnings.catch_warnings():
            if argv is None:  # the console command (tests calling main(argv) keep pytest's warning capture)
                warnings.showwarning = _one_line_warnings(args.command, warnings.showwarning)
                sys.stdout = _ReaderMayStop(sys.stdout)
            _check_matplotlib_backend()
            with _progress.session(args.command, quiet=bool(getattr(args, "quiet", False))):
                return int(args._module.run(args) or 0)
    except DynidError as exc:
        print(f"dynid {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # a file the system refuses after the checks (a race, a full disk)
        if exc.filename:
            what = f"cannot use '{exc.filename}'"
        elif exc.errno in (errno.ENOSPC, errno.EDQUOT):  # a write to an open file names none
            what = "cannot write its files"
        else:
            what = "the system refused an operation"
        print(
            f"dynid {args.command}: error: {what}: {exc.strerror or exc}; check the path, its "
            "permissions and the free space, then run the command again",
            file=sys.stderr,
        )
        return 2
    except KeyboardInterrupt as exc:
        reason = f" by {exc.args[0]}" if exc.args else ""
        print(f"dynid {args.command}: interrupted{reason}; no file was left half written", file=sys.stderr)
        _forget_nested_interrupt()
        return 130
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
