"""What an excitation trajectory must do: the robot, the Fourier series, the grids and the limits.

:class:`ExcitationProblem` holds the series' parametrisation (coordinates in the null spaces of the rest
conditions), its random feasible trajectories, the bounds over a whole period that its limits are checked
with, and the noise-weighted base regressor over one period; :class:`CartesianLimits` the tool's floor
and box.  The robot's numeric functions (base regressor, forward kinematics, compiled library) are built
once per robot and process (:func:`excitation_functions`).  The method is in :mod:`dynid.optim.excitation`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import casadi as ca
import numpy as np
import scipy.linalg

from dynid.exceptions import UsageError
from dynid.optim.criteria import CRITERIA
from dynid.optim.trajectory import FourierTrajectory
from dynid.symbolic.robot import RobotModel

__all__ = [
    "MAX_HARMONICS",
    "MIN_BASE_FREQ",
    "CartesianLimits",
    "ExcitationFunctions",
    "ExcitationProblem",
    "check_harmonics",
    "compiled_library",
    "excitation_functions",
    "fourier_series",
    "meets_limits",
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
        The objective (:mod:`dynid.optim.excitation`).
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
        Exponent p of the smooth extreme-eigenvalue surrogate (:mod:`dynid.optim.excitation`); ``inf`` for the
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
        """A random trajectory within the joint limits on the check grid (:mod:`dynid.optim.excitation`).

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
        swing, dq, ddq, jerk, snap = fourier_series(self, a, b, t)
        k = 0.5 * (0.5 * (t[1] - t[0])) ** 2
        hidden_q = k * np.abs(ddq).max(axis=0)
        return {
            "swing_max": swing.max(axis=0) + hidden_q,
            "swing_min": swing.min(axis=0) - hidden_q,
            "dq": np.abs(dq).max(axis=0) + k * np.abs(jerk).max(axis=0),
            "ddq": np.abs(ddq).max(axis=0) + k * np.abs(snap).max(axis=0),
        }

    def violations(
        self, traj: FourierTrajectory, functions: ExcitationFunctions | None = None
    ) -> dict[str, np.ndarray]:
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
            functions = functions or excitation_functions(self)
            p = functions.tool_positions(traj.evaluate(self.times(fine=True))[0])
            lo, hi = self.cartesian.bounds()
            with np.errstate(invalid="ignore"):
                out["cart_low"] = np.nan_to_num(lo - p.min(axis=0), nan=-np.inf, neginf=-np.inf)
                out["cart_high"] = np.nan_to_num(p.max(axis=0) - hi, nan=-np.inf, neginf=-np.inf)
        return out

    def is_feasible(self, traj: FourierTrajectory, functions: ExcitationFunctions | None = None) -> bool:
        """True when every limit holds on the check grid (to 1e-9 relative)."""
        return meets_limits(self.robot, self.violations(traj, functions))

    # ------------------------------------------------------------------ exact figures
    def regressor(self, traj: FourierTrajectory, *, fine: bool = True) -> np.ndarray:
        """The noise-weighted base regressor H* over one period, shape (m n, n_b).

        On the check grid (default) through the compiled library; on the optimisation grid for the
        rows stacked into later designs.
        """
        functions = excitation_functions(self)
        t = self.times(fine=fine)[: None if fine else self.grid]
        q, dq, ddq = traj.evaluate(t)
        return functions.weighted_regressor(q, dq, ddq, self.noise_std)


def fourier_series(
    problem: ExcitationProblem, a: np.ndarray, b: np.ndarray, t: np.ndarray
) -> tuple[np.ndarray, ...]:
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


def meets_limits(robot: RobotModel, viol: dict[str, np.ndarray]) -> bool:
    """True when no excess of :meth:`ExcitationProblem.violations` is above 1e-9 of its limit."""
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
class ExcitationFunctions:
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
        Y = compiled_library(self.robot).base_regressor(q, dq, ddq)  # (m, n, n_b)
        Y = Y / np.asarray(noise_std)[None, :, None]
        return Y.reshape(-1, Y.shape[2])

    def tool_positions(self, q: np.ndarray) -> np.ndarray:
        """Tool frame origin (m, 3) through the CasADi virtual machine (no compiled library needed)."""
        p = self.fk.map(q.shape[0])(q.T)[0]
        return np.asarray(p).T


_FUNCTIONS: dict[str, ExcitationFunctions] = {}
_COMPILED: dict[str, object] = {}


def compiled_library(robot: RobotModel):
    """The robot's compiled library (one per process; building it computes the base parameters)."""
    lib = _COMPILED.get(robot.key)
    if lib is None:
        from dynid.symbolic.export import compiled_functions

        lib = _COMPILED[robot.key] = compiled_functions(robot, progress=None)
    return lib


def excitation_functions(problem: ExcitationProblem) -> ExcitationFunctions:
    """The robot's numeric functions (one per robot and process; building them computes the base parameters)."""
    key = problem.robot.key
    cached = _FUNCTIONS.get(key)
    if cached is not None:
        return cached
    from dynid.symbolic.base import base_parameters
    from dynid.symbolic.functions import robot_functions

    funcs = robot_functions(problem.robot, progress=None)
    base = base_parameters(funcs)
    out = ExcitationFunctions(
        base_regressor=base.base_regressor,
        fk=funcs.fk,
        gravity_related=np.asarray(base.gravity_related, dtype=bool),
        names=base.names,
        robot=problem.robot,
    )
    _FUNCTIONS[key] = out
    return out
