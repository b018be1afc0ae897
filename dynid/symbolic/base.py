"""Base (minimal) inertial parameters by QR decomposition with column pivoting.

The regressor ``Y`` (n x 10n) is stacked over random states ``W`` (m n x 10n).  QR with column
pivoting reveals its rank ``n_b``; the independent columns ``W_1`` and the dependent ones ``W_2``
satisfy ``W_2 = W_1 K`` for every state, so ``Y pi = Y_b beta`` with

    beta = pi_b + K pi_d          (the base parameters)
    Y_b  = Y[:, independent]      (the base regressor)

Zero columns (parameters that never act) are dependent with a zero column of ``K``.  The
gravity-related base columns are those that do not vanish when ``dq = ddq = 0``: the excitation
criterion weights them separately.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import casadi as ca
import numpy as np
import scipy.linalg

from dynid.exceptions import ShapeError
from dynid.symbolic.functions import RobotFunctions

__all__ = ["BaseParameters", "base_parameters"]

RANK_TOL = 1e-9
"""Relative tolerance on the diagonal of R that separates independent from dependent columns.

On the built-in robots the diagonal drops from about 1e-1 to below 1e-14 (relative) at the rank,
so the split does not depend on this value within many orders of magnitude."""


@dataclass(frozen=True, eq=False)
class BaseParameters:
    """The base parameters of a robot and the map from the standard parameters.

    Attributes
    ----------
    standard_names : tuple of str
        Names of the 10 n standard parameters (``m1, mx1, ..., Izz_n``).
    independent, dependent : ndarray of int
        Indices (into the standard parameters) of the independent and the dependent columns.
    K : ndarray, shape (n_b, n_d)
        ``beta = pi[independent] + K @ pi[dependent]``.
    gravity_related : ndarray of bool, shape (n_b,)
        Base columns that act when the robot stands still (gravity), the others only in motion.
    base_regressor : casadi.Function
        ``base_regressor(q, dq, ddq) -> Yb`` of shape (n, n_b).
    """

    robot_name: str
    standard_names: tuple[str, ...]
    independent: np.ndarray
    dependent: np.ndarray
    K: np.ndarray
    gravity_related: np.ndarray
    base_regressor: ca.Function

    @property
    def n_base(self) -> int:
        return len(self.independent)

    @property
    def n_standard(self) -> int:
        return len(self.standard_names)

    @cached_property
    def matrix(self) -> np.ndarray:
        """B of shape (n_b, 10 n) with ``beta = B @ pi``."""
        B = np.zeros((self.n_base, self.n_standard))
        B[np.arange(self.n_base), self.independent] = 1.0
        B[:, self.dependent] = self.K
        return B

    @cached_property
    def names(self) -> tuple[str, ...]:
        """Short name of each base parameter: the independent standard parameter, suffixed ``R``
        when others are regrouped into it (``Izz1R``)."""
        regrouped = np.any(self.K != 0, axis=1)
        return tuple(
            self.standard_names[i] + ("R" if regrouped[k] else "") for k, i in enumerate(self.independent)
        )

    @cached_property
    def expressions(self) -> tuple[str, ...]:
        """Readable expression of each base parameter, e.g. ``Izz1 + Iyy2 + 0.180625*m2``."""
        out = []
        for k, i in enumerate(self.independent):
            text = self.standard_names[i]
            for j, coef in zip(self.dependent, self.K[k], strict=True):
                if coef == 0:
                    continue
                name = self.standard_names[j]
                shown = f"{abs(coef):.6g}"
                if shown == "1":  # 1 to the six digits shown (1 - 4e-8 on an arm with rounded angles)
                    text += f" {'-' if coef < 0 else '+'} {name}"
                else:
                    text += f" {'-' if coef < 0 else '+'} {shown}*{name}"
            out.append(text)
        return tuple(out)

    @cached_property
    def identifiable(self) -> np.ndarray:
        """Boolean mask (10 n,): standard parameters that are a base parameter on their own.

        Only these have a unique value given the base parameters; every other standard parameter
        is unidentifiable alone (it is regrouped, or never acts)."""
        mask = np.zeros(self.n_standard, dtype=bool)
        alone = ~np.any(self.K != 0, axis=1)
        mask[self.independent[alone]] = True
        # A dependent parameter with a zero column of K never acts: not identifiable either.
        return mask

    def to_base(self, params: np.ndarray) -> np.ndarray:
        """Base parameters ``beta`` of standard parameters ``params``: shape (10 n,) -> (n_b,)."""
        params = np.asarray(params, dtype=float)
        if params.shape[-1] != self.n_standard:
            raise ShapeError(
                f"the standard parameters have {params.shape[-1]} values; the robot '{self.robot_name}' has "
                f"{self.n_standard} (10 per link)."
            )
        return params @ self.matrix.T

    def to_standard(self, beta: np.ndarray, reference: np.ndarray | None = None) -> np.ndarray:
        """A standard parameter vector with base parameters ``beta``.

        The map from standard to base parameters has no inverse; this returns the vector closest (in
        the Euclidean norm) to ``reference`` (e.g. the CAD values of the URDF) among all those with
        ``to_base(pi) == beta``.  Without a reference, the minimum-norm vector.  Physical consistency
        is not enforced here (the consistent estimator of the identification does that).
        """
        beta = np.asarray(beta, dtype=float)
        if beta.shape != (self.n_base,):
            raise ShapeError(
                f"beta has shape {beta.shape}; the robot '{self.robot_name}' has {self.n_base} base parameters."
            )
        ref = np.zeros(self.n_standard) if reference is None else np.asarray(reference, dtype=float)
        B = self.matrix
        correction = np.linalg.lstsq(B, beta - B @ ref, rcond=None)[0]
        return ref + correction

    def evaluate(self, q, dq, ddq) -> np.ndarray:
        """Y_b for a batch through the CasADi virtual machine: shape (m, n, n_b)."""
        q, dq, ddq = (np.atleast_2d(np.asarray(v, dtype=float)) for v in (q, dq, ddq))
        m, n = q.shape
        out = np.asarray(self.base_regressor.map(m)(q.T, dq.T, ddq.T))
        return out.reshape(n, m, self.n_base).transpose(1, 0, 2)

    def table(self) -> list[dict]:
        """One row per base parameter: name, expression, gravity-related."""
        return [
            {"name": name, "expression": expr, "gravity_related": bool(g)}
            for name, expr, g in zip(self.names, self.expressions, self.gravity_related, strict=True)
        ]


def random_states(robot, m: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """States drawn uniformly within the joint limits (positions, speeds, accelerations)."""
    q = rng.uniform(robot.q_min, robot.q_max, size=(m, robot.n))
    dq = rng.uniform(-1.0, 1.0, size=(m, robot.n)) * robot.dq_max
    ddq = rng.uniform(-1.0, 1.0, size=(m, robot.n)) * robot.ddq_max
    return q, dq, ddq


def _split_states(robot, m: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """States for the rank-revealing QR, drawn from a distribution that depends on the joint types only.

    Not on the joint limits: the choice of independent columns (hence the names and the values of
    the base parameters) must be the same for a robot whatever limits a user sets, or a model
    identified on a slowed robot would not match the same robot loaded again.
    """
    revolute = np.array([j.revolute for j in robot.joints])
    span = np.where(revolute, np.pi, 0.5)  # rad, or m for a prismatic joint
    q = rng.uniform(-1.0, 1.0, size=(m, robot.n)) * span
    dq = rng.uniform(-1.0, 1.0, size=(m, robot.n)) * 2.0
    ddq = rng.uniform(-1.0, 1.0, size=(m, robot.n)) * 10.0
    return q, dq, ddq


_MEMO: dict[tuple, BaseParameters] = {}


def base_parameters(funcs: RobotFunctions, *, samples: int | None = None, seed: int = 0) -> BaseParameters:
    """Compute the base parameters of a robot.

    Parameters
    ----------
    funcs : RobotFunctions
        The robot's CasADi functions (:func:`dynid.symbolic.robot_functions`).
    samples : int, optional
        Number of random states stacked (default ``max(200, 40 n)``).
    seed : int
        Seed of the random states; the rank is the same for any seed, the fixed default makes the
        choice of independent columns repeatable.  The states do not depend on the joint limits, and
        the result is kept per process for each tree (:attr:`RobotModel.key`).
    """
    robot = funcs.robot
    n = robot.n
    m = samples or max(200, 40 * n)
    memo_key = (robot.key, m, seed)
    if memo_key in _MEMO:  # the split depends on the tree only (see _split_states)
        return _MEMO[memo_key]
    rng = np.random.default_rng(seed)
    q, dq, ddq = _split_states(robot, m, rng)
    W = funcs.regressor_numeric(q, dq, ddq).reshape(m * n, 10 * n)
    _, R, perm = scipy.linalg.qr(W, mode="economic", pivoting=True)
    diag = np.abs(np.diag(R))
    rank = int(np.sum(diag > RANK_TOL * diag[0])) if diag[0] > 0 else 0
    independent = np.sort(perm[:rank])
    dependent = np.sort(perm[rank:])
    W1, W2 = W[:, independent], W[:, dependent]
    K = np.linalg.lstsq(W1, W2, rcond=None)[0] if len(dependent) else np.zeros((rank, 0))
    scale = max(1.0, float(np.abs(K).max(initial=0.0)))
    K[np.abs(K) < 1e-10 * scale] = 0.0

    # Gravity-related base columns: the ones that do not vanish at rest.
    Wg = funcs.regressor_numeric(q, np.zeros_like(dq), np.zeros_like(ddq)).reshape(m * n, 10 * n)
    gnorm = np.linalg.norm(Wg[:, independent], axis=0)
    gravity_related = gnorm > 1e-9 * np.linalg.norm(W1, axis=0)

    qs, dqs, ddqs = (ca.SX.sym(name, n) for name in ("q", "dq", "ddq"))
    Yb = funcs.regressor(qs, dqs, ddqs)[:, independent.tolist()]
    base = ca.Function("base_regressor", [qs, dqs, ddqs], [ca.densify(Yb)], ["q", "dq", "ddq"], ["Yb"])
    result = BaseParameters(
        robot_name=robot.name,
        standard_names=robot.param_names,
        independent=independent,
        dependent=dependent,
        K=K,
        gravity_related=gravity_related,
        base_regressor=base,
    )
    _MEMO[memo_key] = result
    return result
