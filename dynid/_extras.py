"""How to install one of dynid's optional extras, said the way this copy of dynid was installed.

From PyPI the command is ``pip install "dynid[mujoco]"``; from a clone (an editable install, or the
source folder on the path) that command would fetch another dynid from PyPI, so the clone's own
``pip install -e "<folder>[mujoco]"`` is named instead.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["install_hint"]


def _source_folder() -> Path | None:
    """The folder holding ``pyproject.toml`` when dynid runs from a clone, else None."""
    root = Path(__file__).resolve().parent.parent
    if (root / "pyproject.toml").is_file() and "site-packages" not in root.parts:
        return root
    return None


def install_hint(extra: str) -> str:
    """The pip command that installs ``dynid[extra]`` for this installation.

    Parameters
    ----------
    extra : str
        An optional extra of pyproject.toml (``mujoco``, ``fleet``, ``ros``, ...).
    """
    root = _source_folder()
    if root is None:
        return f'pip install "dynid[{extra}]"'
    here = Path.cwd().resolve()
    where = "." if root == here else str(root)
    return f'pip install -e "{where}[{extra}]"'
