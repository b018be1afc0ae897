"""The ``dynid`` command.

Each subcommand lives in its own module under :mod:`dynid.commands` and defines

* ``HELP``: one line shown by ``dynid --help``;
* ``add_arguments(parser)``: its options;
* ``run(args) -> int``: the work, returning the exit code.

Modules are imported only when their command runs, so ``dynid --help`` starts fast.  A user's
mistake (any :class:`dynid.exceptions.DynidError`) ends with one sentence on stderr and exit code 2,
never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

__all__ = ["main"]

# Command name -> module in dynid.commands.  Listed in the order of the user's path.
COMMANDS = {
    "demo": "demo",
    "info": "info",
    "excite": "excite",
    "simulate": "simulate",
    "identify": "identify",
    "validate": "validate",
    "diagnose": "diagnose",
    "export-c": "export_c",
}


def build_parser() -> argparse.ArgumentParser:
    from dynid import __version__

    parser = argparse.ArgumentParser(
        prog="dynid",
        description="Identify the dynamic model of a robot arm and diagnose what it still gets wrong.",
    )
    parser.add_argument("--version", action="version", version=f"dynid {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, module in COMMANDS.items():
        mod = importlib.import_module(f"dynid.commands.{module}")
        p = sub.add_parser(name, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_module=mod)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``dynid`` command; returns the exit code."""
    from dynid.exceptions import DynidError

    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    try:
        return int(args._module.run(args) or 0)
    except DynidError as exc:
        print(f"dynid {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"dynid {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
