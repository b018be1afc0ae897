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
floored at ``CV_MEAN_FLOOR`` times the column RMS (see :func:`_criterion_data`).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import cached_property

import casadi as ca
import numpy as np
import scipy.linalg

from dynid._threads import one_blas_thread
from dynid.exceptions import ExcitationError, UsageError
from dynid.optim.trajectory import FourierTrajectory
from dynid.symbolic.robot import RobotModel

__all__ = [
    "CRITERIA",
    "MAX_HARMONICS",
    "MIN_BASE_FREQ",
    "CartesianLimits",
    "ExcitationError",
    "ExcitationProblem",
    "ExcitationResult",
    "StageRecord",
    "check_harmonics",
    "design_excitation",
]

MAX_HARMONICS = 10
"""Most harmonics per joint (the paper uses 5).  The optimisation's size grows with their count: one
IPOPT try with 15 harmonics on the UR5 took 71 s of CPU (a search runs up to 60 tries)."""

MIN_BASE_FREQ = 0.01
"""Lowest base frequency (Hz): a period of at most 100 s.  A slower excitation moves too slowly for its
torques to show the inertial parameters, and its design and its repeated periods grow without bound."""

_MIN_AMPLITUDE = 1e-3
"""Smallest amplitude (rad) worth a harmonic: the acceleration limit must allow at least this much."""


def check_harmonics(
    harmonics: int, base_freq: float, *, rate: float | None = None, robot: RobotModel | None = None
) -> None:
    """Refuse more harmonics than the rate, the limits and a sane size allow.

    The rule: at most :data:`MAX_HARMONICS`; the highest harmonic ``N * base_freq`` below the Nyquist
    frequency ``rate / 2`` of the controller; and, with a robot, the acceleration limit must let the
    highest harmonic move its fastest joint by at least 1 mrad (``max ddq_max / (2 pi N ff)^2``).

    Parameters
    ----------
    harmonics : int
        Harmonics N per joint.
    base_freq : float
        Base frequency ff (Hz).
    rate : float, optional
        Controller (sampling) rate (Hz).
    robot : RobotModel, optional
        The robot, for its acceleration limits.

    Raises
    ------
    UsageError
        The bound, the rule behind it and the fix.
    """
    if not (math.isfinite(base_freq) and base_freq > 0):
        return  # ExcitationProblem names a bad base frequency
    bounds = [(MAX_HARMONICS, "the most dynid designs; the paper uses 5")]
    if rate is not None and math.isfinite(rate) and rate > 0:
        bounds.append(
            (
                math.ceil(rate / 2 / base_freq) - 1,
                f"harmonic N at {base_freq:g} Hz must stay below the Nyquist frequency {rate / 2:g} Hz of the "
                f"{rate:g} Hz rate",
            )
        )
    if robot is not None:
        ddq = float(np.max(robot.ddq_max))
        if math.isfinite(ddq) and ddq > 0:
            bound = math.floor(math.sqrt(ddq / _MIN_AMPLITUDE) / (2 * math.pi * base_freq))
            bounds.append(
                (
                    bound,
                    f"the acceleration limit {ddq:g} rad/s^2 of '{robot.name}' leaves a harmonic above {bound} at "
                    f"{base_freq:g} Hz less than 1 mrad of motion",
                )
            )
    limit, reason = min(bounds, key=lambda b: b[0])
    if harmonics > limit:
        if limit >= 2:
            lower = "" if limit == MAX_HARMONICS else ", or lower the base frequency"
            raise UsageError(f"harmonics is {harmonics}; give at most {limit} ({reason}){lower}.")
        raise UsageError(f"harmonics is {harmonics}, and no number of at least 2 fits ({reason}); lower the base frequency.")

CRITERIA = ("seed", "cond", "logdet")
"""Names of the excitation criteria."""

_IPOPT_OPTIONS = {
    "hessian_approximation": "limited-memory",
    "limited_memory_max_history": 10,
    # The limited-memory update as extra rows and columns of the KKT system, one factorisation, instead
    # of Sherman-Morrison back-solves: the same iterates (the criterion equal to 1e-3 after 40
    # iterations on 6 UR5 starts) for 13 ms of CPU per iteration instead of 23.  (A history of 20
    # costs 15 ms per iteration with it; of 5, no less than 10.)
    "limited_memory_aug_solver": "extended",
    "jac_d_constant": "yes",
    "tol": 1e-6,
    # Many random starts matter more than polishing each: stop once the objective has changed by
    # less than 1e-4 (relative) over 5 iterations at a dual infeasibility below 1e-3.  Measured on
    # the Panda (cond, 6 starts): half the iterations (108 instead of 216 on average) for an exact
    # cond 2 % higher per try.
    "acceptable_tol": 1e-3,
    "acceptable_obj_change_tol": 1e-4,
    "acceptable_iter": 5,
    "max_iter": 300,
    "print_level": 0,
    "sb": "yes",
    # The adaptive barrier update spends a third of the time in extra back-solves (1080+ constraints,
    # limited-memory Hessian); monotone reached the same exact cond with 10 % less CPU on UR5.
    "mu_strategy": "monotone",
}


_WARM_OPTIONS = {
    "warm_start_init_point": "yes",
    "warm_start_bound_push": 1e-6,
    "warm_start_slack_bound_push": 1e-6,
    "warm_start_mult_bound_push": 1e-6,
    "mu_init": 1e-4,
}

SCREEN_ITER: int | None = 40
POLISH = 2

CV_MEAN_FLOOR = 1e-3
"""Floor of ``|mean|`` relative to the RMS of a column in the coefficient-of-variation weights (ours)."""


Progress = Callable[[str], None]


# ---------------------------------------------------------------------------- interrupts
_STOP: list[str] = []
"""Name of the signal that interrupted the design in this process (empty while none did).

CasADi checks for signals while IPOPT runs and swallows the ``KeyboardInterrupt`` that Ctrl-C or
dynid's SIGTERM handler raises there (a warning, and the solve goes on): the design would carry on
for minutes.  :func:`_interruptible` records the signal here before the handler raises, the solver's
iteration callback (:class:`_StopCallback`) then ends IPOPT at its next iteration, and the try raises
``KeyboardInterrupt`` again once the solver has returned."""

_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")
_DEPTH = [0]
_SOLVING: set[int] = set()
"""Threads inside IPOPT.  A signal there is only recorded: raised inside the objective's callback, the
exception would be printed with its traceback by CasADi and the solve would go on."""


