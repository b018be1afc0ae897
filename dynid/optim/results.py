"""What an excitation design returns: the trajectories, the figures that judge them, one record per stage."""

from __future__ import annotations

from dataclasses import dataclass, field

from dynid.optim.problem import ExcitationProblem, excitation_functions
from dynid.optim.trajectory import FourierTrajectory

__all__ = ["ExcitationResult", "StageRecord"]


@dataclass(frozen=True, eq=False, kw_only=True)
class StageRecord:
    """What happened while designing the k-th trajectory.

    Attributes
    ----------
    tries : int
        Optimisations run (random starts) before the search stopped.
    kept : int
        Index of the try kept (0-based).
    feasible_tries : int
        Tries whose result met every limit on the check grid (with screening, the screened result).
    polished : int
        Screened tries continued to the end (0 without screening).
    start_cond, cond : float
        Exact cond of the stack (earlier trajectories and this one) at the kept try's random start
        and at its result.
    start_objective, objective : float
        The criterion's exact value at the start and at the result.
    status : str
        IPOPT's return status of the kept try.
    iterations, rounds : int
        IPOPT iterations and solves (tightening rounds) of the kept try.
    seconds : float
        Wall time of the stage.
    """

    tries: int
    kept: int
    feasible_tries: int
    start_cond: float
    cond: float
    start_objective: float
    objective: float
    status: str
    iterations: int
    rounds: int
    seconds: float
    polished: int = 0

    def to_dict(self) -> dict:
        return {name: getattr(self, name) for name in self.__dataclass_fields__}


@dataclass(frozen=True, eq=False, kw_only=True)
class ExcitationResult:
    """An excitation design: the trajectories and the figures that judge them.

    Attributes
    ----------
    problem : ExcitationProblem
        What was asked.
    trajectories : tuple of FourierTrajectory
        The K trajectories, in the order designed (each complements the earlier ones).
    cond : float
        Exact condition number (SVD) of H* stacked over all trajectories on the check grid.
    objective : float
        The criterion's exact value for the stack.
    baseline_cond, baseline_objective : float
        The lowest cond and the best value of the criterion among the random feasible trajectories
        (for K > 1, stacks of K chosen greedily from the pool, each step minimising that figure).
    cond_gravity, cond_motion : float
        Exact cond of the gravity-related columns H*_1 and of the others H*_2 (0 when a group is empty).
    feasible : bool
        Every trajectory meets every limit over its whole period (check grid and curvature bound).
    stages : tuple of StageRecord
        One record per trajectory.
    weights : dict
        The seed criterion's weights ``w_H, w_h1, w_h2`` and the column weights.
    seconds : float
        Wall time of the whole design.
    seed : int
        The seed of the design.
    """

    problem: ExcitationProblem
    trajectories: tuple[FourierTrajectory, ...]
    cond: float
    objective: float
    cond_gravity: float
    cond_motion: float
    baseline_cond: float
    baseline_objective: float
    feasible: bool
    stages: tuple[StageRecord, ...]
    weights: dict = field(default_factory=dict)
    seconds: float = 0.0
    seed: int = 0

    @property
    def criterion(self) -> str:
        return self.problem.criterion

    @property
    def start_cond(self) -> float:
        """Exact cond of the first trajectory's random start (alone)."""
        return self.stages[0].start_cond

    def to_dict(self) -> dict:
        """The figures (``dynid excite --json``)."""
        problem = self.problem
        robot = problem.robot
        return {
            "robot": robot.name,
            "criterion": problem.criterion,
            "cond": self.cond,
            "objective": self.objective,
            "cond_gravity": self.cond_gravity,
            "cond_motion": self.cond_motion,
            "baseline_cond": self.baseline_cond,
            "baseline_objective": self.baseline_objective,
            "cond_ratio": self.cond / self.baseline_cond,
            "start_cond": self.start_cond,
            "feasible": self.feasible,
            "trajectories": len(self.trajectories),
            "harmonics": problem.harmonics,
            "base_freq": problem.base_freq,
            "grid": problem.grid,
            "check_grid": problem.grid * problem.check_factor,
            "noise_std": problem.noise_std.tolist(),
            "sharpness": problem.sharpness,
            "cartesian": None if problem.cartesian is None else problem.cartesian.to_dict(),
            "n_base": int(excitation_functions(problem).n_base),
            "weights": self.weights,
            "stages": [s.to_dict() for s in self.stages],
            "seconds": self.seconds,
            "seed": self.seed,
            "limits": {
                "q_min": robot.q_min.tolist(),
                "q_max": robot.q_max.tolist(),
                "dq_max": robot.dq_max.tolist(),
                "ddq_max": robot.ddq_max.tolist(),
            },
        }
