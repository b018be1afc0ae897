"""Subcommands of the ``dynid`` command, one module each (see :mod:`dynid.cli`).

Modules import numpy, CasADi and the rest inside ``run`` so that ``dynid --help`` stays fast.
"""

__all__: list[str] = []
