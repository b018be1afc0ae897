"""Executable excitation: jerk-limited approach from a home pose, the excitation(s), and a retreat.

An excitation trajectory starts and ends at rest at ``q(t0)``, which is not where the robot stands.
:func:`executable_trajectory` joins, on one uniform time grid at the controller rate::

    home --approach--> q_1(t0) --excitation 1--> q_1(tf) --transfer--> q_2(t0) --excitation 2--> ... --retreat--> home

The point-to-point segments come from ruckig (time-optimal, jerk-limited, start and end at rest).
ruckig's intermediate waypoints need its cloud service, so each segment is its own point-to-point
problem, chained.  Its velocity and acceleration limits are the robot's, times ``speed_fraction``;
its jerk limit is ``jerk_factor`` times the acceleration limit.  Each segment's duration is rounded
up to a whole number of controller periods (ruckig's ``minimum_duration``), so every excitation
starts on a sample.  Between its two rest points every joint moves monotonically, so the segment
stays inside the joint range when both ends do; it is checked on the samples all the same.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dynid.exceptions import UsageError
from dynid.optim.trajectory import FourierTrajectory, SampledTrajectory
from dynid.symbolic.robot import RobotModel

__all__ = [
    "MAX_SAMPLES",
    "Segment",
    "check_length",
    "default_home",
    "executable_trajectory",
    "point_to_point",
]

MAX_SAMPLES = 1_000_000
"""Most samples of an executable trajectory (2000 s at 500 Hz): the sampled file is built in memory."""


def check_length(seconds: float, rate: float, what: str = "the executable trajectory") -> None:
    """Refuse a sampled trajectory longer than :data:`MAX_SAMPLES` samples at ``rate`` (Hz)."""
    if seconds * rate > MAX_SAMPLES:
        raise UsageError(
            f"{what} would last {seconds:.4g} s, {seconds * rate:.3g} samples at {rate:g} Hz, beyond the "
            f"{MAX_SAMPLES:,} dynid writes in one file; shorten it (fewer --periods, a shorter --rest, a higher "
            "--base-freq or --speed-fraction)."
        )


def default_home(robot: RobotModel) -> np.ndarray:
    """The default home pose: the middle of each joint's range (rad or m)."""
    return 0.5 * (robot.q_min + robot.q_max)


def check_pose(robot: RobotModel, pose, label: str = "home pose") -> np.ndarray:
    """Return ``pose`` as an (n,) array within the joint limits, or raise :class:`UsageError`."""
    arr = np.asarray(pose, dtype=float).ravel()
    if arr.shape != (robot.n,) or not np.all(np.isfinite(arr)):
        raise UsageError(
            f"the {label} has {arr.size} values; the robot '{robot.name}' has {robot.n} joints, give {robot.n} "
            "finite joint positions (rad)."
        )
    outside = (arr < robot.q_min) | (arr > robot.q_max)
    if np.any(outside):
        j = int(np.argmax(outside))
        raise UsageError(
            f"the {label} puts joint {j + 1} at {arr[j]:.4g}, outside its limits [{robot.q_min[j]:.4g}, "
            f"{robot.q_max[j]:.4g}] of the robot '{robot.name}'; give a pose within the joint limits."
        )
    return arr


