"""Helpers of the documentation build (docs/conf.py), importable by name from sphinx-gallery."""

from __future__ import annotations

from pathlib import Path
from typing import Any

#: Where the gallery's scripts write their files during a build (ignored by git, with the build).
OUTPUT = Path(__file__).resolve().parent / "_build" / "gallery-output"


def example_output(gallery_conf: dict[str, Any], script_vars: dict[str, Any]) -> list[str]:
    """``sys.argv[1:]`` of a gallery script: a folder of its own under :data:`OUTPUT`.

    Each example writes into the folder it is given (else a temporary one); in a build that is
    ``docs/_build/gallery-output/<example>``, removed with the build rather than left in /tmp.
    """
    return [str(OUTPUT / Path(script_vars["src_file"]).stem)]
