"""Excitation trajectory design: finite Fourier series optimised with IPOPT (METHOD.md, section 3).

The problem, for one trajectory of ``N`` harmonics per joint at base frequency ``ff``::

    minimise    J(H*)                         H* = Omega^-1/2 H, H = base regressor stacked over a grid
    subject to  q_min <= q(t) <= q_max,  |dq(t)| <= dq_max,  |ddq(t)| <= ddq_max   on the grid
                dq(0) = ddq(0) = 0  (hence at the end too: the series is periodic, q(0) = q(T))
                optional: tool above a floor (z >= z_min), tool inside a box

with ``J`` one of three criteria:

``seed``
    the paper's: ``w_H cond(H*) + w_h1 cond(H*_1) + w_h2 cond(H*_2)``, ``H*_1`` the gravity-related
    base columns, ``H*_2`` the others, the weights from the coefficient of variation of each column.
``cond``
    ``cond(H*)``.
``logdet``
    D-optimality: ``-log det(S H*^T H* S) / n_b`` with a fixed column scaling ``S``.

How the pieces are made
-----------------------
*Rest conditions as a parametrisation.*  ``dq(0) = 0`` is ``sum_l a_l = 0`` and ``ddq(0) = 0`` is
``sum_l l b_l = 0`` (per joint).  Rather than equality constraints, the decision variables are
coordinates in an orthonormal basis of those null spaces (``a = P_a y_a``, ``b = P_b y_b``), so the
conditions hold to rounding (1e-16) at every iterate and IPOPT sees inequalities only.

*Limits.*  Positions, velocities and accelerations are linear in the coefficients: on a fixed grid
they are linear constraints with a constant Jacobian.  The grid is only a sample of the period, so
the result is checked on a grid ``check_factor`` (10) times finer, plus the most a peak between two
of its points can add, ``max|x''| (h/2)^2 / 2`` (the acceleration bounds the overshoot of the
position, the jerk that of the velocity, the snap that of the acceleration): a trajectory that
passes meets its limits in continuous time.  One that fails is re-solved from its result (warm
start) with every limit of the failing kind tightened by the overshoot the optimisation grid can
hide under the same formula, and the failing ones by their excess on top; on UR5 and Panda one
re-solve is the rule, three the most seen without Cartesian limits.  Tightening only the failing
joints needed up to seven.

*The regressor* is the base regressor Function (Pinocchio on CasADi SX) mapped over the grid inside
an MX graph, ``A = H*^T H*`` formed with one dense product.  Measured on a UR5 (60 samples, 36 base
parameters): A in 0.4 ms, its reverse derivative in 1.5 ms; the same graph expanded to SX has 577k
instructions and a slower reverse pass (2.9 ms), so the graph stays MX.

*The condition number, smoothed.*  ``cond(H)^2 = lambda_max(A) / lambda_min(A)`` is not differentiable
where the extreme eigenvalues cross, and its gradient through an SVD of the tall H is what broke in
other toolkits on ill-conditioned regressors.  dynid works on the small ``A`` (n_b x n_b) and replaces
``log lambda_max`` and ``log lambda_min`` by their log-sum-exp soft versions::

    log lambda_max ~ (1/p) log sum_i lambda_i^p        (>= log lambda_max, by at most log(n_b)/p)
    log lambda_min ~ -(1/p) log sum_i lambda_i^-p      (<= log lambda_min, by at most log(n_b)/p)

Their difference is a symmetric, smooth function of the eigenvalues, hence (Lewis' theorem on
spectral functions) a smooth function of A even where eigenvalues coincide, with the exact gradient
``V diag(g'(lambda)) V^T`` from one symmetric eigendecomposition (``numpy.linalg.eigh`` of a
36 x 36 matrix: about 0.1 ms).  It bounds the exact cond from above, within a factor
``n_b^(1/p)``: with the default ``p = 16`` and 36 parameters, 1.25 on cond^2 and 1.12 on cond.
This sits in a CasADi Callback with an analytic Jacobian; IPOPT runs with a limited-memory Hessian.
Measured (criterion ``cond``, 8 random starts each, exact cond relative to the best of 100 random
feasible trajectories, mean / best)::

    p        UR5            Panda          IPOPT iterations
    4        0.36 / 0.33    0.34 / 0.31    140-170, a loose bound (n_b^(1/4) = 2.4 on cond^2)
    16       0.35 / 0.33    0.31 / 0.28    200-300
    64       0.35 / 0.32    -              300-450
    inf      0.36 / 0.33    0.32 / 0.30    every solve stops at the iteration limit: 3-4x the time

The exact extreme eigenvalues (p = inf) reach similar values but IPOPT never converges on them (the
gradient jumps where the smallest eigenvalues cross); p = 16 is the default.  Every figure reported
is the exact cond, from an SVD of the stacked H* on the fine grid (``--sharpness`` in
benchmarks/excitation_benchmark.py repeats the comparison).

*Iterative design* (the paper's): the k-th trajectory is optimised with the rows of the k-1 kept
ones stacked above its own (their ``A`` enters as a fixed parameter); each try starts from a random
feasible trajectory, a try is kept when it lowers the exact objective, the search ends after
``patience`` tries without improvement or ``max_tries``.

*Screening* (ours).  A try's criterion after 40 IPOPT iterations ranks it well enough: every try
stops there (``screen_iter``), the search above runs on those values, and only the best two
(``polish``) are continued to the end from their point and multipliers, with the limits checked and
tightened as above.  Measured on the UR5 (seed criterion, seed 0): the kept try is the same (#29 of
44) and the cond ratio 0.349 against 0.353, for 32 s of CPU instead of 155 s; over seeds 0-2 the
ratio is 0.349 / 0.335 / 0.326 (before: 0.353 / 0.325 / 0.346).  Screening at 30 iterations cost 21 s
and reached 0.367 on seed 0.  Tries run in parallel through joblib:
``joblib.parallel_config(backend="dask")`` around the call (or ``backend=``) spreads them on a cluster.

*Random feasible trajectories* (baseline and starts): coefficients drawn from a standard normal
in the null-space coordinates.  Per joint, the bounds on peak speed, peak acceleration and position
swing (max - min) over the period (check grid plus curvature term, as above) all scale linearly
with the amplitude, so each joint is scaled by the largest factor that keeps all three within its
limits; the offset c then places the swing inside the joint range, uniformly at random in the room
left.  Baseline trajectories use the full factor (each joint touches one of its limits), starts 0.9
of it (strictly inside, as an interior-point method likes).  With Cartesian limits, random
trajectories (amplitude 0.3-1) that break them are rejected.

*Weights of the seed criterion* (ours where the paper is silent): computed once per design from the
pooled H* of the random trajectories, so every try minimises the same function; ``|mean|`` is
floored at ``CV_MEAN_FLOOR`` times the column RMS (see :func:`dynid.optim.criteria.criterion_data`).

Where the pieces are
--------------------
This module runs the design (:func:`design_excitation`) and re-exports the public names of its parts:
the problem, its limits and the robot's numeric functions (:mod:`dynid.optim.problem`), the criteria
(:mod:`dynid.optim.criteria`), the IPOPT problem (:mod:`dynid.optim.nlp`), one try
(:mod:`dynid.optim.tries`), the random pool and the rank check (:mod:`dynid.optim.baseline`), the result
(:mod:`dynid.optim.results`) and the handling of signals during IPOPT (:mod:`dynid.optim.interrupts`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dynid._threads import one_blas_thread
from dynid.exceptions import ExcitationError, UsageError
from dynid.optim.baseline import check_rank, greedy_baseline, random_pool
from dynid.optim.criteria import (
    CRITERIA,
    CV_MEAN_FLOOR,
    CriterionData,
    criterion_data,
    exact_figures,
    information,
)
from dynid.optim.interrupts import check_stop, interruptible
from dynid.optim.problem import (
    MAX_HARMONICS,
    MIN_BASE_FREQ,
    CartesianLimits,
    ExcitationFunctions,
    ExcitationProblem,
    check_harmonics,
    excitation_functions,
)
from dynid.optim.results import ExcitationResult, StageRecord
from dynid.optim.trajectory import FourierTrajectory
from dynid.optim.tries import TryResult, solve_try

__all__ = [
    "CRITERIA",
    "CV_MEAN_FLOOR",
    "MAX_HARMONICS",
    "MIN_BASE_FREQ",
    "CartesianLimits",
    "ExcitationError",
    "ExcitationProblem",
    "ExcitationResult",
    "StageRecord",
    "check_harmonics",
    "design_excitation",
    "exact_figures",
]

SCREEN_ITER: int | None = 40
POLISH = 2

Progress = Callable[[str], None]


# joblib's process pool (loky) starts a resource tracker that shares the command's stderr.  When Ctrl-C
# reaches the whole process group, the tracker may outlive the command by a moment and warn of "leaked"
# semaphores that the command had already unlinked (the warning ends with a FileNotFoundError), after the
# command's one line.  The tracker is started with this interpreter's -W options: this one silences its
# warnings alone.  It still unlinks whatever did leak.
_QUIET_TRACKER = "ignore::UserWarning:joblib.externals.loky.backend.resource_tracker"
_IDLE_WORKER_S = 10  # a process pool's workers wait this long for work before they leave


def _parallel(n_jobs: int, backend: str | None):
    import sys

    import joblib

    if _QUIET_TRACKER not in sys.warnoptions:
        sys.warnoptions.append(_QUIET_TRACKER)
    if backend in (None, "loky"):  # idle workers leave after 10 s, not loky's 300 s: a killed design's too
        return joblib.Parallel(n_jobs=n_jobs, backend=backend, idle_worker_timeout=_IDLE_WORKER_S)
    return joblib.Parallel(n_jobs=n_jobs, backend=backend)


@one_blas_thread
def design_excitation(
    problem: ExcitationProblem,
    *,
    trajectories: int = 1,
    seed: int = 0,
    patience: int = 15,
    max_tries: int = 60,
    n_jobs: int = 2,
    backend: str | None = None,
    baseline: int = 100,
    max_rounds: int = 5,
    screen_iter: int | None = SCREEN_ITER,
    polish: int = POLISH,
    progress: Progress | None = None,
) -> ExcitationResult:
    """Design K excitation trajectories, one after the other, each complementing the earlier ones.

    Parameters
    ----------
    problem : ExcitationProblem
        Robot, series, criterion, grid and limits.
    trajectories : int
        Number K of trajectories (the paper's iterative design; 1 for a single trajectory).
    seed : int
        Seed of every random draw (baseline pool, starts); the same seed gives the same result,
        whatever ``n_jobs``.
    patience : int
        Tries without improvement after which the search for one trajectory stops (the paper: 15).
    max_tries : int
        Upper bound on the tries per trajectory.
    n_jobs : int
        Parallel tries (joblib); -1 for every core.
    backend : str, optional
        joblib backend ("loky", "threading", "dask", ...); default: joblib's, or the one set by an
        enclosing ``joblib.parallel_config``.
    baseline : int
        Size of the pool of random feasible trajectories the result is compared with (and from
        which the seed criterion's weights are computed).
    max_rounds : int
        Solves per try: the first, and re-solves with tightened limits while the check grid shows an
        overshoot between optimisation grid points.
    screen_iter : int or None
        IPOPT iterations of a screening solve (default :data:`SCREEN_ITER`): every try stops there, the
        search (``patience``, ``max_tries``) ranks the tries by the exact criterion at that point, and
        only the best ``polish`` are continued to the end (more, ``polish`` at a time, while none
        ends feasible).  None: every try is solved to the end, the search ranks finished tries.
    polish : int
        Screened tries continued to the end (default :data:`POLISH`).
    progress : callable, optional
        Receives one line of text per stage.

    Returns
    -------
    ExcitationResult

    Raises
    ------
    ExcitationError
        The regressor cannot reach full rank with these harmonics and grid, no random trajectory
        meets the Cartesian limits, or no try ends feasible.
    """
    if isinstance(seed, bool) or int(seed) != seed or seed < 0:
        raise UsageError(f"the seed is {seed}; give a whole number of at least 0.")
    if backend is not None:
        from joblib.parallel import BACKENDS, EXTERNAL_BACKENDS

        known = sorted({*BACKENDS, *EXTERNAL_BACKENDS})
        if backend not in known:
            raise UsageError(f"the joblib backend '{backend}' is unknown; give one of {', '.join(known)}.")
    with interruptible():
        return _design(
            problem,
            trajectories=trajectories,
            seed=seed,
            patience=patience,
            max_tries=max_tries,
            n_jobs=n_jobs,
            backend=backend,
            baseline=baseline,
            max_rounds=max_rounds,
            screen_iter=screen_iter,
            polish=polish,
            progress=progress,
        )


@dataclass(frozen=True, eq=False)
class _Search:
    """What every stage of one design shares: the problem, its functions, the criterion's data, the workers."""

    problem: ExcitationProblem
    functions: ExcitationFunctions
    data: CriterionData
    parallel: Any  # joblib.Parallel
    batch: int
    seed: int
    patience: int
    max_tries: int
    max_rounds: int
    screen_iter: int | None
    polish: int

    def figures(self, stack_fine: np.ndarray, traj: FourierTrajectory) -> dict[str, float]:
        """Exact figures of the kept trajectories' rows with those of ``traj`` below them."""
        H = np.vstack([stack_fine, self.problem.regressor(traj)])
        return exact_figures(H, self.problem.criterion, self.data, self.functions.gravity_related)


@dataclass(eq=False)
class _Found:
    """The search for one trajectory so far: the best try and its figures, the counts, the screened tries."""

    best: TryResult | None = None
    figures: dict[str, float] | None = None
    tries: int = 0
    feasible_tries: int = 0
    polished: int = 0
    last_status: str = ""
    screened: list[tuple[float, int, TryResult]] = field(default_factory=list)


@dataclass(eq=False)
class _Kept:
    """The trajectories kept so far, their rows H* on the check grid and their information on the optimisation grid."""

    trajectories: list[FourierTrajectory]
    stack_fine: np.ndarray
    prior: np.ndarray

    def add(self, problem: ExcitationProblem, traj: FourierTrajectory) -> None:
        self.trajectories.append(traj)
        self.stack_fine = np.vstack([self.stack_fine, problem.regressor(traj)])
        self.prior = self.prior + information(problem.regressor(traj, fine=False))


def _check_search(counts: dict[str, int], n_jobs: int) -> None:
    """Refuse counts of the search that are not whole numbers of at least 1, and an ``n_jobs`` of 0."""
    for label, value in counts.items():
        if int(value) != value or value < 1:
            raise UsageError(f"{label} is {value}; give a whole number of at least 1.")
    if n_jobs == 0 or int(n_jobs) != n_jobs:
        raise UsageError(f"n_jobs is {n_jobs}; give a positive number of parallel tries, or -1 for every core.")


def _baseline(
    problem: ExcitationProblem, functions: ExcitationFunctions, seed: int, size: int, trajectories: int
) -> tuple[CriterionData, float, float]:
    """The criterion's data from a pool of random feasible trajectories, and the best greedy stacks of the pool.

    Returns the data, the baseline cond and the baseline objective.
    """
    gravity = functions.gravity_related
    criterion = problem.criterion
    pool = random_pool(problem, functions, np.random.default_rng([seed, 0, 1]), size)
    pool_H = [problem.regressor(traj) for traj in pool]
    data = criterion_data(np.vstack(pool_H), gravity)
    # every pool trajectory's exact figures once (three SVDs each), for both greedy stacks' first step
    alone = [exact_figures(H, criterion, data, gravity) for H in pool_H]
    baseline_cond = greedy_baseline(pool_H, trajectories, "cond", data, gravity, alone)
    baseline_objective = greedy_baseline(pool_H, trajectories, criterion, data, gravity, alone)
    return data, baseline_cond, baseline_objective


def _search(search: _Search, stage: int, par: np.ndarray, stack_fine: np.ndarray) -> _Found:
    """Tries from random starts, a batch at a time, until ``patience`` tries in a row bring no improvement.

    With screening, every try stops after ``screen_iter`` iterations and the feasible ones are kept,
    ranked, for :func:`_polish`.
    """
    import joblib

    found = _Found()
    fails = 0
    while fails < search.patience and found.tries < search.max_tries:
        check_stop()  # a signal CasADi swallowed in this process (baseline, a try run here)
        size = min(search.batch, search.max_tries - found.tries)
        jobs = (
            joblib.delayed(solve_try)(
                search.problem,
                search.functions,
                par,
                (search.seed, stage, found.tries + i),
                found.tries + i,
                search.max_rounds,
                search.screen_iter,
            )
            for i in range(size)
        )
        for res in search.parallel(jobs):
            found.tries += 1
            found.last_status = res.status
            if res.feasible:
                found.feasible_tries += 1
                fig = search.figures(stack_fine, res.trajectory)
                if search.screen_iter is not None:
                    found.screened.append((fig["objective"], res.index, res))
                if found.figures is None or fig["objective"] < found.figures["objective"]:
                    found.best, found.figures, fails = res, fig, 0
                    continue
            fails += 1
            if fails >= search.patience:
                break  # the rest of this batch is discarded: the result does not depend on n_jobs
    return found


def _polish(search: _Search, par: np.ndarray, stack_fine: np.ndarray, found: _Found) -> None:
    """Continue the screened tries, best first, to the end (limits checked) by batches of ``polish``.

    The best feasible one of the first batch that has one replaces the screening's best in ``found``.
    """
    import joblib

    found.screened.sort(key=lambda item: (item[0], item[1]))
    found.best = found.figures = None
    for first in range(0, len(found.screened), search.polish):
        check_stop()
        jobs = (
            joblib.delayed(solve_try)(
                search.problem, search.functions, par, None, item[2].index, search.max_rounds, None, item[2]
            )
            for item in found.screened[first : first + search.polish]
        )
        for res in search.parallel(jobs):
            found.polished += 1
            found.last_status = res.status
            if not res.feasible:
                continue
            fig = search.figures(stack_fine, res.trajectory)
            if found.figures is None or fig["objective"] < found.figures["objective"]:
                found.best, found.figures = res, fig
        if found.best is not None:
            break


def _design_stage(search: _Search, stage: int, kept: _Kept) -> tuple[StageRecord, dict[str, float]]:
    """Trajectory ``stage`` searched (and polished) over the kept ones, added to them; its record and figures."""
    t_stage = time.perf_counter()
    data = search.data
    par = np.concatenate([kept.prior.ravel(order="F"), data.weights, data.scale])
    found = _search(search, stage, par, kept.stack_fine)
    if search.screen_iter is not None:
        _polish(search, par, kept.stack_fine, found)
    best, best_fig = found.best, found.figures
    if best is None or best_fig is None:
        raise ExcitationError(
            f"none of {found.tries} optimisations of trajectory {stage} met every limit of "
            f"'{search.problem.robot.name}' on the check grid (last IPOPT status: {found.last_status}); loosen the "
            "limits or the Cartesian constraints, or allow more tries (max_tries) and rounds (max_rounds)."
        )
    check_stop()
    start_fig = search.figures(kept.stack_fine, best.start)
    kept.add(search.problem, best.trajectory)
    record = StageRecord(
        tries=found.tries,
        kept=best.index,
        feasible_tries=found.feasible_tries,
        polished=found.polished,
        start_cond=start_fig["cond"],
        cond=best_fig["cond"],
        start_objective=start_fig["objective"],
        objective=best_fig["objective"],
        status=best.status,
        iterations=best.iterations,
        rounds=best.rounds,
        seconds=time.perf_counter() - t_stage,
    )
    return record, best_fig


def _result(
    search: _Search,
    kept: _Kept,
    stages: list[StageRecord],
    final: dict[str, float],
    baseline: tuple[float, float],
    t_start: float,
) -> ExcitationResult:
    """The design's result: the kept trajectories with their metadata, the final and baseline figures."""
    problem, data = search.problem, search.data
    feasible = all(problem.is_feasible(t, search.functions) for t in kept.trajectories)
    metas = []
    for k, traj in enumerate(kept.trajectories):
        meta = {
            "robot": problem.robot.name,
            "criterion": problem.criterion,
            "index": k + 1,
            "of": len(kept.trajectories),
            "cond_stack": stages[k].cond,
            "cond": float(np.linalg.cond(problem.regressor(traj))),
            "noise_std": problem.noise_std.tolist(),
            "seed": search.seed,
        }
        metas.append(FourierTrajectory(a=traj.a, b=traj.b, c=traj.c, base_freq=traj.base_freq, meta=meta))
    weights = {
        "w_H": float(data.weights[0]),
        "w_h1": float(data.weights[1]),
        "w_h2": float(data.weights[2]),
        "columns": data.column_weights.tolist(),
    }
    return ExcitationResult(
        problem=problem,
        trajectories=tuple(metas),
        cond=final["cond"],
        objective=final["objective"],
        cond_gravity=final["cond_gravity"],
        cond_motion=final["cond_motion"],
        baseline_cond=baseline[0],
        baseline_objective=baseline[1],
        feasible=feasible,
        stages=tuple(stages),
        weights=weights,
        seconds=time.perf_counter() - t_start,
        seed=search.seed,
    )


def _design(
    problem: ExcitationProblem,
    *,
    trajectories: int,
    seed: int,
    patience: int,
    max_tries: int,
    n_jobs: int,
    backend: str | None,
    baseline: int,
    max_rounds: int,
    screen_iter: int | None,
    polish: int,
    progress: Progress | None,
) -> ExcitationResult:
    """The design, in steps: checks, baseline pool, then one search (and polish) per trajectory."""
    t_start = time.perf_counter()
    counts = {"trajectories": trajectories, "patience": patience, "max_tries": max_tries, "baseline": baseline}
    counts.update(max_rounds=max_rounds, polish=polish, screen_iter=1 if screen_iter is None else screen_iter)
    _check_search(counts, n_jobs)
    import joblib

    functions = excitation_functions(problem)
    check_rank(problem, functions, np.random.default_rng([seed, 0, 0]))
    data, baseline_cond, baseline_objective = _baseline(problem, functions, seed, baseline, trajectories)
    batch = max(1, joblib.effective_n_jobs(n_jobs))
    search = _Search(
        problem=problem,
        functions=functions,
        data=data,
        parallel=_parallel(n_jobs, backend),
        batch=batch,
        seed=seed,
        patience=patience,
        max_tries=max_tries,
        max_rounds=max_rounds,
        screen_iter=screen_iter,
        polish=polish,
    )
    nb = functions.n_base
    kept = _Kept(trajectories=[], stack_fine=np.zeros((0, nb)), prior=np.zeros((nb, nb)))
    stages: list[StageRecord] = []
    final = None
    for stage in range(1, trajectories + 1):
        record, final = _design_stage(search, stage, kept)
        stages.append(record)
        if progress:
            progress(
                f"trajectory {stage}/{trajectories}: cond {record.start_cond:.4g} (random start) -> "
                f"{record.cond:.4g}, {problem.criterion} {record.objective:.4g}; {record.tries} tries, kept "
                f"#{record.kept + 1}, {record.seconds:.1f} s"
            )
    assert final is not None
    return _result(search, kept, stages, final, (baseline_cond, baseline_objective), t_start)