@contextmanager
def _interruptible() -> Iterator[None]:
    """Record SIGINT, SIGTERM and SIGHUP in :data:`_STOP`, then run the handler that was in place.

    Only handlers that are Python callables are wrapped (Ctrl-C's default, dynid's command line):
    a signal left at its default action still ends the process as before.  Outside the main thread
    (where signals cannot be set) nothing changes.
    """
    import signal

    if _DEPTH[0]:  # inside a design (a try run in the designing process): its guard is in place
        yield
        return
    _STOP.clear()
    _DEPTH[0] += 1
    previous: dict[int, Callable] = {}
    if threading.current_thread() is threading.main_thread():
        for name in _SIGNALS:
            sig = getattr(signal, name, None)
            handler = None if sig is None else signal.getsignal(sig)
            if callable(handler):
                previous[sig] = handler

                def record(signum: int, frame: object, handler: Callable = handler) -> None:
                    _STOP.append(signal.Signals(signum).name)
                    if threading.get_ident() not in _SOLVING:  # see _SOLVING
                        handler(signum, frame)

                signal.signal(sig, record)
    try:
        yield
        _check_stop()
    finally:
        _DEPTH[0] -= 1
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _check_stop() -> None:
    """Raise ``KeyboardInterrupt`` (with the signal's name) when a signal came during the design."""
    if _STOP:
        name = _STOP[0]
        raise KeyboardInterrupt(*(() if name == "SIGINT" else (name,)))


