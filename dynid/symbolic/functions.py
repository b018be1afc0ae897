"""Named CasADi functions of a robot: Pinocchio's algorithms evaluated on CasADi SX symbols.

>>> from dynid.symbolic import load_robot, robot_functions
>>> f = robot_functions(load_robot("ur5"))       # first call per environment builds the generator
>>> f.regressor                                    # regressor:(q[6],dq[6],ddq[6])->(Y[6x60])

Every function is a ``casadi.Function`` with named inputs and outputs:

========================  ==========================================  =================================
name                      inputs -> outputs                           meaning
========================  ==========================================  =================================
``regressor``             q, dq, ddq -> Y (n x 10n)                    joint-torque regressor
``rnea``                  q, dq, ddq -> tau (n)                        inverse dynamics, armature included
``gravity``               q -> g (n)                                   generalised gravity
``mass_matrix``           q -> M (n x n)                               joint-space inertia, armature included
``aba``                   q, dq, tau -> ddq (n)                        forward dynamics
``fk``                    q -> p (3), R (3 x 3)                        tool frame in the base frame
``friction_columns``      dq -> F (n x 3n)                             [Coulomb sign(dq), viscous dq, offset]
``armature_columns``      ddq -> A (n x n)                             diag(ddq): rotor inertia columns
========================  ==========================================  =================================
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import casadi as ca
import numpy as np

from dynid.symbolic.build import FUNCTION_NAMES, Progress, robot_function_dir, stderr_progress
from dynid.symbolic.robot import RobotModel

__all__ = ["RobotFunctions", "direction_sx", "friction_columns_function", "robot_functions"]

_CACHE: dict[str, RobotFunctions] = {}


def direction_sx(v: ca.SX) -> ca.SX:
    """:func:`dynid._rest.direction` on symbols, element by element: the sign, 0 at rest."""
    from dynid._rest import AT_REST

    return ca.if_else(ca.fabs(v) < AT_REST, 0.0, ca.sign(v))


def friction_columns_function(n: int) -> ca.Function:
    """``friction_columns(dq) -> F``: per joint, Coulomb ``sign(dq_j)`` (0 at rest, below
    :data:`dynid._rest.AT_REST`), viscous ``dq_j`` and offset ``1``.

    F has shape (n, 3n), columns ordered ``[fc_1..fc_n, fv_1..fv_n, fo_1..fo_n]``.
    """
    dq = ca.SX.sym("dq", n)
    eye = ca.SX.eye(n)
    cols = ca.horzcat(ca.diag(direction_sx(dq)), ca.diag(dq), eye)
    return ca.Function("friction_columns", [dq], [ca.densify(cols)], ["dq"], ["F"])


def armature_columns_function(n: int) -> ca.Function:
    """``armature_columns(ddq) -> A = diag(ddq)``, shape (n, n): rotor inertia seen by each joint."""
    ddq = ca.SX.sym("ddq", n)
    return ca.Function("armature_columns", [ddq], [ca.densify(ca.diag(ddq))], ["ddq"], ["A"])


@dataclass(frozen=True, eq=False)
class RobotFunctions:
    """The CasADi functions of one robot (see the module docstring for the list)."""

    robot: RobotModel
    folder: Path
    regressor: ca.Function
    rnea: ca.Function
    gravity: ca.Function
    mass_matrix: ca.Function
    aba: ca.Function
    fk: ca.Function
    friction_columns: ca.Function
    armature_columns: ca.Function

    @property
    def n(self) -> int:
        return self.robot.n

    def regressor_numeric(self, q, dq, ddq) -> np.ndarray:
        """Y for a batch of states through the CasADi virtual machine, shape (m, n, 10n).

        For large batches prefer the compiled path (:mod:`dynid.symbolic.export`).
        """
        q, dq, ddq = (self.robot.check_state(label, v) for label, v in (("q", q), ("dq", dq), ("ddq", ddq)))
        m = q.shape[0]
        out = np.asarray(self.regressor.map(m)(q.T, dq.T, ddq.T))  # (n, 10n * m), samples side by side
        return out.reshape(self.n, m, 10 * self.n).transpose(1, 0, 2)

    def evaluate(self, name: str, *inputs) -> np.ndarray | tuple[np.ndarray, ...]:
        """Evaluate a function on a batch (each input of shape (m, k)) with the CasADi VM.

        Each output comes as an array of shape (m, rows, cols), or (m, rows) for column outputs; a
        function with several outputs (``fk``) gives a tuple.
        """
        f: ca.Function = getattr(self, name)
        arrays = [np.atleast_2d(np.asarray(v, dtype=float)) for v in inputs]
        m = arrays[0].shape[0]
        results = f.map(m)(*(a.T for a in arrays))
        results = results if isinstance(results, (list, tuple)) else [results]
        outs = []
        for i, res in enumerate(results):
            rows, cols = f.size1_out(i), f.size2_out(i)
            arr = np.asarray(res)
            outs.append(arr.reshape(rows, m, cols).transpose(1, 0, 2) if cols > 1 else arr.T)
        return outs[0] if len(outs) == 1 else tuple(outs)


def _load_functions(folder: Path) -> dict[str, ca.Function]:
    return {name: ca.Function.load(str(folder / f"{name}.casadi")) for name in FUNCTION_NAMES}


def robot_functions(robot: RobotModel, *, progress: Progress | None = stderr_progress) -> RobotFunctions:
    """Load (generating once, then from cache) the CasADi functions of ``robot``.

    Parameters
    ----------
    robot : RobotModel
        The robot, from :func:`dynid.symbolic.load_robot`.
    progress : callable, optional
        Receives one line of text per step of a one-time build (default: printed to stderr).
    """
    cached = _CACHE.get(robot.key)
    if cached is not None:  # same tree: same functions, whatever the limits
        return cached if cached.robot is robot else replace(cached, robot=robot)
    folder = robot_function_dir(robot.spec, progress)
    try:
        loaded = _load_functions(folder)
    except RuntimeError:  # a damaged cache file (truncated, overwritten): generated again
        import warnings

        from dynid.exceptions import CacheWarning

        warnings.warn(
            f"the cached CasADi functions of the robot '{robot.name}' in {folder} could not be read (a damaged "
            "file: cut short or overwritten); they were generated again",
            CacheWarning,
            stacklevel=2,
        )
        folder = robot_function_dir(robot.spec, progress, rebuild=True)
        loaded = _load_functions(folder)
    funcs = RobotFunctions(
        robot=robot,
        folder=folder,
        friction_columns=friction_columns_function(robot.n),
        armature_columns=armature_columns_function(robot.n),
        **loaded,
    )
    _CACHE[robot.key] = funcs
    return funcs
