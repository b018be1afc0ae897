"""A short motion that determines a payload: for robot cells where a full excitation is not allowed.

One period of a finite Fourier series per joint (``T`` at most :data:`MAX_DURATION` s), starting and
ending at rest at a given pose (``q(0) = q(T) = pose``, ``dq = ddq = 0`` there), within the joint
limits (positions with a margin, a fraction of the velocity and acceleration limits).  It is designed
by IPOPT for the payload's ten parameters alone (the arm's model is known): the payload's columns of
the regressor, ``A(q, dq, ddq) = Y(q, dq, ddq)[:, link] T`` (the carrying link's ten columns moved to
frame F, :func:`dynid.symbolic.bodies.frame_transform`), give the information ``F = sum A^T A / s^2``
over the grid, and the criterion is A-optimality in the units the payload identification decides
determinacy in (:data:`dynid.identify.payload.LENGTH`: mass, mass x 10 cm, mass x (10 cm)^2)::

    minimise  log trace (S F S)^-1       S = diag(1, L, L, L, L^2, ..., L^2)

the sum of the ten parameters' variances, each in its own unit: the weakest direction dominates, which
is what decides whether the inertia comes out or is reported undetermined.  The rest conditions are a
parametrisation (as in :mod:`dynid.optim.excitation`: orthonormal null-space coordinates), the start pose
fixes the offsets, the limits are linear constraints on the grid; the result is checked on a grid ten
times finer with the bound on what a peak between its points can add, and shrunk toward the pose until
it passes.  A few random starts; the best is kept.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from dynid._progress import advance, say
from dynid.exceptions import UsageError
from dynid.optim.excitation import ExcitationProblem
from dynid.optim.trajectory import FourierTrajectory

__all__ = ["MAX_DURATION", "PayloadMotion", "design_payload_motion", "payload_information"]

MAX_DURATION = 15.0
"""The longest payload motion (s)."""

_LENGTH = 0.1  # m: the payload's length scale (as dynid.identify.payload.LENGTH)
_MARGIN = 0.05  # fraction of each joint's range kept free at both ends
_NAMES = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")


def _scale() -> NDArray[np.float64]:
    return np.array([1.0, *(3 * [_LENGTH]), *(6 * [_LENGTH**2])])


@dataclass(frozen=True)
class PayloadMotion:
    """A designed payload motion.

    Attributes
    ----------
    trajectory : FourierTrajectory
        One period, at rest at ``pose`` at both ends.
    pose : ndarray, shape (n,)
    relative_std : ndarray, shape (10,)
        Each payload parameter's standard deviation at unit torque noise per sample of the check grid,
        in its unit (1 kg, 1 kg x 10 cm, 1 kg x (10 cm)^2): smaller is better; comparable between motions.
    cond : float
        Condition number of the scaled payload information.
    baseline_cond : float
        The same of the best random feasible motion from the same pose.
    feasible : bool
    seconds : float
    """

    trajectory: FourierTrajectory
    pose: NDArray[np.float64]
    relative_std: NDArray[np.float64]
    cond: float
    baseline_cond: float
    feasible: bool
    seconds: float
    meta: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The JSON figures."""
        return {
            "criterion": "payload",
            "cond": float(self.cond),
            "baseline_cond": float(self.baseline_cond),
            "objective": float(np.log(np.sum(self.relative_std**2))),
            "relative_std": {k: float(v) for k, v in zip(_NAMES, self.relative_std, strict=True)},
            "pose": [float(v) for v in self.pose],
            "duration_s": float(1.0 / self.trajectory.base_freq),
            "feasible": bool(self.feasible),
            "seconds": float(self.seconds),
        }


def _payload_columns_function(robot, link: int, T: NDArray[np.float64]) -> ca.Function:
    """CasADi ``(q, dq, ddq) -> (n, 10)``: the payload's columns (F's ten parameters) at one state."""
    from dynid.symbolic.functions import robot_functions

    funcs = robot_functions(robot, progress=None)
    q, dq, ddq = (ca.SX.sym(name, robot.n) for name in ("q", "dq", "ddq"))
    Y = funcs.regressor(q, dq, ddq)[:, 10 * link : 10 * link + 10]
    return ca.Function("payload_columns", [q, dq, ddq], [ca.mtimes(Y, ca.DM(T))])