# ---------------------------------------------------------------------------- problem
@dataclass(frozen=True, eq=False, kw_only=True)
class CartesianLimits:
    """Limits on the tool position (the robot's tool frame origin, base frame, metres).

    Parameters
    ----------
    z_min : float, optional
        Floor (e.g. a table top): ``z >= z_min`` over the whole trajectory.
    box_min, box_max : sequence of 3 floats, optional
        Corners of an axis-aligned box the tool must stay in.
    """

    z_min: float | None = None
    box_min: Sequence[float] | None = None
    box_max: Sequence[float] | None = None

    def __post_init__(self) -> None:
        for label in ("box_min", "box_max"):
            value = getattr(self, label)
            if value is None:
                continue
            arr = np.asarray(value, dtype=float)
            if arr.shape != (3,) or not np.all(np.isfinite(arr)):
                raise UsageError(f"{label} is {value!r}; give three finite numbers x, y, z in metres.")
            arr.setflags(write=False)
            object.__setattr__(self, label, arr)
        if (self.box_min is None) != (self.box_max is None):
            raise UsageError("a Cartesian box needs both box_min and box_max; give both corners or neither.")
        if self.box_min is not None and np.any(self.box_min >= self.box_max):
            raise UsageError(f"the box {self.box_min} .. {self.box_max} is empty; give box_min < box_max per axis.")
        if self.z_min is not None and not math.isfinite(self.z_min):
            raise UsageError(f"z_min is {self.z_min}; give a finite height in metres.")

    @property
    def active(self) -> bool:
        return self.z_min is not None or self.box_min is not None

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds on (x, y, z) of the tool, infinite where unconstrained."""
        lo = np.full(3, -np.inf)
        hi = np.full(3, np.inf)
        if self.box_min is not None:
            lo, hi = np.array(self.box_min), np.array(self.box_max)
        if self.z_min is not None:
            lo[2] = max(lo[2], self.z_min)
        return lo, hi

    def to_dict(self) -> dict:
        return {
            "z_min": self.z_min,
            "box_min": None if self.box_min is None else list(self.box_min),
            "box_max": None if self.box_max is None else list(self.box_max),
        }


@dataclass(frozen=True, eq=False, kw_only=True)
class ExcitationProblem:
    """What an excitation trajectory must do: robot, series, criterion, grid and limits.

    Parameters
    ----------
    robot : RobotModel
        The robot; its joint limits (``q_min``, ``q_max``, ``dq_max``, ``ddq_max``) are hard constraints.
    harmonics : int
        Number of harmonics N per joint (the paper: 5).  At least 2: the rest conditions take two
        coefficients per joint, one harmonic leaves a motionless trajectory.
    base_freq : float
        Base frequency ff (Hz); the period is 1 / ff (the paper: 0.1 Hz, 10 s).
    criterion : {"seed", "cond", "logdet"}
        The objective (module docstring).
    grid : int, optional
        Samples per period in the optimisation (default ``max(40, 12 N)``); the check grid is
        ``check_factor`` times finer.
    check_factor : int
        Refinement of the check grid over the optimisation grid (default 10).
    noise_std : sequence of float, optional
        Torque noise standard deviation per joint (N m), the diagonal of Omega^1/2; default ones.
    cartesian : CartesianLimits, optional
        Tool position limits (floor, box), from forward kinematics.
    sharpness : float
        Exponent p of the smooth extreme-eigenvalue surrogate (module docstring); ``inf`` for the
        exact, non-smooth extreme eigenvalues.
    """

    robot: RobotModel
    harmonics: int = 5
    base_freq: float = 0.1
    criterion: str = "seed"
    grid: int | None = None
    check_factor: int = 10
    noise_std: Sequence[float] | None = None
    cartesian: CartesianLimits | None = None
    sharpness: float = 16.0

    def __post_init__(self) -> None:
        if not isinstance(self.robot, RobotModel):
            raise UsageError(
                f"robot is a {type(self.robot).__name__}; give a RobotModel from dynid.symbolic.load_robot."
            )
        if self.criterion not in CRITERIA:
            raise UsageError(f"criterion is {self.criterion!r}; choose one of {', '.join(CRITERIA)}.")
        if int(self.harmonics) != self.harmonics or self.harmonics < 1:
            raise UsageError(
                f"harmonics is {self.harmonics}; give a whole number of at least 2 (the rest conditions "
                "dq(0) = ddq(0) = 0 take two coefficients per joint)."
            )
        if not (math.isfinite(self.base_freq) and self.base_freq > 0):
            raise UsageError(f"base_freq is {self.base_freq}; give a positive frequency in Hz, e.g. 0.1.")
        if self.base_freq < MIN_BASE_FREQ:
            raise UsageError(
                f"base_freq is {self.base_freq:g} Hz, a period of {1 / self.base_freq:.3g} s; give at least "
                f"{MIN_BASE_FREQ:g} Hz (a period of at most {1 / MIN_BASE_FREQ:g} s), e.g. 0.1."
            )
        check_harmonics(int(self.harmonics), self.base_freq, robot=self.robot)
        grid = max(40, 12 * int(self.harmonics)) if self.grid is None else self.grid
        if int(grid) != grid or grid < 2:
            raise UsageError(f"grid is {self.grid}; give at least 2 samples per period (default max(40, 12 N)).")
        object.__setattr__(self, "grid", int(grid))
        object.__setattr__(self, "harmonics", int(self.harmonics))
        if int(self.check_factor) != self.check_factor or self.check_factor < 1:
            raise UsageError(f"check_factor is {self.check_factor}; give a whole number of at least 1, e.g. 10.")
        n = self.robot.n
        noise = np.ones(n) if self.noise_std is None else np.asarray(self.noise_std, dtype=float).ravel()
        if noise.size == 1:
            noise = np.full(n, float(noise[0]))
        if noise.shape != (n,) or not np.all(np.isfinite(noise)) or np.any(noise <= 0):
            raise UsageError(
                f"noise_std is {self.noise_std!r}; give {n} positive torque noise levels (one per joint of "
                f"'{self.robot.name}') or one for all."
            )
        noise.setflags(write=False)
        object.__setattr__(self, "noise_std", noise)
        if not self.sharpness >= 1:
            raise UsageError(f"sharpness is {self.sharpness}; give p >= 1 (default 16) or inf.")
        if self.cartesian is not None and not isinstance(self.cartesian, CartesianLimits):
            raise UsageError("cartesian must be a CartesianLimits(z_min=..., box_min=..., box_max=...).")

    # ------------------------------------------------------------------ sizes and bases
    @property
    def n(self) -> int:
        return self.robot.n

    @property
    def period(self) -> float:
        return 1.0 / self.base_freq

    @property
    def wf(self) -> float:
        return 2.0 * math.pi * self.base_freq

    @cached_property
    def null_bases(self) -> tuple[np.ndarray, np.ndarray]:
        """Orthonormal bases P_a (N, N-1) of ``sum_l a_l = 0`` and P_b (N, N-1) of ``sum_l l b_l = 0``."""
        harmonics = np.arange(1, self.harmonics + 1, dtype=float)
        pa = scipy.linalg.null_space(np.ones((1, self.harmonics)))
        pb = scipy.linalg.null_space(harmonics[None, :])
        # Fixed signs make the basis (hence the seeds' meaning) independent of the LAPACK build.
        for p in (pa, pb):
            for k in range(p.shape[1]):
                if p[np.argmax(np.abs(p[:, k])), k] < 0:
                    p[:, k] *= -1
        return pa, pb

    @property
    def n_free(self) -> int:
        """Number of decision variables: ``(2 N - 2) n`` coefficients and n offsets."""
        return (2 * self.harmonics - 2) * self.n + self.n

    def times(self, *, fine: bool = False) -> np.ndarray:
        """The optimisation grid (``grid`` samples on [0, T)) or the check grid (ends included)."""
        if fine:
            m = self.grid * self.check_factor
            return np.arange(m + 1) * (self.period / m)
        return np.arange(self.grid) * (self.period / self.grid)

    def basis(self, t: np.ndarray) -> tuple[np.ndarray, ...]:
        """Rows mapping (a, b) to q - c, dq, ddq at times t: ``(Sq, Cq, C, S, dS, dC)`` of shape (m, N)."""
        lw = self.wf * np.arange(1, self.harmonics + 1)
        phase = np.outer(t, lw)
        s, c = np.sin(phase), np.cos(phase)
        return s / lw, c / lw, c, s, s * lw, c * lw

    # ------------------------------------------------------------------ coefficients <-> decision vector
    def to_trajectory(self, y: np.ndarray, meta: dict | None = None) -> FourierTrajectory:
        """The Fourier trajectory of a decision vector ``y`` (shape (n_free,))."""
        y = np.asarray(y, dtype=float).ravel()
        pa, pb = self.null_bases
        k, n = self.harmonics - 1, self.n
        ya = y[: k * n].reshape(n, k).T
        yb = y[k * n : 2 * k * n].reshape(n, k).T
        return FourierTrajectory(
            a=pa @ ya, b=pb @ yb, c=y[2 * k * n :].copy(), base_freq=self.base_freq, meta=dict(meta or {})
        )

    def to_vector(self, traj: FourierTrajectory) -> np.ndarray:
        """Decision vector of a trajectory (its projection onto the rest conditions)."""
        pa, pb = self.null_bases
        return np.concatenate([(pa.T @ traj.a).T.ravel(), (pb.T @ traj.b).T.ravel(), traj.c])

    # ------------------------------------------------------------------ random feasible trajectories
    def random_trajectory(self, rng: np.random.Generator, *, amplitude: float = 1.0) -> FourierTrajectory:
        """A random trajectory within the joint limits on the check grid (module docstring).

        Parameters
        ----------
        rng : numpy.random.Generator
            Source of randomness.
        amplitude : float
            Fraction (0, 1] of the largest feasible scale of each joint; below 1 the trajectory is
            strictly inside the limits (a start for the interior-point solver).
        """
        pa, pb = self.null_bases
        k, n = self.harmonics - 1, self.n
        robot = self.robot
        a = pa @ rng.standard_normal((k, n))
        b = pb @ rng.standard_normal((k, n))
        env = self.envelope(a, b)
        ratios = [
            (robot.dq_max, env["dq"]),
            (robot.ddq_max, env["ddq"]),
            (robot.q_max - robot.q_min, env["swing_max"] - env["swing_min"]),
        ]
        scale = np.minimum.reduce(
            [np.divide(limit, peak, out=np.full(n, np.inf), where=peak > 0) for limit, peak in ratios]
        )
        scale = np.where(np.isfinite(scale), scale, 0.0) * amplitude  # a motionless joint (one harmonic)
        lo = robot.q_min - scale * env["swing_min"]
        hi = robot.q_max - scale * env["swing_max"]
        offset = lo + rng.uniform(0.0, 1.0, size=n) * (hi - lo)
        if amplitude < 1:  # keep the room between the swing and the range symmetric-ish: stay inside
            room = (hi - lo) * 0.5 * (1 - amplitude)
            offset = np.clip(offset, lo + room, hi - room)
        return FourierTrajectory(a=a * scale, b=b * scale, c=offset, base_freq=self.base_freq)

    # ------------------------------------------------------------------ checks on the fine grid
    def envelope(self, a: np.ndarray, b: np.ndarray) -> dict[str, np.ndarray]:
        """Bounds over the whole period, per joint, of the swing ``q - c`` (max and min), ``|dq|``, ``|ddq|``.

        The largest value on the check grid plus the most a peak between two of its points (spacing h)
        can exceed it: ``max|x''| (h/2)^2 / 2`` (x'' = ddq for positions, the jerk for velocities, the
        snap for accelerations).  All are linear in the amplitude of (a, b).
        """
        t = self.times(fine=True)
        swing, dq, ddq, jerk, snap = _series(self, a, b, t)
        k = 0.5 * (0.5 * (t[1] - t[0])) ** 2
        hidden_q = k * np.abs(ddq).max(axis=0)
        return {
            "swing_max": swing.max(axis=0) + hidden_q,
            "swing_min": swing.min(axis=0) - hidden_q,
            "dq": np.abs(dq).max(axis=0) + k * np.abs(jerk).max(axis=0),
            "ddq": np.abs(ddq).max(axis=0) + k * np.abs(snap).max(axis=0),
        }

    def violations(self, traj: FourierTrajectory, functions: _Functions | None = None) -> dict[str, np.ndarray]:
        """Largest excess over each limit over the whole period (<= 0 where the limit holds).

        Joint limits: bounds from the check grid and the curvature (:meth:`envelope`), so a trajectory
        without excess meets its limits in continuous time.  Cartesian limits: on the check grid.

        Returns
        -------
        dict of ndarray
            ``q_low``, ``q_high``, ``dq``, ``ddq`` (n,) in joint units, and ``cart_low``, ``cart_high`` (3,)
            in metres when Cartesian limits are set.
        """
        robot = self.robot
        env = self.envelope(traj.a, traj.b)
        out = {
            "q_low": robot.q_min - (traj.c + env["swing_min"]),
            "q_high": traj.c + env["swing_max"] - robot.q_max,
            "dq": env["dq"] - robot.dq_max,
            "ddq": env["ddq"] - robot.ddq_max,
        }
        if self.cartesian is not None and self.cartesian.active:
            functions = functions or _functions(self)
            p = functions.tool_positions(traj.evaluate(self.times(fine=True))[0])
            lo, hi = self.cartesian.bounds()
            with np.errstate(invalid="ignore"):
                out["cart_low"] = np.nan_to_num(lo - p.min(axis=0), nan=-np.inf, neginf=-np.inf)
                out["cart_high"] = np.nan_to_num(p.max(axis=0) - hi, nan=-np.inf, neginf=-np.inf)
        return out

    def is_feasible(self, traj: FourierTrajectory, functions: _Functions | None = None) -> bool:
        """True when every limit holds on the check grid (to 1e-9 relative)."""
        return _feasible(self.robot, self.violations(traj, functions))

    # ------------------------------------------------------------------ exact figures
    def regressor(self, traj: FourierTrajectory, *, fine: bool = True) -> np.ndarray:
        """The noise-weighted base regressor H* over one period, shape (m n, n_b).

        On the check grid (default) through the compiled library; on the optimisation grid for the
        rows stacked into later designs.
        """
        functions = _functions(self)
        t = self.times(fine=fine)[: None if fine else self.grid]
        q, dq, ddq = traj.evaluate(t)
        return functions.weighted_regressor(q, dq, ddq, self.noise_std)


def _series(problem: ExcitationProblem, a: np.ndarray, b: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, ...]:
    """Swing ``q - c``, dq, ddq, jerk and snap of coefficients (a, b) at times t: each (len(t), n)."""
    lw = problem.wf * np.arange(1, problem.harmonics + 1)
    phase = np.outer(t, lw)
    s, c = np.sin(phase), np.cos(phase)
    return (
        (s / lw) @ a - (c / lw) @ b,
        c @ a + s @ b,
        (-s * lw) @ a + (c * lw) @ b,
        (-c * lw**2) @ a + (-s * lw**2) @ b,
        (s * lw**3) @ a + (-c * lw**3) @ b,
    )


def _feasible(robot: RobotModel, viol: dict[str, np.ndarray]) -> bool:
    scale = {
        "q_low": robot.q_max - robot.q_min,
        "q_high": robot.q_max - robot.q_min,
        "dq": robot.dq_max,
        "ddq": robot.ddq_max,
    }
    for key, value in viol.items():
        tol = 1e-9 * scale.get(key, 1.0)
        if np.any(value > tol):
            return False
    return True


# ---------------------------------------------------------------------------- numeric functions
@dataclass(frozen=True, eq=False)
class _Functions:
    """The robot's base regressor and forward kinematics (picklable: sent to parallel workers)."""

    base_regressor: ca.Function
    fk: ca.Function
    gravity_related: np.ndarray
    names: tuple[str, ...]
    robot: RobotModel

    @property
    def n_base(self) -> int:
        return int(self.gravity_related.size)

    def weighted_regressor(self, q, dq, ddq, noise_std) -> np.ndarray:
        """H* rows (m n, n_b): the compiled base regressor with joint j's rows divided by sigma_j."""
        Y = _compiled(self.robot).base_regressor(q, dq, ddq)  # (m, n, n_b)
        Y = Y / np.asarray(noise_std)[None, :, None]
        return Y.reshape(-1, Y.shape[2])

    def tool_positions(self, q: np.ndarray) -> np.ndarray:
        """Tool frame origin (m, 3) through the CasADi virtual machine (no compiled library needed)."""
        p = self.fk.map(q.shape[0])(q.T)[0]
        return np.asarray(p).T


