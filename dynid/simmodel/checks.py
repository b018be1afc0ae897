"""Reload checks of an exported simulator description: the file, read back, gives dynid's torque.

* URDF: numeric Pinocchio (``buildModelFromUrdf``, dynid's locked joints locked again, the armature set
  as ``model.armature`` because URDF has no field for it) reproduces the rigid-body + armature torque of
  the exported parameters, :func:`dynid.identify.columns.linear_torque`, to :data:`URDF_TOLERANCE`
  (relative, over random states).
* MJCF, inverse dynamics: MuJoCo's ``mj_inverse`` with the constraints disabled (frictionloss and joint
  limits are constraints in MuJoCo) reproduces rigid body + armature + viscous torque to
  :data:`MJCF_TOLERANCE`.
* MJCF, frictionloss, per joint with a Coulomb level: (1) sliding, the constraint force MuJoCo computes
  (``mj_forward``, the joint moving alone from the middle of its range) is that level, opposing the
  motion, to 1e-9 relative; MuJoCo's frictionloss is a soft constraint that saturates at its level only
  above a speed that depends on the joint's inertia, so the speed is doubled from 0.5 rad/s until it
  saturates (the speed is reported); (2) holding, in a forward rollout from rest with gravity and bias
  compensated, a push of half the level moves the joint less than half as far as the same push moves
  it without its frictionloss (a soft constraint creeps: measured 1-45 % on ur5 and Panda models).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid.identify.columns import column_set, linear_torque
from dynid.symbolic.robot import SNAP_RAD, pin_model_from_urdf

__all__ = ["MJCF_TOLERANCE", "URDF_TOLERANCE", "check_mjcf", "check_urdf", "random_states"]

URDF_TOLERANCE = 1e-8
MJCF_TOLERANCE = 1e-6
_HOLD = 0.5
_SLIDE_TOL = 1e-9
_MAX_SPEED = 100.0  # rad/s: beyond it the soft constraint is taken as not saturating


def random_states(robot, count: int, seed: int = 0) -> tuple[NDArray[np.float64], ...]:
    """Random joint states within the robot's limits: (q, dq, ddq), each (count, n)."""
    rng = np.random.default_rng(seed)
    lo = np.maximum(robot.q_min, -np.pi)
    hi = np.minimum(robot.q_max, np.pi)
    q = rng.uniform(lo, hi, (count, robot.n))
    dq = rng.uniform(-1, 1, (count, robot.n)) * np.minimum(robot.dq_max, 3.0)
    ddq = rng.uniform(-1, 1, (count, robot.n)) * np.minimum(robot.ddq_max, 10.0)
    return q, dq, ddq


def _reference(model, params, q, dq, ddq) -> NDArray[np.float64]:
    """dynid's rigid body + armature torque of the exported values, through dynid's own regressor.

    Each armature acts on its own joint: a coupled transmission's cross terms are no field of either
    format (they are listed among what is not carried), so the check is of what the file does carry.
    """
    robot = model.robot
    n = robot.n
    cols = column_set(robot.with_transmission(None), friction=False, armature=True)
    x = cols.P @ np.concatenate([params.standard, params.armature, np.zeros(3 * n)])
    return linear_torque(cols, x, q, dq, ddq)


def _relative(got, ref) -> float:
    return float(np.linalg.norm(got - ref) / max(np.linalg.norm(ref), 1e-300))


def check_urdf(path: str | Path, model, params, *, count: int = 50) -> dict[str, Any]:
    """Pinocchio's torque of the exported URDF against dynid's (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The exported URDF.
    model : IdentifiedModel
        The model exported.
    params : SimParameters
        What was written.
    count : int
        Random states.

    Returns
    -------
    dict
        ``check``, ``relative_error``, ``tolerance``, ``states``, ``passed``.
    """
    import pinocchio as pin

    robot = model.robot
    full = pin_model_from_urdf(path)
    names = list(full.names)[1:]
    locked = [full.getJointId(nm) for nm in names if nm not in robot.joint_names]
    pm = pin.buildReducedModel(full, locked, pin.neutral(full)) if locked else full
    pm.armature = np.array(params.armature, dtype=float)
    pm.gravity.linear = np.array(robot.gravity, dtype=float)
    data = pm.createData()
    q, dq, ddq = random_states(robot, count)
    got = np.array([pin.rnea(pm, data, q[k], dq[k], ddq[k]) for k in range(count)])
    err = _relative(got, _reference(model, params, q, dq, ddq))
    # A description whose right angles were rounded (CAD) is read snapped by dynid and as written by
    # Pinocchio: the file carries the description's own angles, the torques then differ by the order of
    # the snap, which the tolerance allows (ten times it).
    snap = 0.0
    if pm.njoints - 1 == robot.n:
        for i, joint in enumerate(robot.joints):
            snap = max(snap, float(np.abs(np.asarray(pm.jointPlacements[i + 1].rotation) - joint.rotation).max()))
            inner = pm.joints[i + 1].extract()
            if hasattr(inner, "axis"):  # an unaligned joint: its axis is snapped too
                snap = max(snap, float(np.abs(np.asarray(inner.axis, dtype=float) - joint.axis).max()))
    tolerance = URDF_TOLERANCE if snap > SNAP_RAD else max(URDF_TOLERANCE, 10.0 * snap)
    check = "URDF in Pinocchio: rigid body + armature (model.armature) vs dynid"
    if tolerance > URDF_TOLERANCE:
        check += f" (the description's right angles as written, {snap:.2g} rad from dynid's snapped ones)"
    return {
        "check": check,
        "relative_error": err,
        "tolerance": tolerance,
        "states": count,
        "passed": bool(err <= tolerance),
    }


