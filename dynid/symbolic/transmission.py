"""Coupled transmissions: the motor of joint i turns, in joint units, by ``(R q)_i``.

A wrist whose motor 6 also turns with joint 5 has ``R[5, 4] = 1`` (the TX40's).  The matrix is checked
(numbers, finite, unit diagonal, ratios below :data:`_MAX_COUPLING`, invertible) wherever it comes from: a
``[transmission]`` table in a robot's TOML file, a file of its own (:func:`load_transmission`), or a
:class:`~dynid.symbolic.robot_model.RobotModel` made with one.
"""

from __future__ import annotations

import math
import os
import tomllib
from pathlib import Path

import numpy as np

from dynid.exceptions import RobotModelError

__all__ = ["check_transmission", "load_transmission", "transmission_table"]

_MAX_COUPLING = 1e3
"""Largest coupling ratio (joint units per joint unit) of a transmission: real wrists couple at ratios near 1."""

_MAX_TRANSMISSION_COND = 1e8
"""Largest condition number of a transmission matrix: beyond it motor and joint angles cannot be told apart."""


def _is_number(value) -> bool:
    """A TOML/JSON number: an int or a float, not a bool (``true`` is not joint 1) nor a string."""
    number = isinstance(value, int | float | np.integer | np.floating)
    return number and not isinstance(value, bool | np.bool_)


def check_transmission(value, n: int, where: str) -> np.ndarray:
    """The matrix R (n, n) of a coupled transmission, checked: numbers, finite, unit diagonal, invertible."""
    if isinstance(value, list | tuple) and not all(
        _is_number(v) for row in value for v in (row if isinstance(row, list | tuple) else [row])
    ):
        R = np.zeros(0)  # strings or booleans as numbers
    else:
        try:
            R = np.array(value, dtype=float)
        except (TypeError, ValueError):
            R = np.zeros(0)
    if R.shape != (n, n) or not np.all(np.isfinite(R)):
        raise RobotModelError(
            f"the transmission of {where} is {R.shape if R.size else 'not a matrix of numbers'}; give an "
            f"({n}, {n}) matrix of finite numbers (motor angles in joint units per joint angle)."
        )
    if not np.allclose(np.diag(R), 1.0):
        raise RobotModelError(
            f"the transmission of {where} has diagonal {np.diag(R).tolist()}; each motor turns with its own "
            "joint at ratio 1 in joint units: give a unit diagonal (fold the gear ratio into the coupling)."
        )
    big = np.abs(R - np.eye(n)) > _MAX_COUPLING
    if np.any(big):
        i, j = np.argwhere(big)[0]
        raise RobotModelError(
            f"the transmission of {where} couples motor {i + 1} to joint {j + 1} at ratio {R[i, j]:g}, beyond "
            f"+-{_MAX_COUPLING:g}; give the ratio in joint units per joint unit (a wrist couples at about 1)."
        )
    cond = np.linalg.cond(R)
    if not cond <= _MAX_TRANSMISSION_COND:
        raise RobotModelError(
            f"the transmission of {where} is singular (condition number {cond:.3g}): two motors turn with the "
            "same combination of joints, so motor and joint angles cannot be told apart; couple each pair of "
            "joints once (motor b with joint a, not also motor a with joint b at the same ratio)."
        )
    R.setflags(write=False)
    return R


def transmission_table(section, n: int, where: str) -> np.ndarray:
    """R from a ``[transmission]`` table: ``matrix = [[...], ...]`` or ``coupled = [[a, b, r], ...]``
    (motor b also turns by r times joint a, joints numbered from 1)."""
    if not isinstance(section, dict) or not ({"matrix", "coupled"} & set(section)):
        raise RobotModelError(
            f"the [transmission] table of {where} has neither 'matrix' nor 'coupled'; write e.g. "
            "coupled = [[5, 6, 1.0]] (motor 6 also turns with joint 5) or an n x n matrix."
        )
    unknown = sorted(set(section) - {"matrix", "coupled"})
    if unknown:
        raise RobotModelError(
            f"the [transmission] table of {where} has the unknown key '{unknown[0]}'; it holds 'coupled' or "
            "'matrix' only: remove or rename the key."
        )
    if len(section) > 1:
        raise RobotModelError(
            f"the [transmission] table of {where} has both 'matrix' and 'coupled'; give one of them."
        )
    if "matrix" in section:
        return check_transmission(section["matrix"], n, where)
    coupled = section["coupled"]
    if isinstance(coupled, list) and not coupled:
        raise RobotModelError(
            f"'transmission.coupled' in {where} is empty; list the couplings, e.g. coupled = [[5, 6, 1.0]], or "
            "give no transmission when the joints are not coupled."
        )
    R = np.eye(n)
    seen: set[tuple[int, int]] = set()
    for entry in coupled if isinstance(coupled, list) else [None]:
        ok = isinstance(entry, list) and len(entry) == 3
        if ok:
            a, b, r = entry
            ok = all(_is_number(v) and int(v) == v and 1 <= v <= n for v in (a, b)) and a != b
            ok = ok and _is_number(r) and math.isfinite(r)
        if not ok:
            raise RobotModelError(
                f"the entry {entry!r} of 'transmission.coupled' in {where} is not [a, b, r] with joints a != b "
                f"in 1..{n} and a finite ratio r (numbers, not text or true/false); write e.g. "
                "coupled = [[5, 6, 1.0]]."
            )
        a, b = int(a), int(b)
        if (a, b) in seen:
            raise RobotModelError(
                f"'transmission.coupled' in {where} couples motor {b} to joint {a} twice; give each pair once."
            )
        seen.add((a, b))
        R[b - 1, a - 1] = float(r)
    return check_transmission(R, n, where)


def load_transmission(path: str | os.PathLike[str], n: int) -> np.ndarray:
    """Read a coupled transmission from a TOML file holding a ``[transmission]`` table.

    Parameters
    ----------
    path : str or path-like
        The file (``[transmission]`` with ``coupled = [[a, b, r], ...]``: motor b also turns by r times
        joint a, joints from 1; or ``matrix``: the n x n matrix ``R`` with ``u = R q``).
    n : int
        Number of joints of the robot.

    Returns
    -------
    ndarray, shape (n, n)

    Raises
    ------
    RobotModelError
        Missing or malformed file or table.
    """
    path = Path(path)
    if not path.is_file():
        raise RobotModelError(
            f"the transmission file '{path}' does not exist; give a .toml file with a [transmission] table."
        )
    try:
        table = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise RobotModelError(
            f"the transmission file '{path}' is not valid TOML ({exc}); fix its syntax."
        ) from None
    return transmission_table(table.get("transmission"), n, f"'{path}'")
