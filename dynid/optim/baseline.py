"""Random trajectories around an excitation design: the rank check, the feasible pool, its greedy stacks.

The pool of random feasible trajectories gives the seed criterion's weights and the baseline the result is
compared with (``baseline_cond``: for K trajectories, stacks of K chosen greedily from the pool).
"""

from __future__ import annotations

import math

import numpy as np

from dynid.exceptions import ExcitationError
from dynid.optim.criteria import CriterionData, exact_figures
from dynid.optim.problem import ExcitationFunctions, ExcitationProblem
from dynid.optim.trajectory import FourierTrajectory

__all__ = ["check_rank", "greedy_baseline", "random_pool"]


def check_rank(problem: ExcitationProblem, functions: ExcitationFunctions, rng: np.random.Generator) -> None:
    """Raise when a generic trajectory of this problem cannot excite every base parameter."""
    nb = functions.n_base
    n, m, harmonics = problem.n, problem.grid, problem.harmonics
    where = f"with {harmonics} harmonic{'s' if harmonics != 1 else ''} and {m} grid points"
    if m * n < nb:
        raise ExcitationError(
            f"{where} the base regressor has {m * n} rows for {nb} base parameters of '{problem.robot.name}'; "
            f"use at least {-(-nb // n)} grid points per period."
        )
    H = problem.regressor(problem.random_trajectory(rng), fine=False)
    sv = np.linalg.svd(H, compute_uv=False)
    rank = int(np.sum(sv > sv[0] * max(H.shape) * np.finfo(float).eps)) if sv[0] > 0 else 0
    if rank < nb:
        fix = (
            "use at least 2 harmonics (the rest conditions dq(0) = ddq(0) = 0 leave a single harmonic motionless)"
            if harmonics < 2
            else "use more harmonics or more grid points"
        )
        raise ExcitationError(
            f"{where} the base regressor of '{problem.robot.name}' reaches rank {rank} of {nb}: these "
            f"trajectories cannot excite every base parameter; {fix}."
        )


def random_pool(
    problem: ExcitationProblem, functions: ExcitationFunctions, rng: np.random.Generator, size: int
) -> list[FourierTrajectory]:
    """``size`` random trajectories that meet every limit on the check grid (Cartesian ones by rejection)."""
    pool: list[FourierTrajectory] = []
    cart = problem.cartesian is not None and problem.cartesian.active
    attempts = 0
    while len(pool) < size:
        attempts += 1
        if attempts > 50 * size:
            raise ExcitationError(
                f"none of {attempts - 1} random trajectories within the joint limits of '{problem.robot.name}' "
                "keeps the tool inside the Cartesian limits; check z_min and the box (base frame, metres) or "
                "the joint ranges."
                if not pool
                else f"only {len(pool)} of {attempts - 1} random trajectories meet the Cartesian limits; "
                "loosen them or ask for fewer baseline trajectories."
            )
        traj = problem.random_trajectory(rng, amplitude=1.0 if not cart else rng.uniform(0.3, 1.0))
        if not cart or problem.is_feasible(traj, functions):
            pool.append(traj)
    return pool


def greedy_baseline(
    pool_H: list[np.ndarray],
    count: int,
    criterion: str,
    data: CriterionData,
    gravity: np.ndarray,
    alone: list[dict[str, float]] | None = None,
) -> float:
    """Best value of ``criterion`` over stacks of ``count`` pool trajectories, chosen one at a time.

    ``alone``: the :func:`exact_figures` of each pool trajectory by itself (the first step's values),
    when already computed.
    """
    stack = np.zeros((0, pool_H[0].shape[1]))
    best = math.inf
    for step in range(count):
        if step == 0 and alone is not None:
            key = "cond" if criterion == "cond" else "objective"
            values = [fig[key] if math.isfinite(fig["cond"]) else math.inf for fig in alone]
        else:
            values = [
                exact_figures(np.vstack([stack, H]), criterion, data, gravity)["objective"] for H in pool_H
            ]
        k = int(np.argmin(values))
        stack = np.vstack([stack, pool_H[k]])
        best = values[k]
    return float(best)
