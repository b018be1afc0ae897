"""Synthetic identification data made from the regressor itself (tests and benchmarks).

``tau = W(q, dq, ddq) x_true (+ friction(dq) + unmodelled(q, dq)) + noise`` on random Fourier motions.
This is not the simulator (:mod:`dynid.sim.simulator`, forward dynamics with effects); it is the
shortest path to data whose truth is known exactly in the identified parameters.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from dynid.identify.dataset import Dataset
from dynid.identify.linear_system import ColumnSet, linear_torque
from dynid.optim.trajectory import FourierTrajectory

__all__ = ["random_fourier", "synthetic_dataset", "true_parameters"]


def random_fourier(
    robot,
    rng: np.random.Generator,
    *,
    harmonics: int = 5,
    base_freq: float = 0.1,
    periods: int = 1,
    fraction: float = 0.6,
    still: tuple[int, ...] = (),
) -> FourierTrajectory:
    """A random Fourier motion within ``fraction`` of each joint's limits (position, speed, acceleration).

    Parameters
    ----------
    robot : RobotModel
        The robot (its limits scale the motion).
    rng : numpy.random.Generator
        Random source.
    harmonics : int
        Harmonics per joint.
    base_freq : float
        Base frequency (Hz).
    periods : int
        Periods the trajectory lasts.
    fraction : float
        Share of each limit the motion may use.
    still : tuple of int
        Joints (1-based) that do not move.
    """
    n = robot.n
    a = rng.normal(size=(harmonics, n))
    b = rng.normal(size=(harmonics, n))
    traj = FourierTrajectory(a=a, b=b, c=np.zeros(n), base_freq=base_freq, periods=periods)
    t = np.linspace(0.0, traj.period, 2000)
    q, dq, ddq = traj.evaluate(t)
    q = q - q.mean(axis=0)
    span = np.minimum(robot.q_max - robot.q_min, 2 * np.pi) / 2
    center = 0.5 * (robot.q_max + robot.q_min)
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
    c = center - scale * traj.evaluate(t)[0].mean(axis=0)
    return FourierTrajectory(a=a * scale, b=b * scale, c=c, base_freq=base_freq, periods=periods)


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