_FUNCTIONS: dict[str, _Functions] = {}
_COMPILED: dict[str, object] = {}


def _compiled(robot: RobotModel):
    """The robot's compiled library (one per process; building it computes the base parameters)."""
    lib = _COMPILED.get(robot.key)
    if lib is None:
        from dynid.symbolic.export import compiled_functions

        lib = _COMPILED[robot.key] = compiled_functions(robot, progress=None)
    return lib


def _functions(problem: ExcitationProblem) -> _Functions:
    key = problem.robot.key
    cached = _FUNCTIONS.get(key)
    if cached is not None:
        return cached
    from dynid.symbolic.base import base_parameters
    from dynid.symbolic.functions import robot_functions

    funcs = robot_functions(problem.robot, progress=None)
    base = base_parameters(funcs)
    out = _Functions(
        base_regressor=base.base_regressor,
        fk=funcs.fk,
        gravity_related=np.asarray(base.gravity_related, dtype=bool),
        names=base.names,
        robot=problem.robot,
    )
    _FUNCTIONS[key] = out
    return out


# ---------------------------------------------------------------------------- criteria, exact
@dataclass(frozen=True, eq=False)
class _CriterionData:
    """Fixed numbers of a criterion for one design: seed weights (w_H, w_h1, w_h2), column scaling."""

    weights: np.ndarray  # (3,)
    scale: np.ndarray  # (n_b,) column scaling of logdet (1 / RMS over the random pool)
    column_weights: np.ndarray  # (n_b,) w_ci


def _criterion_data(H_pool: np.ndarray, gravity: np.ndarray) -> _CriterionData:
    """Coefficient-of-variation weights and column scaling from pooled random trajectories.

    The paper does not say on which H* the weights are computed (ours): on the pool of random
    feasible trajectories, once per design, so that every try minimises the same function and
    their objectives can be compared.  Some columns have a mean that vanishes over any period
    (the column of ``Izz1`` is ``ddq_1``, whose integral over a period is zero): their CV is
    1e17 and would take all the weight, so (ours) ``|mean|`` is floored at ``CV_MEAN_FLOOR`` times
    the column's RMS, which caps a CV at 1 / CV_MEAN_FLOOR.
    """
    mean = np.abs(H_pool.mean(axis=0))
    std = H_pool.std(axis=0)
    rms = np.sqrt(np.mean(H_pool**2, axis=0))
    cv = std / np.maximum(mean, np.maximum(CV_MEAN_FLOOR * rms, 1e-300))
    w = cv / cv.sum()
    w1 = float(w[gravity].sum())
    w2 = float(w[~gravity].sum())
    return _CriterionData(
        weights=np.array([w1 + w2, w1, w2]),
        scale=1.0 / np.maximum(rms, 1e-300),
        column_weights=w,
    )


def exact_figures(H: np.ndarray, criterion: str, data: _CriterionData, gravity: np.ndarray) -> dict[str, float]:
    """Exact condition numbers (SVD) and the criterion's exact value for a stacked H*."""
    cond = float(np.linalg.cond(H))
    cond1 = float(np.linalg.cond(H[:, gravity])) if gravity.any() else 0.0
    cond2 = float(np.linalg.cond(H[:, ~gravity])) if (~gravity).any() else 0.0
    if criterion == "seed":
        w = data.weights
        objective = w[0] * cond + w[1] * cond1 + w[2] * cond2
    elif criterion == "cond":
        objective = cond
    else:
        Hs = H * data.scale
        sign, logdet = np.linalg.slogdet(Hs.T @ Hs / H.shape[0])
        objective = -logdet / H.shape[1] if sign > 0 else math.inf
    if not math.isfinite(cond):
        objective = math.inf
    return {"cond": cond, "cond_gravity": cond1, "cond_motion": cond2, "objective": float(objective)}


