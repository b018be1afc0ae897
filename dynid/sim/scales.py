"""The per-joint scales that the simulator's default effect and friction sizes are relative to.

:func:`robot_scales` computes, once per robot and from 1000 random states drawn with a fixed
generator (so they depend on the robot only, never on the seed or the trajectory), the torque scale
``s_j`` (N m), the inertia scale ``I_j`` (kg m^2) and the reference speed ``v_j`` (rad/s) that
:mod:`dynid.sim.effects` defines.  Split out of :mod:`dynid.sim.effects`, which re-exports its names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dynid.symbolic.robot import RobotModel

__all__ = ["RobotScales", "robot_scales"]


@dataclass(frozen=True, eq=False)
class RobotScales:
    """Per-joint sizes that default effect sizes are relative to.

    Attributes
    ----------
    torque : ndarray, shape (n,)
        Torque scale s_j (N m): 95th percentile of ``|rnea_j|`` over random states.
    inertia : ndarray, shape (n,)
        Inertia scale I_j (kg m^2): median of ``M_jj(q)`` over random configurations.
    speed : ndarray, shape (n,)
        Reference speed v_j = dq_max_j / 2 (rad/s).
    """

    torque: np.ndarray
    inertia: np.ndarray
    speed: np.ndarray

    def to_dict(self) -> dict:
        return {
            "torque": self.torque.tolist(),
            "inertia": self.inertia.tolist(),
            "speed": self.speed.tolist(),
        }


def robot_scales(robot: RobotModel, *, samples: int = 1000) -> RobotScales:
    """Torque, inertia and speed scales of a robot (see :mod:`dynid.sim.effects`).

    Parameters
    ----------
    robot : RobotModel
        The nominal robot.
    samples : int
        Number of random states; drawn with ``np.random.default_rng(0)`` so the scales depend on the
        robot only.

    Returns
    -------
    RobotScales
    """
    import pinocchio as pin

    model = robot.pin_model
    data = model.createData()
    rng = np.random.default_rng(0)
    lo, hi = np.maximum(robot.q_min, -math.pi), np.minimum(robot.q_max, math.pi)
    lo, hi = np.where(lo < hi, lo, robot.q_min), np.where(lo < hi, hi, robot.q_max)
    q = rng.uniform(lo, hi, size=(samples, robot.n))
    dq = rng.uniform(-0.5, 0.5, size=(samples, robot.n)) * robot.dq_max
    ddq = rng.uniform(-0.5, 0.5, size=(samples, robot.n)) * robot.ddq_max
    tau = np.empty((samples, robot.n))
    diag = np.empty((samples, robot.n))
    for i in range(samples):
        tau[i] = pin.rnea(model, data, q[i], dq[i], ddq[i])
        diag[i] = np.diag(pin.crba(model, data, q[i]))
    torque = np.percentile(np.abs(tau), 95, axis=0)
    inertia = np.median(diag, axis=0)
    # A joint that carries nothing still gets a size (a millionth of the largest), never zero.
    torque = np.maximum(torque, 1e-6 * max(float(torque.max()), 1e-9))
    inertia = np.maximum(inertia, 1e-6 * max(float(inertia.max()), 1e-12))
    return RobotScales(torque=torque, inertia=inertia, speed=0.5 * np.asarray(robot.dq_max, dtype=float))
