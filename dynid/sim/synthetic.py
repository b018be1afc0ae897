"""Synthetic identification data made from the regressor itself (tests and benchmarks).

``tau = W(q, dq, ddq) x_true (+ friction(dq) + unmodelled(q, dq)) + noise`` on random Fourier motions.
This is not the simulator (:mod:`dynid.sim.simulator`, forward dynamics with effects); it is the
shortest path to data whose truth is known exactly in the identified parameters.

:func:`random_fourier` is the ONE random excitation of synthetic data: these regressor datasets, the
simulated cases of the gap diagnosis (:func:`dynid.sim.cases.case_excitation`) and the benchmarks.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from dynid.data.dataset import Dataset
from dynid.exceptions import UsageError
from dynid.identify.columns import ColumnSet, linear_torque
from dynid.optim.trajectory import FourierTrajectory

__all__ = ["random_fourier", "synthetic_dataset", "true_parameters"]


_SAMPLES = {"joint": 2000, "arm": 4000}  # points per period on which the limits are checked
_ARM_REACH = 1.2  # rad: "arm" scaling keeps each angle within this of the centre (and 80 % of its half-range)


def random_fourier(
    robot,
    rng: np.random.Generator,
    *,
    harmonics: int = 5,
    base_freq: float = 0.1,
    periods: int = 1,
    fraction: float = 0.6,
    still: tuple[int, ...] = (),
    centre=None,
    scaling: str = "joint",
) -> FourierTrajectory:
    """A random Fourier motion within ``fraction`` of the robot's limits: the ONE synthetic excitation.

    The coefficients are standard normal draws from ``rng`` (``a`` then ``b``, each (harmonics, n)),
    then scaled in one of two ways:

    ``scaling="joint"``
        each joint on its own, to ``fraction`` of the tightest of its position half-range
        (``min(q_max - q_min, 2 pi) / 2``), speed and acceleration limit; the motion's mean sits on
        ``centre`` (default the middle of each joint's range).
    ``scaling="arm"``
        one factor for all joints (the motion keeps its shape across joints): ``fraction`` of the
        tightest speed and acceleration limit of any joint, and every angle within
        ``min(0.8 half-range, 1.2 rad)`` of ``centre`` (default the middle of each joint's range
        clipped to +-pi), the half-range also clipped to +-pi.  The offset ``c`` is the centre itself.

    Parameters
    ----------
    robot : RobotModel
        The robot (its limits scale the motion).
    rng : numpy.random.Generator
        Random source of the coefficients.
    harmonics : int
        Harmonics per joint.
    base_freq : float
        Base frequency (Hz).
    periods : int
        Periods the trajectory lasts.
    fraction : float
        Share of each limit the motion may use.
    still : tuple of int
        Joints (1-based) that do not move (``scaling="joint"`` only).
    centre : array_like, shape (n,), optional
        Centre posture (rad), e.g. :func:`dynid.sim.cases.case_centre`; default the middle of the range.
    scaling : {"joint", "arm"}
        Scale each joint on its own, or the whole arm by one factor (see above).

    Raises
    ------
    UsageError
        An unknown scaling, ``still`` joints with ``scaling="arm"``, or a centre of the wrong length.
    """
    if scaling not in _SAMPLES:
        raise UsageError(
            f"the scaling is '{scaling}'; give 'joint' (each joint on its own) or 'arm' (one factor)."
        )
    if still and scaling != "joint":
        raise UsageError(
            f"still joints {still} need scaling='joint' (one factor for the arm cannot hold a joint still); "
            "give scaling='joint' or no still joints."
        )
    n = robot.n
    if centre is not None:
        centre = np.asarray(centre, dtype=float)
        if centre.shape != (n,):
            raise UsageError(
                f"the centre posture has shape {centre.shape}; the robot '{robot.name}' has {n} joints, "
                f"give {n} angles (rad)."
            )
    a = rng.normal(size=(harmonics, n))
    b = rng.normal(size=(harmonics, n))
    if scaling == "arm":
        return _scale_arm(robot, a, b, base_freq, periods, fraction, centre)
    traj = FourierTrajectory(a=a, b=b, c=np.zeros(n), base_freq=base_freq, periods=periods)
    t = np.linspace(0.0, traj.period, _SAMPLES["joint"])
    q, dq, ddq = traj.evaluate(t)
    q = q - q.mean(axis=0)
    span = np.minimum(robot.q_max - robot.q_min, 2 * np.pi) / 2
    middle = 0.5 * (robot.q_max + robot.q_min) if centre is None else centre
    scale = fraction * np.min(
        np.vstack(
            [
                span / np.abs(q).max(axis=0),
                robot.dq_max / np.abs(dq).max(axis=0),
                robot.ddq_max / np.abs(ddq).max(axis=0),
            ]
        ),
        axis=0,
    )
    for j in still:
        scale[j - 1] = 0.0
    c = middle - scale * traj.evaluate(t)[0].mean(axis=0)
    return FourierTrajectory(a=a * scale, b=b * scale, c=c, base_freq=base_freq, periods=periods)


def _scale_arm(robot, a, b, base_freq, periods, fraction, centre) -> FourierTrajectory:
    """``scaling="arm"`` of :func:`random_fourier`: one factor for all joints, offset = centre."""
    lo, hi = np.maximum(robot.q_min, -math.pi), np.minimum(robot.q_max, math.pi)
    c = 0.5 * (lo + hi) if centre is None else centre
    half = np.minimum(0.5 * (hi - lo) * 0.8, _ARM_REACH)
    traj = FourierTrajectory(a=a, b=b, c=c, base_freq=base_freq)
    q, dq, ddq = traj.evaluate(np.linspace(0.0, 1.0 / base_freq, _SAMPLES["arm"]))
    s = min(
        float(np.min(fraction * robot.dq_max / np.max(np.abs(dq), axis=0))),
        float(np.min(fraction * robot.ddq_max / np.max(np.abs(ddq), axis=0))),
        float(np.min(half / np.max(np.abs(q - c), axis=0))),
    )
    return FourierTrajectory(a=a * s, b=b * s, c=c, base_freq=base_freq, periods=periods)


def true_parameters(columns: ColumnSet, rng: np.random.Generator | None = None) -> NDArray[np.float64]:
    """Identified parameters of the robot's own (URDF) standard parameters, plus made-up extras.

    Parameters
    ----------
    columns : ColumnSet
        The identified parameters.
    rng : numpy.random.Generator, optional
        Draws the armature (0.01-0.05 kg m^2), Coulomb (0.5-3 N m), viscous (0.2-2 N m s/rad) and
        offset (-0.5..0.5 N m) per joint; without it they are zero.
    """
    n = columns.n
    phi = np.zeros(14 * n)
    phi[: 10 * n] = columns.robot.params
    if rng is not None:
        phi[10 * n : 11 * n] = rng.uniform(0.01, 0.05, n)
        phi[11 * n : 12 * n] = rng.uniform(0.5, 3.0, n)
        phi[12 * n : 13 * n] = rng.uniform(0.2, 2.0, n)
        phi[13 * n : 14 * n] = rng.uniform(-0.5, 0.5, n)
    phi[10 * n :] *= columns.enabled_extras
    return columns.P @ phi


def synthetic_dataset(
    columns: ColumnSet,
    x_true: NDArray[np.float64],
    traj: FourierTrajectory,
    *,
    rate: float,
    rng: np.random.Generator,
    noise: NDArray[np.float64] | float = 0.0,
    extra: Callable[[NDArray[np.float64], NDArray[np.float64]], NDArray[np.float64]] | None = None,
    state_noise: float = 0.0,
    with_derivatives: bool = True,
) -> Dataset:
    """Samples of ``tau = W x_true + extra(q, dq) + noise`` along ``traj``.

    Parameters
    ----------
    columns : ColumnSet
        The identified parameters.
    x_true : ndarray, shape (p,)
        Their true values.
    traj : FourierTrajectory
        The motion.
    rate : float
        Sampling rate (Hz).
    rng : numpy.random.Generator
        Random source.
    noise : float or ndarray, shape (n,) or (n, n)
        Torque noise: one standard deviation (N m), one per joint, or a covariance (N^2 m^2).
    extra : callable, optional
        ``extra(q, dq) -> (m, n)`` torque added (friction, unmodelled effects).
    state_noise : float
        Standard deviation (rad) of white noise added to the recorded ``q``.
    with_derivatives : bool
        Record the exact ``dq`` and ``ddq`` (True) or leave them to preprocessing.
    """
    t, q, dq, ddq = traj.sample(rate)
    tau = linear_torque(columns, x_true, q, dq, ddq)
    if extra is not None:
        tau = tau + extra(q, dq)
    n = columns.n
    noise = np.asarray(noise, dtype=float)
    if noise.ndim == 2:
        tau = tau + rng.multivariate_normal(np.zeros(n), noise, size=len(t))
    elif np.any(noise > 0):
        tau = tau + rng.normal(size=tau.shape) * noise
    q_rec = q + state_noise * rng.normal(size=q.shape) if state_noise > 0 else q
    return Dataset(
        t,
        q_rec,
        tau,
        dq=dq if with_derivatives else None,
        ddq=ddq if with_derivatives else None,
        meta={"source": "synthetic (regressor)"},
    )