# ---------------------------------------------------------------------------- criteria, smooth
def _soft_log_cond2(S: np.ndarray, p: float) -> tuple[float, np.ndarray]:
    """Smooth upper bound of log cond(S) for a symmetric positive definite S, and its gradient dL/dS.

    ``L = (1/p) log sum lambda^p + (1/p) log sum lambda^-p`` (p = inf: the exact extreme eigenvalues).
    """
    lam, V = np.linalg.eigh(0.5 * (S + S.T))
    floor = max(lam[-1], 1e-300) * 1e-15
    lam = np.maximum(lam, floor)
    ll = np.log(lam)
    if math.isinf(p):
        hi_w = np.zeros_like(lam)
        lo_w = np.zeros_like(lam)
        hi_w[-1] = lo_w[0] = 1.0
        value = ll[-1] - ll[0]
    else:
        z = p * ll
        zmax = z.max()
        e = np.exp(z - zmax)
        hi = (zmax + math.log(e.sum())) / p
        hi_w = e / e.sum()
        z2 = -p * ll
        z2max = z2.max()
        e2 = np.exp(z2 - z2max)
        lo = -(z2max + math.log(e2.sum())) / p
        lo_w = e2 / e2.sum()
        value = hi - lo
    grad = (V * ((hi_w - lo_w) / lam)) @ V.T
    return float(value), grad


class _SmoothCriterion:
    """The smooth criterion f(A, w, s) of the information matrix A = H*^T H* and its gradient."""

    def __init__(self, criterion: str, gravity: np.ndarray, sharpness: float) -> None:
        self.criterion = criterion
        self.gravity = np.asarray(gravity, dtype=bool)
        self.sharpness = sharpness
        self._last: tuple[bytes, tuple] | None = None

    def __call__(self, A: np.ndarray, w: np.ndarray, s: np.ndarray):
        key = A.tobytes() + w.tobytes() + s.tobytes()
        if self._last is not None and self._last[0] == key:
            return self._last[1]
        out = self._evaluate(A, w, s)
        self._last = (key, out)
        return out

    def _evaluate(self, A: np.ndarray, w: np.ndarray, s: np.ndarray):
        nb = A.shape[0]
        p = self.sharpness
        if self.criterion == "logdet":
            # -(1/n_b) log det(D A D), D = diag(s): eigenvalues of the scaled matrix (better conditioned);
            # the gradient D (D A D)^-1 D is A^-1 whatever the scaling, which only shifts the value.
            S = A * np.outer(s, s)
            lam, V = np.linalg.eigh(0.5 * (S + S.T))
            lam = np.maximum(lam, max(lam[-1], 1e-300) * 1e-15)
            value = -float(np.sum(np.log(lam))) / nb
            dA = -((V / lam) @ V.T) * np.outer(s, s) / nb
            return value, dA, np.zeros(3), -2.0 / (nb * s)
        value_all, g_all = _soft_log_cond2(A, p)
        if self.criterion == "cond":
            return 0.5 * value_all, 0.5 * g_all, np.zeros(3), np.zeros(nb)
        # seed: log(w_H c + w_1 c_1 + w_2 c_2) with c = exp(L / 2) the smooth condition numbers
        terms = [(w[0], value_all, g_all, None)]
        for weight, mask in ((w[1], self.gravity), (w[2], ~self.gravity)):
            if mask.any() and weight > 0:
                idx = np.flatnonzero(mask)
                v, g = _soft_log_cond2(A[np.ix_(idx, idx)], p)
                terms.append((weight, v, g, idx))
            else:
                terms.append((0.0, 0.0, None, None))
        conds = np.array([math.exp(0.5 * t[1]) if t[2] is not None else 0.0 for t in terms])
        weights = np.array([t[0] for t in terms])
        total = float(weights @ conds)
        dA = np.zeros_like(A)
        for (weight, _, g, idx), c in zip(terms, conds, strict=True):
            if g is None or weight == 0:
                continue
            block = weight * c * 0.5 * g / total
            if idx is None:
                dA += block
            else:
                dA[np.ix_(idx, idx)] += block
        return math.log(total), dA, conds / total, np.zeros(nb)


class _CriterionCallback(ca.Callback):
    """CasADi node ``f(A, w, s)`` of the smooth criterion, with its analytic Jacobian."""

    def __init__(self, name: str, fn: _SmoothCriterion, nb: int) -> None:
        ca.Callback.__init__(self)
        self._fn = fn
        self._nb = nb
        self._jac: _CriterionJacobian | None = None
        self.construct(name, {"enable_fd": False})

    def get_n_in(self) -> int:
        return 3

    def get_n_out(self) -> int:
        return 1

    def get_name_in(self, i: int) -> str:
        return ("A", "w", "s")[i]

    def get_name_out(self, i: int) -> str:
        return "f"

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        return (ca.Sparsity.dense(self._nb, self._nb), ca.Sparsity.dense(3, 1), ca.Sparsity.dense(self._nb, 1))[i]

    def get_sparsity_out(self, i: int) -> ca.Sparsity:
        return ca.Sparsity.dense(1, 1)

    def eval(self, arg):
        A, w, s = (np.asarray(v.full() if hasattr(v, "full") else v, dtype=float) for v in arg)
        value = self._fn(A, w.ravel(), s.ravel())[0]
        return [value]

    def has_jacobian(self) -> bool:
        return True

    def get_jacobian(self, name, inames, onames, opts):
        self._jac = _CriterionJacobian(name, self._fn, self._nb, inames, onames, opts)
        return self._jac


class _CriterionJacobian(ca.Callback):
    """Jacobian of :class:`_CriterionCallback`: inputs (A, w, s, f), outputs df/dA, df/dw, df/ds (rows)."""

    def __init__(self, name, fn: _SmoothCriterion, nb: int, inames, onames, opts) -> None:
        ca.Callback.__init__(self)
        self._fn = fn
        self._nb = nb
        self._inames = list(inames)
        self._onames = list(onames)
        self.construct(name, dict(opts, enable_fd=False))

    def get_n_in(self) -> int:
        return 4

    def get_n_out(self) -> int:
        return 3

    def get_name_in(self, i: int) -> str:
        return self._inames[i]

    def get_name_out(self, i: int) -> str:
        return self._onames[i]

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        nb = self._nb
        return (ca.Sparsity.dense(nb, nb), ca.Sparsity.dense(3, 1), ca.Sparsity.dense(nb, 1), ca.Sparsity.dense(1, 1))[i]

    def get_sparsity_out(self, i: int) -> ca.Sparsity:
        return (ca.Sparsity.dense(1, self._nb**2), ca.Sparsity.dense(1, 3), ca.Sparsity.dense(1, self._nb))[i]

    def eval(self, arg):
        A, w, s = (np.asarray(v.full() if hasattr(v, "full") else v, dtype=float) for v in arg[:3])
        _, dA, dw, ds = self._fn(A, w.ravel(), s.ravel())
        return [dA.reshape(1, -1, order="F"), dw.reshape(1, -1), ds.reshape(1, -1)]


