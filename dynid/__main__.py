"""``python -m dynid``: the command line, as the ``dynid`` script runs it."""

from dynid.cli import main

__all__: list[str] = []

if __name__ == "__main__":
    raise SystemExit(main())