@dataclass(frozen=True, eq=False, kw_only=True)
class Segment:
    """A piece of the executable trajectory on [start, start + duration] (s).

    Attributes
    ----------
    kind : str
        ``rest``, ``approach``, ``excitation``, ``transfer`` or ``retreat``.
    start, duration : float
        Start time in the joined trajectory and length (s).
    index : int
        Number of the excitation (1-based) for ``excitation`` segments, else 0.
    """

    kind: str
    start: float
    duration: float
    index: int = 0
    _ruckig: object | None = None
    _fourier: FourierTrajectory | None = None
    _pose: np.ndarray | None = None  # a rest: held still at this pose

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, dq, ddq at local times ``t`` in [0, duration]: each (len(t), n)."""
        t = np.clip(np.asarray(t, dtype=float), 0.0, self.duration)
        if self._pose is not None:
            zeros = np.zeros((t.size, self._pose.size))
            return np.broadcast_to(self._pose, zeros.shape).copy(), zeros, zeros.copy()
        if self._fourier is not None:
            return self._fourier.evaluate(t)
        rows = [self._ruckig.at_time(float(ti)) for ti in t]
        return (
            np.array([r[0] for r in rows], dtype=float),
            np.array([r[1] for r in rows], dtype=float),
            np.array([r[2] for r in rows], dtype=float),
        )

    def to_dict(self) -> dict:
        return {"kind": self.kind, "start": self.start, "duration": self.duration, "index": self.index}


def _ruckig_limits(robot: RobotModel, speed_fraction: float, jerk_factor: float):
    if not (0 < speed_fraction <= 1):  # also nan
        raise UsageError(f"speed_fraction is {speed_fraction}; give a fraction of the robot's limits in (0, 1].")
    if not (math.isfinite(jerk_factor) and jerk_factor > 0):
        raise UsageError(f"jerk_factor is {jerk_factor}; give a positive factor (jerk limit = factor x ddq_max).")
    return robot.dq_max * speed_fraction, robot.ddq_max * speed_fraction, robot.ddq_max * jerk_factor


def point_to_point(
    robot: RobotModel,
    start,
    goal,
    *,
    rate: float | None = None,
    speed_fraction: float = 0.5,
    jerk_factor: float = 5.0,
    kind: str = "approach",
    offset: float = 0.0,
) -> Segment:
    """A time-optimal, jerk-limited motion from rest at ``start`` to rest at ``goal`` (ruckig).

    Parameters
    ----------
    robot : RobotModel
        Its limits give ruckig's: ``speed_fraction * dq_max``, ``speed_fraction * ddq_max`` and
        ``jerk_factor * ddq_max``.
    start, goal : array_like, shape (n,)
        Joint positions (rad), both within the joint limits.
    rate : float, optional
        Controller rate (Hz); the duration is rounded up to a whole number of periods.
    speed_fraction : float
        Fraction (0, 1] of the velocity and acceleration limits used.
    jerk_factor : float
        Jerk limit as a multiple of the acceleration limit (rad/s^3 per rad/s^2).
    kind : str
        Label of the segment.
    offset : float
        Start time of the segment in a joined trajectory (s).
    """
    from ruckig import InputParameter, Result, Ruckig, Trajectory

    start = check_pose(robot, start, "start pose" if kind != "approach" else "home pose")
    goal = check_pose(robot, goal, "goal pose" if kind != "retreat" else "home pose")
    vmax, amax, jmax = _ruckig_limits(robot, speed_fraction, jerk_factor)
    n = robot.n
    inp = InputParameter(n)
    inp.current_position = start.tolist()
    inp.current_velocity = [0.0] * n
    inp.current_acceleration = [0.0] * n
    inp.target_position = goal.tolist()
    inp.target_velocity = [0.0] * n
    inp.target_acceleration = [0.0] * n
    inp.max_velocity = vmax.tolist()
    inp.max_acceleration = amax.tolist()
    inp.max_jerk = jmax.tolist()
    otg = Ruckig(n)
    traj = Trajectory(n)
    try:
        result = otg.calculate(inp, traj)
    except ValueError:  # an error code the binding's enum lacks (-101: beyond ruckig's numerical range)
        result = None
    if result is None:
        raise UsageError(
            f"ruckig could not plan the {kind} from {np.round(start, 4).tolist()} to {np.round(goal, 4).tolist()}: "
            f"at {speed_fraction:g} of the velocity and acceleration limits it would last beyond ruckig's numerical "
            "range; give a larger speed fraction (--speed-fraction, default 0.5)."
        )
    if result != Result.Working:
        raise UsageError(
            f"ruckig could not plan the {kind} from {np.round(start, 4).tolist()} to {np.round(goal, 4).tolist()} "
            f"({result}); check the robot's velocity, acceleration and jerk limits."
        )
    if rate is not None:
        steps = math.ceil(traj.duration * rate - 1e-9)
        rounded = steps / rate
        if rounded > traj.duration:
            inp.minimum_duration = rounded
            result = otg.calculate(inp, traj)
            if result != Result.Working:  # pragma: no cover - ruckig slows down a feasible profile
                raise UsageError(f"ruckig could not stretch the {kind} to {rounded} s ({result}).")
    return Segment(kind=kind, start=offset, duration=float(traj.duration), _ruckig=traj)


def executable_trajectory(
    robot: RobotModel,
    excitations: Sequence[FourierTrajectory] | FourierTrajectory,
    *,
    rate: float,
    home=None,
    periods: int = 1,
    rest: float = 0.0,
    speed_fraction: float = 0.5,
    jerk_factor: float = 5.0,
) -> SampledTrajectory:
    """Approach, excitation(s) and retreat on one uniform grid at ``rate`` Hz (module docstring).

    Parameters
    ----------
    robot : RobotModel
        The robot (limits, joint count).
    excitations : FourierTrajectory or sequence of them
        Run one after the other, each for ``periods`` periods, joined by ruckig transfers.
    rate : float
        Controller rate (Hz).
    home : array_like, shape (n,), optional
        Start and end pose (rad); default the middle of the joint ranges.  Must lie within the limits.
    periods : int
        Periods of each excitation (identification averages over them).
    rest : float
        Seconds held still at ``home`` before the approach and after the retreat (default 0).  Rests give
        the sensor offsets and the torque noise at standstill, and mark where the motion starts and ends.
    speed_fraction, jerk_factor : float
        ruckig limits, see :func:`point_to_point`.

    Returns
    -------
    SampledTrajectory
        ``meta["segments"]`` lists each piece (kind, start, duration, index).
    """
    if isinstance(excitations, FourierTrajectory):
        excitations = [excitations]
    if not excitations:
        raise UsageError("no excitation trajectory given; pass at least one FourierTrajectory.")
    if not (math.isfinite(rate) and rate > 0):
        raise UsageError(f"the controller rate is {rate}; give a positive rate in Hz, e.g. 500.")
    if int(periods) != periods or periods < 1:
        raise UsageError(f"periods is {periods}; give a whole number of at least 1.")
    for k, exc in enumerate(excitations):
        if exc.n != robot.n:
            raise UsageError(
                f"excitation {k + 1} has {exc.n} joints; the robot '{robot.name}' has {robot.n}: design it for this robot."
            )
    home = default_home(robot) if home is None else check_pose(robot, home)
    if not (math.isfinite(rest) and rest >= 0):
        raise UsageError(f"the rest is {rest} s; give a duration of at least 0 s, e.g. 2.")
    segments: list[Segment] = []
    clock = 0.0
    pose = home
    if rest > 0:
        segments.append(Segment(kind="rest", start=0.0, duration=float(rest), _pose=np.asarray(home, float)))
        clock += float(rest)
    for k, exc in enumerate(excitations):
        repeated = FourierTrajectory(a=exc.a, b=exc.b, c=exc.c, base_freq=exc.base_freq, periods=int(periods))
        q0 = repeated.evaluate([0.0])[0][0]
        seg = point_to_point(
            robot,
            pose,
            q0,
            rate=rate,
            speed_fraction=speed_fraction,
            jerk_factor=jerk_factor,
            kind="approach" if k == 0 else "transfer",
            offset=clock,
        )
        segments.append(seg)
        clock += seg.duration
        segments.append(Segment(kind="excitation", start=clock, duration=repeated.duration, index=k + 1,
                                _fourier=repeated))
        clock += repeated.duration
        pose = repeated.evaluate([repeated.duration])[0][0]
    seg = point_to_point(
        robot, pose, home, rate=rate, speed_fraction=speed_fraction, jerk_factor=jerk_factor, kind="retreat",
        offset=clock,
    )
    segments.append(seg)
    clock += seg.duration
    if rest > 0:
        segments.append(Segment(kind="rest", start=clock, duration=float(rest), _pose=np.asarray(home, float)))
        clock += float(rest)

    check_length(clock, rate)
    steps = math.ceil(clock * rate - 1e-9)
    t = np.arange(steps + 1) / rate
    q = np.empty((t.size, robot.n))
    dq = np.empty_like(q)
    ddq = np.empty_like(q)
    starts = np.array([s.start for s in segments])
    which = np.clip(np.searchsorted(starts, t + 1e-9 / rate, side="right") - 1, 0, len(segments) - 1)
    for i, seg in enumerate(segments):
        mask = which == i
        if np.any(mask):
            q[mask], dq[mask], ddq[mask] = seg.evaluate(t[mask] - seg.start)
    # After the retreat's end (at most one period): at rest at home.
    late = t > clock
    q[late], dq[late], ddq[late] = home, 0.0, 0.0
    _check_limits(robot, q, dq, ddq, t, segments)
    return SampledTrajectory(
        t=t,
        q=q,
        dq=dq,
        ddq=ddq,
        meta={
            "robot": robot.name,
            "rate": rate,
            "home": home.tolist(),
            "segments": [s.to_dict() for s in segments],
            "speed_fraction": speed_fraction,
            "jerk_factor": jerk_factor,
        },
    )


def _check_limits(robot: RobotModel, q, dq, ddq, t, segments: list[Segment]) -> None:
    """Raise when a sample of the joined trajectory leaves the joint limits (1e-9 relative slack)."""
    span = robot.q_max - robot.q_min
    checks = (
        ("position", np.maximum(robot.q_min - q, q - robot.q_max) / span),
        ("velocity", (np.abs(dq) - robot.dq_max) / robot.dq_max),
        ("acceleration", (np.abs(ddq) - robot.ddq_max) / robot.ddq_max),
    )
    for label, excess in checks:
        if np.any(excess > 1e-9):
            i, j = np.unravel_index(int(np.argmax(excess)), excess.shape)
            seg = next(s for s in reversed(segments) if s.start <= t[i] + 1e-12)
            name = f"{seg.kind} {seg.index}" if seg.index else seg.kind
            raise UsageError(
                f"the {name} exceeds the {label} limit of joint {j + 1} at t = {t[i]:.3f} s; design the excitation "
                "for these limits (dynid excite) or lower speed_fraction."
            )