def payload_information(
    robot, traj: FourierTrajectory, link: int, T: NDArray[np.float64], *, samples: int = 400, noise_std=None
) -> NDArray[np.float64]:
    """The payload's information ``S F S`` (10 x 10) over one period, unit noise unless given.

    Parameters
    ----------
    robot : RobotModel
    traj : FourierTrajectory
    link : int
        The carrying body (index of its joint from 0).
    T : ndarray, shape (10, 10)
        Payload parameters in F -> in the link's frame.
    samples : int
        Grid points over the period.
    noise_std : array_like, shape (n,), optional
        Torque noise per joint (N m); default 1.
    """
    f = _payload_columns_function(robot, link, T)
    t = np.arange(samples) * (1.0 / traj.base_freq / samples)
    q, dq, ddq = traj.evaluate(t)
    A = np.asarray(f.map(samples)(q.T, dq.T, ddq.T)).reshape(robot.n, samples, 10).transpose(1, 0, 2)
    sigma = np.ones(robot.n) if noise_std is None else np.asarray(noise_std, dtype=float)
    A = A / sigma[None, :, None] * _scale()[None, None, :]
    return np.einsum("mjk,mjl->kl", A, A)


def _figures(info: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
    lam = np.linalg.eigvalsh(info)
    if lam[0] <= 0:
        return np.full(10, np.inf), math.inf
    cov = np.linalg.inv(info)
    return np.sqrt(np.diag(cov)), float(np.sqrt(lam[-1] / lam[0]))


def design_payload_motion(
    robot,
    link: int,
    T: NDArray[np.float64],
    *,
    pose=None,
    duration: float = 10.0,
    harmonics: int = 4,
    speed_fraction: float = 0.5,
    noise_std=None,
    starts: int = 4,
    seed: int = 0,
) -> PayloadMotion:
    """Design a short motion that determines a payload's ten parameters (module docstring).

    Parameters
    ----------
    robot : RobotModel
    link : int
        The body carrying the payload (its joint's index from 0).
    T : ndarray, shape (10, 10)
        :func:`dynid.symbolic.bodies.frame_transform` of the payload's frame.
    pose : array_like, shape (n,), optional
        Start and end pose (rad); default the middle of the joint ranges.
    duration : float
        The motion's length (s), at most :data:`MAX_DURATION`.
    harmonics : int
        Harmonics per joint (at least 2: the rest conditions take two).
    speed_fraction : float
        Fraction of the velocity and acceleration limits the motion may use, in (0, 1].
    noise_std : array_like, shape (n,), optional
        Torque noise per joint weighting the information; default 1.
    starts : int
        Random starts.
    seed : int

    Raises
    ------
    UsageError
        A duration out of (0, 15] s, a pose outside the limits, too few harmonics, a bad fraction.
    """
    import time

    start_time = time.perf_counter()
    lo, hi, q0 = _checked_request(robot, pose, duration, speed_fraction)
    problem = ExcitationProblem(robot=robot, harmonics=harmonics, base_freq=1.0 / duration)
    series = _series(problem, q0, duration, harmonics, robot.n)
    grid = max(60, 16 * harmonics)
    bounds = _limit_bounds(robot, lo, hi, speed_fraction, grid)
    solver = _payload_solver(robot, link, T, series, problem, grid, noise_std, bounds)
    rng = np.random.default_rng(seed)
    limited = robot.with_limits(q_min=lo, q_max=hi, dq_max=speed_fraction * robot.dq_max,
                                ddq_max=speed_fraction * robot.ddq_max)  # fmt: skip
    shrink = _Shrink(ExcitationProblem(robot=limited, harmonics=harmonics, base_freq=1.0 / duration), series)
    payload = _Payload(robot, link, T, noise_std)
    say(f"designing a {duration:g} s payload motion for {robot.name} ({starts} starts, IPOPT)")
    best, baseline = _best_of_starts(solver, shrink, payload, rng, starts)
    traj = FourierTrajectory(
        a=best.traj.a, b=best.traj.b, c=best.traj.c, base_freq=best.traj.base_freq,
        meta={"design": "payload", "pose": [float(v) for v in q0], "link": int(link + 1)},
    )  # fmt: skip
    return PayloadMotion(
        trajectory=traj,
        pose=q0,
        relative_std=best.std,
        cond=best.cond,
        baseline_cond=baseline,
        feasible=bool(best.ok),
        seconds=time.perf_counter() - start_time,
    )


def _checked_request(
    robot, pose, duration: float, speed_fraction: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The position limits less the margin and the start pose, after refusing a bad duration, fraction or pose."""
    if not (math.isfinite(duration) and 0 < duration <= MAX_DURATION):
        raise UsageError(
            f"--duration is {duration}; give the payload motion's length in s, in (0, {MAX_DURATION:g}]"
        )
    if not (0 < speed_fraction <= 1):
        raise UsageError(f"--speed-fraction is {speed_fraction}; give a fraction in (0, 1]")
    n = robot.n
    lo = robot.q_min + _MARGIN * (robot.q_max - robot.q_min)
    hi = robot.q_max - _MARGIN * (robot.q_max - robot.q_min)
    q0 = 0.5 * (robot.q_min + robot.q_max) if pose is None else np.asarray(pose, dtype=float).ravel()
    if q0.shape != (n,) or not np.all(np.isfinite(q0)):
        raise UsageError(f"the pose has {q0.size} values; give {n} angles (rad), one per joint")
    if np.any(q0 < lo) or np.any(q0 > hi):
        j = int(np.argmax((q0 < lo) | (q0 > hi)))
        raise UsageError(
            f"the pose's joint {j + 1} is {q0[j]:.4g} rad, outside [{lo[j]:.4g}, {hi[j]:.4g}] (its limits less a "
            f"{100 * _MARGIN:.0f} % margin); give a pose inside them"
        )
    return lo, hi, q0


@dataclass(frozen=True)
class _Series:
    """The motion's Fourier series from its null-space coordinates: at rest at ``q0`` at both ends."""

    pa: NDArray[np.float64]
    pb: NDArray[np.float64]
    lw: NDArray[np.float64]
    q0: NDArray[np.float64]
    duration: float
    k: int
    n: int

    def trajectory(self, z: NDArray[np.float64], scale: float = 1.0) -> FourierTrajectory:
        """The trajectory of coordinates ``z`` (``(y_a, y_b)``, column-major) scaled by ``scale``."""
        k, n = self.k, self.n
        za = z[: k * n].reshape(n, k).T * scale  # veccat is column-major: (k, n) column by column
        zb = z[k * n :].reshape(n, k).T * scale
        a, b = self.pa @ za, self.pb @ zb
        return FourierTrajectory(a=a, b=b, c=self.q0 + (1.0 / self.lw) @ b, base_freq=1.0 / self.duration)


def _series(
    problem: ExcitationProblem, q0: NDArray[np.float64], duration: float, harmonics: int, n: int
) -> _Series:
    """The rest-to-rest parametrisation of the excitation problem's series about the pose."""
    pa, pb = problem.null_bases
    lw = problem.wf * np.arange(1, harmonics + 1)
    return _Series(pa=pa, pb=pb, lw=lw, q0=q0, duration=duration, k=harmonics - 1, n=n)


@dataclass(frozen=True)
class _Solver:
    """IPOPT on the payload criterion with the limits' bounds on the grid."""

    solver: ca.Function
    lbg: NDArray[np.float64]
    ubg: NDArray[np.float64]

    def solve(self, z0: NDArray[np.float64]) -> NDArray[np.float64]:
        """The optimised coordinates from the start ``z0``."""
        sol = self.solver(x0=z0, lbg=self.lbg, ubg=self.ubg)
        return np.asarray(sol["x"]).ravel()


def _payload_solver(
    robot,
    link: int,
    T: NDArray[np.float64],
    series: _Series,
    problem: ExcitationProblem,
    grid: int,
    noise_std,
    bounds: tuple[NDArray[np.float64], NDArray[np.float64]],
) -> _Solver:
    """The NLP (A-optimality of the scaled payload information on the grid, limits as constraints) and IPOPT."""
    n, k, q0, duration = robot.n, series.k, series.q0, series.duration
    pa, pb, lw = series.pa, series.pb, series.lw
    t = np.arange(grid) * (duration / grid)
    Sq, Cq, C, S, dS, dC = problem.basis(t)
    # per joint, the series as linear maps of (y_a, y_b) (each (k,)): swing q - q0, dq, ddq
    Mq_a, Mq_b = Sq @ pa, ((1.0 / lw)[None, :] - Cq) @ pb  # q(t) - q0, since c = q0 + (1/lw) b
    Md_a, Md_b = C @ pa, S @ pb
    Mdd_a, Mdd_b = -dS @ pa, dC @ pb

    ya = ca.MX.sym("ya", k, n)
    yb = ca.MX.sym("yb", k, n)
    Q = ca.repmat(ca.DM(q0).T, grid, 1) + ca.mtimes(ca.DM(Mq_a), ya) + ca.mtimes(ca.DM(Mq_b), yb)
    DQ = ca.mtimes(ca.DM(Md_a), ya) + ca.mtimes(ca.DM(Md_b), yb)
    DDQ = ca.mtimes(ca.DM(Mdd_a), ya) + ca.mtimes(ca.DM(Mdd_b), yb)
    f = _payload_columns_function(robot, link, T)
    cols = f.map(grid)(Q.T, DQ.T, DDQ.T)  # (n, 10 grid)
    sigma = np.ones(n) if noise_std is None else np.asarray(noise_std, dtype=float)
    S = np.diag(_scale())
    blocks = [ca.mtimes(ca.DM(np.diag(1.0 / sigma)), cols[:, 10 * i : 10 * i + 10]) for i in range(grid)]
    H = ca.vertcat(*blocks)
    info = ca.mtimes(ca.mtimes(ca.DM(S), ca.mtimes(H.T, H)), ca.DM(S))
    ridge = 1e-9 * ca.trace(info) + 1e-12
    objective = ca.log(ca.trace(ca.solve(info + ridge * ca.DM.eye(10), ca.DM.eye(10))))
    x = ca.veccat(ya, yb)
    g = ca.veccat(Q, DQ, DDQ)
    solver = ca.nlpsol(
        "payload_motion",
        "ipopt",
        {"x": x, "f": objective, "g": g},
        {
            "ipopt.print_level": 0,
            "print_time": False,
            "ipopt.max_iter": 300,
            "ipopt.hessian_approximation": "limited-memory",
            "ipopt.tol": 1e-6,
            "ipopt.sb": "yes",
        },
    )
    return _Solver(solver, *bounds)


def _limit_bounds(
    robot, lo: NDArray[np.float64], hi: NDArray[np.float64], speed_fraction: float, grid: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Lower and upper bounds of the constraints ``(q, dq, ddq)`` on the grid: positions, speeds, accelerations."""
    lbg = np.concatenate(
        [np.tile(lo, (grid, 1)).T.ravel(), -speed_fraction * np.tile(robot.dq_max, (grid, 1)).T.ravel(),
         -speed_fraction * np.tile(robot.ddq_max, (grid, 1)).T.ravel()]
    )  # fmt: skip
    ubg = np.concatenate(
        [np.tile(hi, (grid, 1)).T.ravel(), speed_fraction * np.tile(robot.dq_max, (grid, 1)).T.ravel(),
         speed_fraction * np.tile(robot.ddq_max, (grid, 1)).T.ravel()]
    )  # fmt: skip
    return lbg, ubg


@dataclass(frozen=True)
class _Shrink:
    """The fine-grid check of a motion, and the shrinking toward the pose that makes it pass."""

    check: ExcitationProblem
    series: _Series

    def largest(self, z: NDArray[np.float64]) -> float:
        """The largest scale of ``z`` whose motion passes the fine-grid check (shrinking goes toward the pose)."""
        check, trajectory = self.check, self.series.trajectory
        low, high = 0.0, 1.0
        while check.is_feasible(trajectory(z, high)) and high < 1e6:
            low, high = high, 2.0 * high
        for _ in range(40):
            mid = 0.5 * (low + high)
            low, high = (mid, high) if check.is_feasible(trajectory(z, mid)) else (low, mid)
        return low

    def checked(self, z: NDArray[np.float64]) -> tuple[FourierTrajectory, bool]:
        """The motion of ``z``, shrunk until it passes the check, and whether it passes at a scale above 0."""
        trajectory = self.series.trajectory
        if self.check.is_feasible(trajectory(z)):
            return trajectory(z), True
        scale = self.largest(z)
        return trajectory(z, scale), scale > 0

    def start(self, rng: np.random.Generator) -> NDArray[np.float64]:
        """A random start strictly inside the limits."""
        series = self.series
        z = rng.standard_normal(2 * series.k * series.n)
        return z * 0.8 * self.largest(z)  # strictly inside the limits


@dataclass(frozen=True)
class _Payload:
    """What the payload's figures of a motion are computed for: the robot, carrying link, frame and noise."""

    robot: Any
    link: int
    T: NDArray[np.float64]
    noise_std: Any

    def figures(self, traj: FourierTrajectory) -> tuple[NDArray[np.float64], float]:
        """Relative standard deviations and condition number of the payload on ``traj``."""
        return _figures(payload_information(self.robot, traj, self.link, self.T, noise_std=self.noise_std))


@dataclass(frozen=True)
class _Candidate:
    """A checked motion and its figures."""

    traj: FourierTrajectory
    ok: bool
    std: NDArray[np.float64]
    cond: float


def _best_of_starts(
    solver: _Solver, shrink: _Shrink, payload: _Payload, rng: np.random.Generator, starts: int
) -> tuple[_Candidate, float]:
    """The best checked motion over the random starts (a checked random one if none passes), and the best
    start's condition number."""
    best, best_value, baseline = None, math.inf, math.inf
    for i in range(starts):
        z0 = shrink.start(rng)
        _, cond0 = payload.figures(shrink.series.trajectory(z0))
        baseline = min(baseline, cond0)
        z = solver.solve(z0)
        traj, ok = shrink.checked(z)
        std, cond = payload.figures(traj)
        value = float(np.sum(std**2)) if ok else math.inf
        if value < best_value:
            best, best_value = _Candidate(traj, ok, std, cond), value
        advance(i + 1, starts)
    if best is None:
        traj, ok = shrink.checked(shrink.start(rng))
        std, cond = payload.figures(traj)
        best = _Candidate(traj, ok, std, cond)
    return best, baseline