class _StopCallback(ca.Callback):
    """IPOPT's iteration callback: returns 1 (IPOPT stops: User_Requested_Stop) once a signal came."""

    def __init__(self, name: str, nx: int, ng: int, npar: int) -> None:
        ca.Callback.__init__(self)
        self._sizes = {"x": nx, "lam_x": nx, "g": ng, "lam_g": ng, "lam_p": npar, "f": 1}
        self.construct(name, {})

    def get_n_in(self) -> int:
        return ca.nlpsol_n_out()

    def get_n_out(self) -> int:
        return 1

    def get_name_in(self, i: int) -> str:
        return ca.nlpsol_out(i)

    def get_name_out(self, i: int) -> str:
        return "ret"

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        return ca.Sparsity.dense(self._sizes.get(ca.nlpsol_out(i), 0), 1)

    def eval(self, arg):
        return [1 if _STOP else 0]


# ---------------------------------------------------------------------------- the NLP
class _Nlp:
    """IPOPT on the decision vector y for one problem; built once per process and reused."""

    def __init__(self, problem: ExcitationProblem, functions: _Functions) -> None:
        n, m, k = problem.n, problem.grid, problem.harmonics - 1
        nb = functions.n_base
        self.problem = problem
        self.nb = nb
        pa, pb = problem.null_bases
        sq, cq, c_, s_, ds, dc = problem.basis(problem.times())
        # The trajectory on the grid and the constraints, in SX (small, their Jacobian is generated
        # as SX too: with Cartesian limits an MX Jacobian made each IPOPT iteration twice as slow).
        ys = ca.SX.sym("y", problem.n_free)
        ya = ca.reshape(ys[: k * n], k, n)
        yb = ca.reshape(ys[k * n : 2 * k * n], k, n)
        offset = ys[2 * k * n :]
        Qs = ca.repmat(offset.T, m, 1) + ca.mtimes(ca.DM(sq @ pa), ya) - ca.mtimes(ca.DM(cq @ pb), yb)
        DQs = ca.mtimes(ca.DM(c_ @ pa), ya) + ca.mtimes(ca.DM(s_ @ pb), yb)
        DDQs = -ca.mtimes(ca.DM(ds @ pa), ya) + ca.mtimes(ca.DM(dc @ pb), yb)
        gs = [ca.vec(Qs), ca.vec(DQs), ca.vec(DDQs)]
        self.cart_axes: np.ndarray = np.zeros(0, dtype=int)
        cart = problem.cartesian
        if cart is not None and cart.active:
            lo, hi = cart.bounds()
            self.cart_axes = np.flatnonzero(np.isfinite(lo) | np.isfinite(hi))
            P = functions.fk.map(m)(Qs.T)[0]  # 3 x m
            gs.append(ca.vec(P[self.cart_axes.tolist(), :].T))
        states = ca.Function("grid_states", [ys], [Qs.T, DQs.T, DDQs.T])
        constraints = ca.Function("constraints", [ys], [ca.vertcat(*gs)])
        y = ca.MX.sym("y", problem.n_free)
        QT, DQT, DDQT = states(y)
        # Base regressor over the grid: n x (m n_b), samples side by side; regrouped as H*^T (n_b x m n)
        # with the columns ordered joint by joint, then scaled by 1 / sigma_joint.
        R = functions.base_regressor.map(m)(QT, DQT, DDQT)
        Ht = ca.reshape(R.T, nb, m * n)
        row_weight = np.repeat(1.0 / np.asarray(problem.noise_std), m)
        Ht = Ht * ca.repmat(ca.DM(row_weight).T, nb, 1)
        A = ca.mtimes(Ht, Ht.T)
        par = ca.MX.sym("p", nb * nb + 3 + nb)
        prior = ca.reshape(par[: nb * nb], nb, nb)
        w = par[nb * nb : nb * nb + 3]
        scale = par[nb * nb + 3 :]
        self.criterion = _CriterionCallback(
            "excitation_criterion",
            _SmoothCriterion(problem.criterion, functions.gravity_related, problem.sharpness),
            nb,
        )
        f = self.criterion(A + prior, w, scale)
        self.A = ca.Function("information", [y], [A], ["y"], ["A"])
        options = dict(_IPOPT_OPTIONS)
        if self.cart_axes.size:
            options["jac_d_constant"] = "no"
        g = constraints(y)
        nlp = {"x": y, "p": par, "f": f, "g": g}
        # stops IPOPT at its next iteration once a signal came (CasADi swallows the KeyboardInterrupt)
        self.stop = _StopCallback("excitation_stop", problem.n_free, g.shape[0], par.shape[0])
        common = {"print_time": False, "error_on_fail": False, "iteration_callback": self.stop}
        self.solver = ca.nlpsol("excitation", "ipopt", nlp, {"ipopt": options, **common})
        # Re-solves after tightening start from the previous solution and multipliers, with a small
        # barrier parameter: the solution moves little.
        self.warm_solver = ca.nlpsol(
            "excitation_warm",
            "ipopt",
            nlp,
            {"ipopt": dict(options, **_WARM_OPTIONS), **common},
        )
        self._nlp_dict, self._options, self._common = nlp, options, common
        self._screen_solvers: dict[int, ca.Function] = {}
        self._multipliers: tuple[np.ndarray, np.ndarray] | None = None

    def screen_solver(self, max_iter: int) -> ca.Function:
        """A solver that stops after ``max_iter`` iterations (a screening solve), built once per size."""
        solver = self._screen_solvers.get(max_iter)
        if solver is None:
            options = dict(self._options, max_iter=int(max_iter))
            solver = self._screen_solvers[max_iter] = ca.nlpsol(
                f"excitation_screen_{max_iter}", "ipopt", self._nlp_dict, {"ipopt": options, **self._common}
            )
        return solver

    def bounds(self, margins: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """lbg, ubg for the limits reduced by ``margins`` (same keys as the violations)."""
        robot, m = self.problem.robot, self.problem.grid
        q_lo = robot.q_min + margins["q_low"]
        q_hi = robot.q_max - margins["q_high"]
        dq = robot.dq_max - margins["dq"]
        ddq = robot.ddq_max - margins["ddq"]
        lbg = [np.repeat(q_lo, m), np.repeat(-dq, m), np.repeat(-ddq, m)]
        ubg = [np.repeat(q_hi, m), np.repeat(dq, m), np.repeat(ddq, m)]
        if self.cart_axes.size:
            lo, hi = self.problem.cartesian.bounds()
            lo = lo + margins["cart_low"]
            hi = hi - margins["cart_high"]
            lbg.append(np.repeat(lo[self.cart_axes], m))
            ubg.append(np.repeat(hi[self.cart_axes], m))
        return np.concatenate(lbg), np.concatenate(ubg)

    def solve(
        self,
        y0: np.ndarray,
        par: np.ndarray,
        margins: dict[str, np.ndarray],
        *,
        warm: bool = False,
        max_iter: int | None = None,
        multipliers: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, str, int]:
        """Solve from ``y0``; ``warm`` re-uses the multipliers of the previous solve (or ``multipliers``);
        ``max_iter`` screens."""
        if warm and multipliers is not None:
            self._multipliers = multipliers
        lbg, ubg = self.bounds(margins)
        me = threading.get_ident()
        _SOLVING.add(me)
        try:
            if max_iter is not None:
                solver = self.screen_solver(max_iter)
                sol = solver(x0=y0, p=par, lbg=lbg, ubg=ubg)
            elif warm and self._multipliers is not None and _WARM_OPTIONS:
                solver = self.warm_solver
                sol = solver(
                    x0=y0, p=par, lbg=lbg, ubg=ubg, lam_g0=self._multipliers[0], lam_x0=self._multipliers[1]
                )
            else:
                solver = self.solver
                sol = solver(x0=y0, p=par, lbg=lbg, ubg=ubg)
        finally:
            _SOLVING.discard(me)
        self._multipliers = (np.asarray(sol["lam_g"]).ravel(), np.asarray(sol["lam_x"]).ravel())
        stats = solver.stats()
        return np.asarray(sol["x"]).ravel(), str(stats.get("return_status", "?")), int(stats.get("iter_count", -1))


_NLPS: dict[tuple, _Nlp] = {}
_NLPS_LOCK = threading.Lock()


def _graph_key(problem: ExcitationProblem) -> tuple:
    cart = problem.cartesian
    axes = () if cart is None or not cart.active else tuple(np.isfinite(np.concatenate(cart.bounds())))
    return (
        problem.robot.key,
        problem.n,
        problem.harmonics,
        problem.base_freq,
        problem.grid,
        problem.criterion,
        problem.sharpness,
        np.asarray(problem.noise_std).tobytes(),
        axes,
    )


def _nlp(problem: ExcitationProblem, functions: _Functions) -> _Nlp:
    # One per thread too: a solver keeps the multipliers of its last solve (threading backend, or a
    # Dask worker's threads).  The cache is shared by those threads: its reads and writes hold a lock,
    # and it keeps a few graphs per live thread, so that no thread rebuilds its solvers for every try.
    key = (*_graph_key(problem), threading.get_ident())
    with _NLPS_LOCK:
        nlp = _NLPS.get(key)
    if nlp is None:
        nlp = _Nlp(problem, functions)  # built outside the lock: threads build theirs at once
        with _NLPS_LOCK:
            while len(_NLPS) >= max(4, 2 * threading.active_count()):
                _NLPS.pop(next(iter(_NLPS)))
            _NLPS[key] = nlp
    else:
        nlp.problem = problem  # same graph; the limits (bounds) may differ
    return nlp


# ---------------------------------------------------------------------------- one try
def _hidden_overshoot(problem: ExcitationProblem, traj: FourierTrajectory) -> dict[str, np.ndarray]:
    """Largest overshoot between optimisation grid points that the curvature of ``traj`` allows.

    A quantity x peaking between two samples h apart sits at most ``max|x''| (h/2)^2 / 2`` above the
    nearer sample: positions by the acceleration, velocities by the jerk, accelerations by the snap.
    """
    h = problem.period / problem.grid
    k = 0.5 * (0.5 * h) ** 2
    _, _, ddq, jerk, snap = _series(problem, traj.a, traj.b, problem.times(fine=True))
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
class _TryResult:
    index: int
    start: FourierTrajectory
    trajectory: FourierTrajectory
    feasible: bool
    status: str
    iterations: int
    rounds: int
    seconds: float
    multipliers: tuple[np.ndarray, np.ndarray] | None = None


def _solve_try(
    problem: ExcitationProblem,
    functions: _Functions,
    par: np.ndarray,
    seed: tuple[int, ...],
    index: int,
    max_rounds: int,
    screen_iter: int | None = None,
    screened: _TryResult | None = None,
) -> _TryResult:
    """Optimise from one random start; tighten and re-solve while the check grid shows an overshoot.

    ``screen_iter``: one solve of at most that many iterations, nothing checked (a screening pass).
    ``screened``: continue that screening result (its point and multipliers) to the end instead.
    """
    with _interruptible():
        if screen_iter is not None:
            return _screen_try(problem, functions, par, seed, index, screen_iter)
        return _solve_try_guarded(problem, functions, par, seed, index, max_rounds, screened)


def _screen_try(
    problem: ExcitationProblem,
    functions: _Functions,
    par: np.ndarray,
    seed: tuple[int, ...],
    index: int,
    screen_iter: int,
) -> _TryResult:
    t0 = time.perf_counter()
    start = problem.random_trajectory(np.random.default_rng(list(seed)), amplitude=0.9)
    nlp = _nlp(problem, functions)
    zero = {key: np.zeros(problem.n) for key in ("q_low", "q_high", "dq", "ddq")}
    zero.update(cart_low=np.zeros(3), cart_high=np.zeros(3))
    y, status, it = nlp.solve(problem.to_vector(start), par, zero, max_iter=screen_iter)
    _check_stop()
    finite = bool(np.all(np.isfinite(y)))
    return _TryResult(
        index=index,
        start=start,
        trajectory=problem.to_trajectory(y) if finite else start,
        feasible=finite,  # worth continuing; the limits are checked after the full solve
        status=status,
        iterations=it,
        rounds=1,
        seconds=time.perf_counter() - t0,
        multipliers=nlp._multipliers,
    )


def _solve_try_guarded(
    problem: ExcitationProblem,
    functions: _Functions,
    par: np.ndarray,
    seed: tuple[int, ...],
    index: int,
    max_rounds: int,
    screened: _TryResult | None = None,
) -> _TryResult:
    t0 = time.perf_counter()
    if screened is None:
        start = problem.random_trajectory(np.random.default_rng(list(seed)), amplitude=0.9)
    else:
        start = screened.start
    nlp = _nlp(problem, functions)
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
        _check_stop()
        iterations += it
        if not np.all(np.isfinite(y)):
            break
        traj = problem.to_trajectory(y)
        viol = problem.violations(traj, functions)
        if _feasible(robot, viol):
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
    return _TryResult(
        index=index,
        start=start,
        trajectory=traj,
        feasible=feasible,
        status=status,
        iterations=iterations,
        rounds=rounds,
        seconds=time.perf_counter() - t0,
    )


# ---------------------------------------------------------------------------- the design
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
            "n_base": int(_functions(problem).n_base),
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


def _check_rank(problem: ExcitationProblem, functions: _Functions, rng: np.random.Generator) -> None:
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


def _random_pool(
    problem: ExcitationProblem, functions: _Functions, rng: np.random.Generator, size: int
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


def _greedy_baseline(
    pool_H: list[np.ndarray],
    count: int,
    criterion: str,
    data: _CriterionData,
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


def _information(H: np.ndarray) -> np.ndarray:
    return H.T @ H


# joblib's process pool (loky) starts a resource tracker that shares the command's stderr.  When Ctrl-C
# reaches the whole process group, the tracker may outlive the command by a moment and warn of "leaked"
# semaphores that the command had already unlinked (the warning ends with a FileNotFoundError), after the
# command's one line.  The tracker is started with this interpreter's -W options: this one silences its
# warnings alone.  It still unlinks whatever did leak.
_QUIET_TRACKER = "ignore::UserWarning:joblib.externals.loky.backend.resource_tracker"


def _parallel(n_jobs: int, backend: str | None):
    import sys

    import joblib

    if _QUIET_TRACKER not in sys.warnoptions:
        sys.warnoptions.append(_QUIET_TRACKER)
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
    with _interruptible():
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
    t_start = time.perf_counter()
    for label, value, low in (
        ("trajectories", trajectories, 1),
        ("patience", patience, 1),
        ("max_tries", max_tries, 1),
        ("baseline", baseline, 1),
        ("max_rounds", max_rounds, 1),
        ("polish", polish, 1),
        ("screen_iter", 1 if screen_iter is None else screen_iter, 1),
    ):
        if int(value) != value or value < low:
            raise UsageError(f"{label} is {value}; give a whole number of at least {low}.")
    if n_jobs == 0 or int(n_jobs) != n_jobs:
        raise UsageError(f"n_jobs is {n_jobs}; give a positive number of parallel tries, or -1 for every core.")
    import joblib

    functions = _functions(problem)
    gravity = functions.gravity_related
    nb = functions.n_base
    criterion = problem.criterion
    _check_rank(problem, functions, np.random.default_rng([seed, 0, 0]))

    # Baseline pool: random feasible trajectories, the weights of the criterion, greedy stacks.
    pool = _random_pool(problem, functions, np.random.default_rng([seed, 0, 1]), baseline)
    pool_H = [problem.regressor(traj) for traj in pool]
    data = _criterion_data(np.vstack(pool_H), gravity)
    # every pool trajectory's exact figures once (three SVDs each), for both greedy stacks' first step
    alone = [exact_figures(H, criterion, data, gravity) for H in pool_H]
    baseline_cond = _greedy_baseline(pool_H, trajectories, "cond", data, gravity, alone)
    baseline_objective = _greedy_baseline(pool_H, trajectories, criterion, data, gravity, alone)

    batch = max(1, joblib.effective_n_jobs(n_jobs))
    parallel = _parallel(n_jobs, backend)
    kept: list[FourierTrajectory] = []
    stages: list[StageRecord] = []
    stack_fine = np.zeros((0, nb))
    prior = np.zeros((nb, nb))
    final = None
    for stage in range(1, trajectories + 1):
        t_stage = time.perf_counter()
        par = np.concatenate([prior.ravel(order="F"), data.weights, data.scale])
        best = None
        best_fig = None
        fails = tries = feasible_tries = polished = 0
        screened: list[tuple[float, int, _TryResult]] = []
        while fails < patience and tries < max_tries:
            _check_stop()  # a signal CasADi swallowed in this process (baseline, a try run here)
            size = min(batch, max_tries - tries)
            jobs = (
                joblib.delayed(_solve_try)(
                    problem, functions, par, (seed, stage, tries + i), tries + i, max_rounds, screen_iter
                )
                for i in range(size)
            )
            for res in parallel(jobs):
                tries += 1
                if res.feasible:
                    feasible_tries += 1
                    fig = exact_figures(
                        np.vstack([stack_fine, problem.regressor(res.trajectory)]), criterion, data, gravity
                    )
                    if screen_iter is not None:
                        screened.append((fig["objective"], res.index, res))
                    if best_fig is None or fig["objective"] < best_fig["objective"]:
                        best, best_fig, fails = res, fig, 0
                        continue
                fails += 1
                if fails >= patience:
                    break  # the rest of this batch is discarded: the result does not depend on n_jobs
        if screen_iter is not None:
            # the screened tries, best first, continued to the end (limits checked) by batches of `polish`
            screened.sort(key=lambda item: (item[0], item[1]))
            best = best_fig = None
            for first in range(0, len(screened), polish):
                _check_stop()
                jobs = (
                    joblib.delayed(_solve_try)(
                        problem, functions, par, None, item[2].index, max_rounds, None, item[2]
                    )
                    for item in screened[first : first + polish]
                )
                for res in parallel(jobs):
                    polished += 1
                    if not res.feasible:
                        continue
                    fig = exact_figures(
                        np.vstack([stack_fine, problem.regressor(res.trajectory)]), criterion, data, gravity
                    )
                    if best_fig is None or fig["objective"] < best_fig["objective"]:
                        best, best_fig = res, fig
                if best is not None:
                    break
        if best is None:
            raise ExcitationError(
                f"none of {tries} optimisations of trajectory {stage} met every limit of '{problem.robot.name}' "
                f"on the check grid (last IPOPT status: {res.status}); loosen the limits or the Cartesian "
                "constraints, or allow more tries (max_tries) and rounds (max_rounds)."
            )
        _check_stop()
        start_fig = exact_figures(np.vstack([stack_fine, problem.regressor(best.start)]), criterion, data, gravity)
        traj = best.trajectory
        kept.append(traj)
        stack_fine = np.vstack([stack_fine, problem.regressor(traj)])
        prior = prior + _information(problem.regressor(traj, fine=False))
        final = best_fig
        record = StageRecord(
            tries=tries,
            kept=best.index,
            feasible_tries=feasible_tries,
            polished=polished,
            start_cond=start_fig["cond"],
            cond=best_fig["cond"],
            start_objective=start_fig["objective"],
            objective=best_fig["objective"],
            status=best.status,
            iterations=best.iterations,
            rounds=best.rounds,
            seconds=time.perf_counter() - t_stage,
        )
        stages.append(record)
        if progress:
            progress(
                f"trajectory {stage}/{trajectories}: cond {record.start_cond:.4g} (random start) -> "
                f"{record.cond:.4g}, {criterion} {record.objective:.4g}; {tries} tries, kept #{best.index + 1}, "
                f"{record.seconds:.1f} s"
            )
    assert final is not None
    feasible = all(problem.is_feasible(t, functions) for t in kept)
    metas = []
    for k, traj in enumerate(kept):
        meta = {
            "robot": problem.robot.name,
            "criterion": criterion,
            "index": k + 1,
            "of": len(kept),
            "cond_stack": stages[k].cond,
            "cond": float(np.linalg.cond(problem.regressor(traj))),
            "noise_std": problem.noise_std.tolist(),
            "seed": seed,
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
        baseline_cond=baseline_cond,
        baseline_objective=baseline_objective,
        feasible=feasible,
        stages=tuple(stages),
        weights=weights,
        seconds=time.perf_counter() - t_start,
        seed=seed,
    )