def _dofs(mujoco, m, robot) -> NDArray[np.intp]:
    return np.array(
        [m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, nm)] for nm in robot.joint_names]
    )


def _qpos(mujoco, m, robot) -> NDArray[np.intp]:
    return np.array(
        [m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, nm)] for nm in robot.joint_names]
    )


def _rollout(mujoco, m, robot, q0, joint: int, push: float, seconds: float) -> float:
    """Displacement (rad) of one joint pushed from rest with gravity and bias compensated."""
    d = mujoco.MjData(m)
    qadr, dadr = _qpos(mujoco, m, robot), _dofs(mujoco, m, robot)
    d.qpos[qadr] = q0
    mujoco.mj_forward(m, d)
    d.qfrc_applied[:] = d.qfrc_bias
    d.qfrc_applied[dadr[joint]] += push
    for _ in range(max(round(seconds / m.opt.timestep), 1)):
        mujoco.mj_step(m, d)
    return float(d.qpos[qadr[joint]] - q0[joint])


def check_mjcf(path: str | Path, model, params, *, count: int = 50, seconds: float = 0.2) -> list[dict[str, Any]]:
    """MuJoCo's inverse dynamics and frictionloss of the exported MJCF (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The exported MJCF.
    model : IdentifiedModel
        The model exported.
    params : SimParameters
        What was written.
    count : int
        Random states of the inverse-dynamics check.
    seconds : float
        Length of each frictionloss rollout (s).

    Returns
    -------
    list of dict
        Two checks: ``check``, ``passed`` and their figures.
    """
    from dynid.simmodel.mjcf import import_mujoco

    mujoco = import_mujoco()
    robot = model.robot
    m = mujoco.MjModel.from_xml_path(str(path))
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    d = mujoco.MjData(m)
    qadr, dadr = _qpos(mujoco, m, robot), _dofs(mujoco, m, robot)
    q, dq, ddq = random_states(robot, count)
    got = np.empty_like(q)
    for k in range(count):
        d.qpos[:] = m.qpos0
        d.qvel[:] = 0.0
        d.qacc[:] = 0.0
        d.qpos[qadr], d.qvel[dadr], d.qacc[dadr] = q[k], dq[k], ddq[k]
        mujoco.mj_inverse(m, d)
        got[k] = d.qfrc_inverse[dadr]
    ref = _reference(model, params, q, dq, ddq) + dq * params.damping
    err = _relative(got, ref)
    out = [
        {
            "check": "MJCF in MuJoCo: mj_inverse (constraints off) vs dynid rigid body + armature + viscous",
            "relative_error": err,
            "tolerance": MJCF_TOLERANCE,
            "states": count,
            "passed": bool(err <= MJCF_TOLERANCE),
        }
    ]
    # frictionloss: the sliding force, then a forward rollout from the middle of the joint ranges
    m = mujoco.MjModel.from_xml_path(str(path))
    q0 = 0.5 * (np.maximum(robot.q_min, -np.pi) + np.minimum(robot.q_max, np.pi))
    joints = []
    for j in range(robot.n):
        f = float(m.dof_frictionloss[dadr[j]])
        if not f > 0:
            continue
        speed, force = 0.5, 0.0
        while speed <= _MAX_SPEED:
            d = mujoco.MjData(m)
            d.qpos[qadr] = q0
            d.qvel[dadr[j]] = speed
            mujoco.mj_forward(m, d)
            force = float(d.qfrc_constraint[dadr[j]])
            if abs(force + f) <= _SLIDE_TOL * f:
                break
            speed *= 2
        hold = _rollout(mujoco, m, robot, q0, j, 0.5 * f, seconds)
        m.dof_frictionloss[dadr[j]] = 0.0
        free = _rollout(mujoco, m, robot, q0, j, 0.5 * f, seconds)
        m.dof_frictionloss[dadr[j]] = f
        sliding_ok = abs(force + f) <= _SLIDE_TOL * f
        holding_ok = abs(hold) <= _HOLD * abs(free)
        joints.append(
            {
                "joint": j + 1,
                "frictionloss": f,
                "sliding_force": force,
                "sliding_speed": speed,
                "held_rad": hold,
                "free_rad": free,
                "passed": bool(sliding_ok and holding_ok),
            }
        )
    out.append(
        {
            "check": "MJCF in MuJoCo: frictionloss (the sliding force equals the level; a joint pushed by half "
            "its level from rest holds in a forward rollout)",
            "joints": joints,
            "seconds": seconds,
            "passed": all(r["passed"] for r in joints),
        }
    )
    return out
