"""One try of an excitation design: a random start optimised, checked on the fine grid, tightened, re-solved.

A screening try stops after a few IPOPT iterations and is not checked; a screened try is continued to the
end from its point and multipliers (:func:`solve_try`).  Tries run in joblib's workers: everything they
take and return is picklable.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from dynid.optim.interrupts import check_stop, interruptible
from dynid.optim.nlp import excitation_nlp
from dynid.optim.problem import ExcitationFunctions, ExcitationProblem, fourier_series, meets_limits
from dynid.optim.trajectory import FourierTrajectory

__all__ = ["TryResult", "solve_try"]


def _hidden_overshoot(problem: ExcitationProblem, traj: FourierTrajectory) -> dict[str, np.ndarray]:
    """Largest overshoot between optimisation grid points that the curvature of ``traj`` allows.

    A quantity x peaking between two samples h apart sits at most ``max|x''| (h/2)^2 / 2`` above the
    nearer sample: positions by the acceleration, velocities by the jerk, accelerations by the snap.
    """
    h = problem.period / problem.grid
    k = 0.5 * (0.5 * h) ** 2
    _, _, ddq, jerk, snap = fourier_series(problem, traj.a, traj.b, problem.times(fine=True))
    q_margin = k * np.abs(ddq).max(axis=0)
    return {
        "q_low": q_margin,
        "q_high": q_margin,
        "dq": k * np.abs(jerk).max(axis=0),
        "ddq": k * np.abs(snap).max(axis=0),
        "cart_low": np.zeros(3),
        "cart_high": np.zeros(3),
    }


@dataclass(frozen=True, eq=False)
class TryResult:
    """The outcome of one try: its random start, its result, and the multipliers a screening solve ended with."""

    index: int
    start: FourierTrajectory
    trajectory: FourierTrajectory
    feasible: bool
    status: str
    iterations: int
    rounds: int
    seconds: float
    multipliers: tuple[np.ndarray, np.ndarray] | None = None


def solve_try(
    problem: ExcitationProblem,
    functions: ExcitationFunctions,
    par: np.ndarray,
    seed: tuple[int, ...],
    index: int,
    max_rounds: int,
    screen_iter: int | None = None,
    screened: TryResult | None = None,
) -> TryResult:
    """Optimise from one random start; tighten and re-solve while the check grid shows an overshoot.

    ``screen_iter``: one solve of at most that many iterations, nothing checked (a screening pass).
    ``screened``: continue that screening result (its point and multipliers) to the end instead.
    """
    with interruptible():
        if screen_iter is not None:
            return _screen_try(problem, functions, par, seed, index, screen_iter)
        return _solve_try_guarded(problem, functions, par, seed, index, max_rounds, screened)


def _screen_try(
    problem: ExcitationProblem,
    functions: ExcitationFunctions,
    par: np.ndarray,
    seed: tuple[int, ...],
    index: int,
    screen_iter: int,
) -> TryResult:
    t0 = time.perf_counter()
    start = problem.random_trajectory(np.random.default_rng(list(seed)), amplitude=0.9)
    nlp = excitation_nlp(problem, functions)
    zero = {key: np.zeros(problem.n) for key in ("q_low", "q_high", "dq", "ddq")}
    zero.update(cart_low=np.zeros(3), cart_high=np.zeros(3))
    y, status, it = nlp.solve(problem.to_vector(start), par, zero, max_iter=screen_iter)
    check_stop()
    finite = bool(np.all(np.isfinite(y)))
    return TryResult(
        index=index,
        start=start,
        trajectory=problem.to_trajectory(y) if finite else start,
        feasible=finite,  # worth continuing; the limits are checked after the full solve
        status=status,
        iterations=it,
        rounds=1,
        seconds=time.perf_counter() - t0,
        multipliers=nlp.multipliers,
    )


def _solve_try_guarded(
    problem: ExcitationProblem,
    functions: ExcitationFunctions,
    par: np.ndarray,
    seed: tuple[int, ...],
    index: int,
    max_rounds: int,
    screened: TryResult | None = None,
) -> TryResult:
    t0 = time.perf_counter()
    if screened is None:
        start = problem.random_trajectory(np.random.default_rng(list(seed)), amplitude=0.9)
    else:
        start = screened.start
    nlp = excitation_nlp(problem, functions)
    robot = problem.robot
    margins = {
        "q_low": np.zeros(robot.n),
        "q_high": np.zeros(robot.n),
        "dq": np.zeros(robot.n),
        "ddq": np.zeros(robot.n),
        "cart_low": np.zeros(3),
        "cart_high": np.zeros(3),
    }
    extra = {
        "q_low": 1e-7 * (robot.q_max - robot.q_min),
        "q_high": 1e-7 * (robot.q_max - robot.q_min),
        "dq": 1e-7 * robot.dq_max,
        "ddq": 1e-7 * robot.ddq_max,
        "cart_low": np.full(3, 1e-7),
        "cart_high": np.full(3, 1e-7),
    }
    y = problem.to_vector(start if screened is None else screened.trajectory)
    status, iterations, feasible = "not run", 0 if screened is None else screened.iterations, False
    traj = start
    rounds = 0
    for rounds in range(1, max_rounds + 1):
        if rounds == 1 and screened is not None:
            y, status, it = nlp.solve(y, par, margins, warm=True, multipliers=screened.multipliers)
        else:
            y, status, it = nlp.solve(y, par, margins, warm=rounds > 1)
        check_stop()
        iterations += it
        if not np.all(np.isfinite(y)):
            break
        traj = problem.to_trajectory(y)
        viol = problem.violations(traj, functions)
        if meets_limits(robot, viol):
            feasible = True
            break
        # Tighten every limit of a violated kind (positions, speeds, ...) to the overshoot the grid can
        # hide given the curvature of this solution, and violated ones by their excess on top: the
        # optimum moves when re-solved, so tightening only the violated joints needed up to 7 rounds
        # on UR5, this at most 3.
        hidden = _hidden_overshoot(problem, traj)
        for key, value in viol.items():
            bad = value > 0
            if np.any(bad):
                margins[key] = np.maximum(margins[key] + np.where(bad, 1.2 * value, 0.0), hidden[key]) + np.where(
                    bad, extra[key], 0.0
                )
    return TryResult(
        index=index,
        start=start,
        trajectory=traj,
        feasible=feasible,
        status=status,
        iterations=iterations,
        rounds=rounds,
        seconds=time.perf_counter() - t0,
    )
